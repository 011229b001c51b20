"""Probe: the oscillator per update, the authors' TensorFlow code beside ours, from the same
data and initial weights.

Our HIG's oscillator test loss is ~1e-6 after the paper's hour of updates (~24,700) and
flattens near 7.5e-7, while the paper shows ~1e-7. Physics and the HIG direction agree with
the authors' code to rounding, so the difference per update lies in what surrounds them. This
probe changes one factor at a time, from a copy of the authors' set-up to ours as published:

* ``mirror``: the authors' data and initial weights, their fixed batch order (the same 32
  mini-batches in the same order every epoch), network and physics in float32 and the
  inversion in float32 (their SVD runs in the network's precision);
* ``float64 inversion``: as ``mirror``, the inversion in float64 (our default);
* ``reshuffled``: as ``float64 inversion``, the mini-batches reshuffled every epoch (ours);
* ``ours``: our data and initialisation (data seed 0, seed 0), reshuffled, float64
  inversion: our published runs.

All at the authors' settings (b = 128, eta = 1, tau = 1e-6), evaluated after every epoch
(32 updates) on all 4,096 training and 4,096 test samples, as the authors' code does. The
authors' own curve comes from ``scripts/export_authors_oscillator.py`` (``make
probe-authors-oscillator`` runs both)::

    python scripts/probe_oscillator_authors.py EXPORT.npz --epochs 772   # the paper's hour of updates
    python scripts/probe_oscillator_authors.py EXPORT.npz --report-only  # redraw from the CSV

Writes ``NAME.csv`` (variant x epoch), ``NAME_summary.csv`` and ``NAME.png`` to ``--out``
(default docs/results/probes; ``--name``, default oscillator_authors).
"""

from __future__ import annotations

import argparse
import multiprocessing
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
CHECKPOINTS = (1024, 8192, 24_576)  # updates: the authors' exported run; a third; the paper's hour
AUTHORS = "authors' TF code"


@dataclass(frozen=True)
class Variant:
    name: str
    data: str  # "authors": the export's data and initial weights | "ours": data seed 0, seed 0
    order: str  # "fixed": the authors' batch order | "shuffled": reshuffled every epoch
    precision: str  # the inversion's dtype (optimizer.precision)


VARIANTS = (
    Variant("mirror", "authors", "fixed", "float32"),
    Variant("float64 inversion", "authors", "fixed", "float64"),
    Variant("reshuffled", "authors", "shuffled", "float64"),
    Variant("ours", "ours", "shuffled", "float64"),
)


def compose(variant: Variant):
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    from higbench.config import config_dir

    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        # problem_optimizer/oscillator_hig: the paper's b = 128, eta = 1, tau = 1e-6
        return hydra_compose(
            "config", ["problem=oscillator", "optimizer=hig", f"optimizer.precision={variant.precision}", "threads=1"]
        )


def load_keras_weights(model, weights: list[np.ndarray]) -> None:
    """Dense kernels (in, out) and biases, layer by layer, into our Linear layers (out, in)."""
    import torch

    linears = [m for m in model if isinstance(m, torch.nn.Linear)]
    if len(weights) != 2 * len(linears):
        raise ValueError(f"export has {len(weights)} weight arrays, the network {len(linears)} dense layers")
    with torch.no_grad():
        for layer, kernel, bias in zip(linears, weights[::2], weights[1::2]):
            layer.weight.copy_(torch.as_tensor(kernel.T))
            layer.bias.copy_(torch.as_tensor(bias))


def use_export(problem, model, export: Path) -> None:
    """The export's training and test sets (the target is the initial state) and initial weights."""
    import torch

    from higbench.problems.base import Batch

    data = np.load(export)

    def batch(x: np.ndarray) -> Batch:
        x = torch.as_tensor(x, dtype=problem.dtype)
        return Batch(net_inputs=x, inputs=x, targets=x)

    problem.train, problem.test = batch(data["x_train"]), batch(data["x_test"])
    load_keras_weights(model, [data[f"weight_{i}"] for i in range(sum(k.startswith("weight_") for k in data.files))])


def mean_loss(problem, model, batch) -> float:
    import torch

    from higbench.runner.train import evaluate

    with torch.no_grad():
        return evaluate(problem, model, batch)["test_loss"]  # the mean per-sample loss of ``batch``


def train(variant: Variant, export: Path, epochs: int) -> pd.DataFrame:
    """One variant: loss after every epoch (row 0: before training); stops at a refused update."""
    import torch

    from higbench.dtypes import DTYPES
    from higbench.problems.base import build_problem
    from higbench.runner.updates import build_update

    torch.set_num_threads(1)
    cfg = compose(variant)
    torch.manual_seed(cfg.seed)
    problem = build_problem(cfg.problem, dtype=DTYPES[cfg.dtype], device=torch.device("cpu"), seed=cfg.seed)
    model = problem.build_model()
    if variant.data == "authors":
        use_export(problem, model, export)
    update, b = build_update(problem, model, cfg.optimizer), int(cfg.batch_size)
    shuffle = torch.Generator().manual_seed(cfg.seed)
    rows, started, status = [], time.perf_counter(), "completed"

    def record(epoch: int) -> None:
        train_loss, test_loss = mean_loss(problem, model, problem.train), mean_loss(problem, model, problem.test)
        rows.append({"variant": variant.name, "epoch": epoch, "updates": epoch * len(problem.train) // b,
                     "train_loss": train_loss, "test_loss": test_loss})  # fmt: skip

    record(0)
    for epoch in range(1, epochs + 1):
        n = len(problem.train)
        batches = problem.epoch(b, shuffle) if variant.order == "shuffled" else (problem.train[i : i + b] for i in range(0, n, b))
        if not all(update(batch).finite for batch in batches):
            status = "diverged"
            break
        record(epoch)
    out = pd.DataFrame(rows)
    out["status"], out["seconds"] = status, time.perf_counter() - started
    print(f"{time.strftime('%H:%M:%S')} {variant.name}: {status}, test {rows[-1]['test_loss']:.3e}", file=sys.stderr, flush=True)
    return out


