"""Probe: the oscillator's table-2 levels over data draws and seeds, at the paper's run length
(claims osc-3 and osc-5: what one test draw's mean is worth, and whether a larger batch
ends lower).

HIG and GN at table 2's settings (eta = 1, tau = 1e-6) at b = 32, 64, 128, each for the updates
the paper's GPU makes in the authors' documented hour at that b (table 3's seconds per update;
GN's update priced as HIG's, as the paper's table gives none). An update budget, not seconds:
the levels then do not depend on this machine's speed or load, and the batch sizes meet at the
paper's cost ratio. Each setting runs on 3 (data draw, seed) pairs; HIG at b = 128, the paper's
headline setting, on 3 draws x 2 seeds.

Every run file keeps its final evaluation sample by sample (``/final/test_losses``) and the
mean over a fresh draw of 32,768 samples (``/final/fresh_test_losses``), so the table sets the
paper's metric (the mean over its 4,096 test samples) beside the median, the 95th percentile,
the share of the mean carried by the 10 worst samples, and the fresh-set mean.

    python scripts/probe_oscillator_draws.py                 # 18 runs, ~1 h on 2 cores (1 thread each)
    python scripts/probe_oscillator_draws.py --report-only   # re-read outputs/probes/oscillator_draws
    python scripts/probe_oscillator_draws.py --fraction 0.01 --root /some/dir   # a quick trial

Writes ``oscillator_draws.csv`` (one row per run) to ``--out`` (default docs/results/probes).
"""

from __future__ import annotations

import argparse

import numpy as np
import pandas as pd
import probe_runs

from higbench.bench.paper import PAPER_COSTS
from higbench.claims.rules import documented_updates
from higbench.runfile.reader import load_final

BATCHES = (32, 64, 128)
PAIRS = ((0, 0), (1, 1), (2, 0))  # (data draw, seed): every setting
HEADLINE_PAIRS = ((0, 1), (1, 0), (2, 1))  # more for HIG at b=128 (3 draws x 2 seeds in all)
WORST = 10  # samples whose share of the mean is reported
EVAL_EVERY = 256  # updates between evaluations


def paper_updates(batch_size: int, fraction: float = 1.0) -> int:
    """Updates of the authors' documented hour at ``batch_size`` on the paper's GPU (table 3, HIG)."""
    full = documented_updates("oscillator", PAPER_COSTS[("oscillator", "hig", batch_size)][1])
    return max(1, round(full * fraction))


def settings() -> list[tuple[str, int, int, int]]:
    """(optimizer, batch size, data draw, seed) of every run."""
    runs = [(o, b, d, s) for o in ("hig", "gn") for b in BATCHES for d, s in PAIRS if not (o == "gn" and b == 64)]
    return runs + [("hig", 128, d, s) for d, s in HEADLINE_PAIRS]


def jobs(fraction: float = 1.0) -> list[list[str]]:
    return [
        [f"optimizer={o}", "problem=oscillator", f"batch_size={b}", f"problem.data_seed={d}", f"seed={s}",
         "optimizer.lr=1.0", "optimizer.tau=1e-6", "budget.seconds=null", f"budget.max_updates={paper_updates(b, fraction)}",
         "eval_unit=updates", f"eval_every={EVAL_EVERY}"]
        for o, b, d, s in settings()
    ]  # fmt: skip


TAIL_COLUMNS = ("samples", "mean", "median", "p95", "worst_share", "max_share", "fresh_samples", "fresh_mean")


def tail_row(path: str) -> dict[str, float]:
    """The final evaluation's per-sample losses of one run, summarised, and its fresh-set mean."""
    final = load_final(path)
    losses = np.sort(final["test_losses"])
    fresh = final.get("fresh_test_losses")
    return {
        "samples": len(losses),
        "mean": losses.mean(),
        "median": np.median(losses),
        "p95": np.percentile(losses, 95),
        "worst_share": losses[-WORST:].sum() / losses.sum(),
        "max_share": losses[-1] / losses.sum(),
        "fresh_samples": 0 if fresh is None else len(fresh),
        "fresh_mean": np.nan if fresh is None else float(np.mean(fresh)),
    }


def summarise(runs: pd.DataFrame) -> pd.DataFrame:
    """One row per finished run; a diverged run keeps its row (status, the update it stopped at)
    with no losses: that it diverged is the result."""
    done = runs[runs["status"].isin(["completed", "diverged"])]
    cols = {
        "optimizer.name": "optimizer", "batch_size": "batch_size", "problem.data_seed": "data_seed", "seed": "seed",
        "status": "status", "steps": "updates", "train_time_s": "seconds",
    }  # fmt: skip
    table = done[[*cols, "path"]].rename(columns=cols)
    tails = pd.DataFrame(
        [tail_row(p) if status == "completed" else {} for p, status in zip(table["path"], table["status"])],
        index=table.index,
        columns=list(TAIL_COLUMNS),
    ).astype({"samples": "Int64", "fresh_samples": "Int64"})  # counts stay integers beside a diverged run's blanks
    keys = ["optimizer", "batch_size", "data_seed", "seed"]
    return pd.concat([table.drop(columns="path"), tails], axis=1).sort_values(keys)


def main(argv=None) -> None:
    p = probe_runs.parser("the oscillator over data draws and seeds (see docstring).", "oscillator_draws")
    p.add_argument("--fraction", type=float, default=1.0, help="of the paper's run length (a quick trial)")
    args: argparse.Namespace = probe_runs.parse(p, "probe_oscillator_draws.py", argv)
    if not args.report_only:
        probe_runs.launch(
            [probe_runs.as_job([*j, *args.set], "oscillator_draws") for j in jobs(args.fraction)], args.root, args.jobs
        )
    runs, _curves = probe_runs.runs_under(args.root)
    table = summarise(runs)
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / "oscillator_draws.csv", index=False, float_format="%.4g")
    print(table.to_string(index=False, float_format=lambda v: f"{v:.3g}"))


if __name__ == "__main__":
    main()
