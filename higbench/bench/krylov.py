"""How close and how fast the Krylov route's step is, against the exact Gram route, on one batch.

For a problem, a batch size and a list of Lanczos step counts m, prints one JSON object per m:

    problem, optimizer, batch_size, rows, update, steps, steps_taken, cosine, rel_error,
    step_error, krylov_s, exact_s, threads

``cosine`` and ``rel_error`` compare the Krylov direction with the exact one (the Gram
route: K formed, eigen-decomposed); ``step_error`` is the route's own estimate of its relative
error (what a run records per update). ``krylov_s`` is the Krylov inversion (Lanczos with its
products and the final J^T c), ``exact_s`` the exact route's (K, its eigen-decomposition and
J^T c); both from the same derivatives (solver Jacobians and network factors, not timed), both
medians over ``--repeats``, timed interleaved in this one process. ``--train N`` first takes
N exact updates on fresh batches (the directions at update N rather than at initialisation).
``--no-exact`` skips the exact route (batch sizes whose K does not fit).

    python -m higbench.bench.krylov --problem poisson --batch-size 64 --steps 50 100 200 400
    python -m higbench.bench.krylov --problem poisson --batch-size 64 --steps 200 --train 8
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import torch

from higbench.bench.step import CPU, Config, Runner, default_batch
from higbench.optim.closure import reduce_loss
from higbench.optim.inversion import gram_coefficients
from higbench.optim.krylov import krylov_direction
from higbench.optim.structured import network_jacobian, solver_jacobian
from higbench.runner.updates import synchronize


def derivatives(runner: Runner, batch):
    """(J as a StructuredJacobian, g) of the runner's optimizer at its current weights, as ``step_structured``."""
    closure = runner.update.closure(batch)
    opt = runner.update.optimizer
    with torch.no_grad():
        u = closure.model(closure.net_inputs)
    y, A = solver_jacobian(closure.physics, closure.inputs, u, physics_jacobian=closure.physics_jacobian)
    with torch.enable_grad():
        per_sample = closure.loss(y.requires_grad_(True))
        (grad_y,) = torch.autograd.grad(reduce_loss(per_sample, closure.reduction), y)
    J = network_jacobian(closure.model, opt.params, closure.net_inputs, A, opt.group["precision"])
    return J, grad_y.reshape(-1).to(opt.group["precision"])


def exact_direction(J, g, opts: dict) -> torch.Tensor:
    return J.transpose_apply(gram_coefficients(J.gram(), g, **opts, overwrite=True, n_params=J.n_params))


def timed(fn, device):
    synchronize(device)
    t0 = time.perf_counter()
    out = fn()
    synchronize(device)
    return out, time.perf_counter() - t0


def probe(
    problem: str,
    optimizer: str,
    batch_size: int,
    steps: list[int],
    repeats: int,
    train: int,
    exact: bool,
    device: torch.device = CPU,
    overrides: tuple[str, ...] = (),
) -> list[dict]:
    runner = Runner(Config(problem, optimizer, batch_size, "structured", "gram", overrides), torch.float32, device)
    gen = torch.Generator().manual_seed(1)
    for _ in range(train):  # exact updates on fresh batches
        runner.update(next(iter(runner.problem.epoch(batch_size, gen))))
    opt = runner.update.optimizer
    opts = opt._opts()
    J, g = derivatives(runner, runner.batch)
    times: dict[object, list[float]] = {m: [] for m in steps}
    times["exact"] = []
    results, reference = {}, None
    for _ in range(repeats):  # interleaved: every round runs each route once
        if exact:
            reference, t = timed(lambda: exact_direction(J, g, opts), device)
            times["exact"].append(t)
        for m in steps:
            results[m], t = timed(lambda m=m: krylov_direction(J, g, **opts, steps=m), device)
            times[m].append(t)
    rows = []
    for m in steps:
        d, result = results[m]
        row = dict(
            problem=problem,
            optimizer=optimizer,
            batch_size=batch_size,
            rows=J.rows,
            update=train,
            steps=m,
            steps_taken=result.steps,
            step_error=result.step_error,
            krylov_s=statistics.median(times[m]),
            threads=torch.get_num_threads(),
        )
        if reference is not None:
            row["cosine"] = float(d @ reference / (d.norm() * reference.norm()))
            row["rel_error"] = float((d - reference).norm() / reference.norm())
            row["exact_s"] = statistics.median(times["exact"])
        rows.append(row)
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m higbench.bench.krylov", description=__doc__.split("\n\n")[0])
    parser.add_argument("--problem", default="poisson")
    parser.add_argument("--optimizer", default="hig", choices=["hig", "gn"])
    parser.add_argument("--batch-size", nargs="+", type=int, default=None, help="default: the problem x optimizer default")
    parser.add_argument("--steps", nargs="+", type=int, default=[50, 100, 200, 400], help="Lanczos steps m")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--train", type=int, default=0, help="exact updates before the probe")
    parser.add_argument("--no-exact", action="store_true", help="skip the exact route (K too large)")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="extra Hydra overrides")
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    parser.add_argument("--threads", default="auto", help="torch threads: N or auto (as bench.step)")
    args = parser.parse_args(argv)
    if any(m < 1 for m in args.steps):
        parser.error(f"--steps {args.steps}: every step count must be >= 1")
    from higbench.runner.threads import resolve_threads

    torch.set_num_threads(resolve_threads(args.threads if args.threads == "auto" else int(args.threads)))
    device = torch.device(args.device)
    for b in args.batch_size or [default_batch(args.problem, args.optimizer)]:
        rows = probe(
            args.problem, args.optimizer, b, args.steps, args.repeats, args.train, not args.no_exact, device, tuple(args.set)
        )
        for row in rows:
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