def authors_curve(export: Path) -> pd.DataFrame:
    data = np.load(export)
    epochs = np.arange(len(data["test_loss"]))
    per_epoch = int(data["updates_per_epoch"])
    return pd.DataFrame({"variant": AUTHORS, "epoch": epochs, "updates": epochs * per_epoch,
                         "train_loss": data["train_loss"], "test_loss": data["test_loss"], "status": "completed",
                         "seconds": float(np.sum(data["epoch_seconds"]))})  # fmt: skip


def at_updates(curve: pd.DataFrame, updates: int) -> tuple[float, float]:
    """(train, test) loss at the last evaluation at or before ``updates`` (NaN past the curve's end)."""
    done = curve[curve["updates"] <= updates]
    if done.empty or curve["updates"].max() < updates:
        return float("nan"), float("nan")
    last = done.iloc[-1]
    return float(last["train_loss"]), float(last["test_loss"])


def summary(curves: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for name, curve in curves.groupby("variant", sort=False):
        row = {"variant": name, "status": curve["status"].iloc[0], "updates": int(curve["updates"].max())}
        for n in CHECKPOINTS:
            row[f"train_at_{n}"], row[f"test_at_{n}"] = at_updates(curve, n)
        row["test_min"] = float(curve["test_loss"].min())
        rows.append(row)
    return pd.DataFrame(rows)


def plot(curves: pd.DataFrame, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for i, (name, curve) in enumerate(curves[curves["updates"] > 0].groupby("variant", sort=False)):
        theirs = name == AUTHORS  # drawn on top, with markers: ours from their weights lies on it
        style = {"color": "k", "marker": "o", "ms": 3, "zorder": 3} if theirs else {"color": f"C{i}"}
        ax.plot(curve["updates"], curve["test_loss"], lw=1.6, label=f"{name} (test)", **style)
        ax.plot(curve["updates"], curve["train_loss"], color=style["color"], lw=0.8, ls="--", alpha=0.7)
    ax.plot([], [], color="grey", ls="--", lw=0.8, label="training loss (dashed)")
    ax.set(xscale="log", yscale="log", xlabel="HIG updates (b = 128)", ylabel="loss (mean over samples)")
    ax.set_title("Oscillator HIG per update: the authors' code and ours from the same data and weights", fontsize=9)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("export", type=Path, help="the .npz of scripts/export_authors_oscillator.py")
    p.add_argument("--epochs", type=int, default=772, help="our epochs of 32 updates (default 772: the paper's hour)")
    p.add_argument("--jobs", type=int, default=2, help="variants trained at the same time (one thread each)")
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "probes")
    p.add_argument("--variants", nargs="+", choices=[v.name for v in VARIANTS], default=[v.name for v in VARIANTS],
                   help="which of ours to train (default: all)")  # fmt: skip
    p.add_argument("--name", default="oscillator_authors", help="stem of the files written to --out")
    p.add_argument("--report-only", action="store_true", help="redraw from --out's CSV, the authors' curve from EXPORT")
    args = p.parse_args(argv)
    if not args.export.is_file():
        p.error(f"export={args.export}: no such file (make it with scripts/export_authors_oscillator.py)")
    if args.epochs < 1 or args.jobs < 1:
        p.error(f"--epochs={args.epochs} --jobs={args.jobs}: both must be at least 1")
    if args.report_only and not (args.out / f"{args.name}.csv").is_file():
        p.error(f"--report-only: no {args.name}.csv in {args.out}; run the probe first")
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse(argv)
    table = args.out / f"{args.name}.csv"
    if args.report_only:  # the authors' rows are taken anew from the export (a longer run of theirs)
        curves = pd.read_csv(table)
        ours = curves[curves["variant"] != AUTHORS]
        curves = pd.concat([authors_curve(args.export), ours], ignore_index=True)
        curves.to_csv(table, index=False, float_format="%.6g")
    else:
        spawn = multiprocessing.get_context("spawn")  # torch in forked workers is not safe
        chosen = [v for v in VARIANTS if v.name in args.variants]
        with ProcessPoolExecutor(args.jobs, mp_context=spawn) as pool:
            ours = list(pool.map(train, chosen, [args.export] * len(chosen), [args.epochs] * len(chosen)))
        curves = pd.concat([authors_curve(args.export), *ours], ignore_index=True)
        args.out.mkdir(parents=True, exist_ok=True)
        curves.to_csv(table, index=False, float_format="%.6g")
    summary(curves).to_csv(args.out / f"{args.name}_summary.csv", index=False, float_format="%.4g")
    plot(curves, args.out / f"{args.name}.png")
    print(summary(curves).to_string(index=False))


if __name__ == "__main__":
    main()
