"""Run the authors' oscillator HIG code (tum-pbs/half-inverse-gradients, TensorFlow) and save
what a side-by-side comparison with ours needs: their training and test data, their network's
initial weights, and their training and test loss after every epoch.

Their code is imported from a checkout and run as it is, with the settings of their
``Nonlinear_oscillators/submit_HIG.py`` (b = 128, eta = 1, tau = 1e-6, N = 4096, data and
weights seeded with 22); only the stopping rule is a number of epochs instead of an hour.
It needs TensorFlow and numpy, not higbench: run it with the interpreter ``make authors-env``
builds (``.venv-authors``)::

    .venv-authors/bin/python scripts/export_authors_oscillator.py --authors CHECKOUT \\
        --epochs 32 --out outputs/probes/oscillator_authors.npz

``scripts/probe_oscillator_authors.py`` then trains ours from the same data and weights.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

# Their submit_HIG.py: the settings of the paper's oscillator HIG run.
SETTINGS = {"oscillators": 2, "steps": 96, "dt": 0.125, "n": 4096, "batch_size": 128, "lr": 1.0, "tau": 1e-6, "seed": 22}


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--authors", type=Path, required=True, help="a checkout of tum-pbs/half-inverse-gradients")
    p.add_argument(
        "--epochs", type=int, default=32, help="epochs of 32 updates each (default 32: 1,024 updates; 0: data and weights only)"
    )
    p.add_argument("--out", type=Path, required=True, help="the .npz file to write (never overwritten)")
    args = p.parse_args(argv)
    if not (args.authors / "Nonlinear_oscillators" / "simulation.py").is_file():
        p.error(f"--authors={args.authors}: no Nonlinear_oscillators/simulation.py there")
    if args.epochs < 0:
        p.error(f"--epochs={args.epochs}: must be at least 0")
    if args.out.exists():
        p.error(f"--out={args.out}: exists; it is kept (choose another path)")
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse(argv)
    sys.path.insert(0, str(args.authors / "Nonlinear_oscillators"))
    import tensorflow as tf
    from NLO_HIG import NLO_optimization_framework, ig_gpinv
    from simulation import simulation
    from world_batch import l2_loss

    s = SETTINGS
    sim = simulation()
    sim.set_physics(s["oscillators"], s["steps"], s["dt"])
    sim.set_optimization("IG", tf.keras.optimizers.SGD, s["tau"], "HIG")
    sim.set_learning(s["n"], s["batch_size"], s["lr"], "epochs", args.epochs)
    sim.set_seed(s["seed"])
    # simulation.start(), in its order (data first: it seeds numpy and TensorFlow), keeping
    # the initial weights it does not return.
    x_train, y_train, x_test, y_test = sim.get_data()
    model, solver = sim.get_model_and_solver()
    initial = model.get_weights()
    framework = NLO_optimization_framework(model, solver, l2_loss)
    framework.set_data_set(x_train, y_train, x_test, y_test)
    framework.set_training_parameters("IG", tf.keras.optimizers.SGD, s["batch_size"], s["lr"], "epochs", args.epochs)
    framework.set_inversion_parameters(ig_gpinv, s["tau"])
    started = time.time()
    empty = {"train_loss": [], "test_loss": [], "epoch_time": []}
    results = framework.start_training() if args.epochs else empty

    args.out.parent.mkdir(parents=True, exist_ok=True)
    np.savez(
        args.out,
        x_train=x_train,
        x_test=x_test,
        **{f"weight_{i}": w for i, w in enumerate(initial)},
        train_loss=np.array([float(v) for v in results["train_loss"]]),
        test_loss=np.array([float(v) for v in results["test_loss"]]),
        epoch_seconds=np.array(results["epoch_time"], dtype=float),
        updates_per_epoch=s["n"] // s["batch_size"],
        tensorflow=tf.__version__,
        settings=repr(s),
        wall_seconds=time.time() - started,
    )
    print(f"wrote {args.out}: {args.epochs} epochs" + (f", test loss {results['test_loss'][-1]:.3e}" if args.epochs else ""))


if __name__ == "__main__":
    main()
