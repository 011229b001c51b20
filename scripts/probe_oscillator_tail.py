"""Probe: what the oscillator's mean test loss is worth (issue osc-3, the heavy tail).

HIG at the paper's table-2 settings (b = 128, eta = 1, tau = 1e-6) on 3 data draws
(``problem.data_seed``) x 2 initialisations (``seed``), each for the same wall-clock budget.
Every run file keeps its final evaluation's per-sample test losses (``/final/test_losses``), so
the table sets the paper's metric (their mean over the 4,096 test samples) beside the median,
the 95th percentile and the share of the mean carried by the 10 worst samples.

    python scripts/probe_oscillator_tail.py                  # 6 x 300 s on 2 cores: ~16 min
    python scripts/probe_oscillator_tail.py --report-only    # re-read outputs/probes/oscillator_tail

Writes ``oscillator_tail.csv`` (one row per run) to ``--out`` (default docs/results/probes).
"""

from __future__ import annotations

import argparse

import numpy as np
import pandas as pd
import probe_runs

from higbench.runfile.reader import load_final

DATA_SEEDS = (0, 1, 2)
SEEDS = (0, 1)
WORST = 10  # samples whose share of the mean is reported


def jobs(seconds: float) -> list[list[str]]:
    return [
        ["problem=oscillator", "optimizer=hig", f"problem.data_seed={d}", f"seed={s}", f"budget.seconds={seconds:g}"]
        for d in DATA_SEEDS
        for s in SEEDS
    ]


def tail_row(path: str) -> dict[str, float]:
    """The final evaluation's per-sample losses of one run, summarised."""
    losses = np.sort(load_final(path)["test_losses"])
    return {
        "samples": len(losses),
        "mean": losses.mean(),
        "median": np.median(losses),
        "p95": np.percentile(losses, 95),
        "worst_share": losses[-WORST:].sum() / losses.sum(),
        "max_share": losses[-1] / losses.sum(),
    }


def summarise(runs: pd.DataFrame) -> pd.DataFrame:
    done = runs[runs["status"] == "completed"]
    cols = {"problem.data_seed": "data_seed", "seed": "seed", "steps": "updates", "train_time_s": "seconds"}
    table = done[[*cols, "path"]].rename(columns=cols)
    tails = pd.DataFrame([tail_row(p) for p in table["path"]], index=table.index)
    return pd.concat([table.drop(columns="path"), tails], axis=1).sort_values(["data_seed", "seed"])


def main(argv=None) -> None:
    p = probe_runs.parser("the oscillator's heavy-tailed test loss (see docstring).", "oscillator_tail")
    p.add_argument("--seconds", type=float, default=300.0, help="training clock of each run")
    args: argparse.Namespace = probe_runs.parse(p, "probe_oscillator_tail.py", argv)
    if not args.report_only:
        probe_runs.launch(
            [probe_runs.as_job([*j, *args.set], "oscillator_tail") for j in jobs(args.seconds)], args.root, args.jobs
        )
    runs, _curves = probe_runs.runs_under(args.root)
    table = summarise(runs)
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / "oscillator_tail.csv", index=False, float_format="%.4g")
    print(table.to_string(index=False, float_format=lambda v: f"{v:.3g}"))


if __name__ == "__main__":
    main()
