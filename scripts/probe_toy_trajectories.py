"""Probe: toy-6's y-space trajectories over three seeds (the figure's plotted data keep seed 0's only).

Figure 1 plots the probe sample's trajectory of the first seed, so the committed data let toy-6
read one seed. This probe trains the four runs toy-6 reads (γ=0.01: Adam and HIG; γ=1: Adam and
GN, each at the toy's defaults, the paper's settings) for seeds 0, 1 and 2, for a fixed number of
updates (not seconds: the trajectories do not depend on this CPU or its load), evaluating every
``UPDATES // 250`` updates, and measures each run's trajectory with toy-6's own functions
(``higbench.paper.toy``): the share of the distance to the target along y_2 left at the end,
and the aim at the target after GN's initial phase (each seed's GN run sets it for that seed).

    python scripts/probe_toy_trajectories.py                # 12 short runs, two at a time
    python scripts/probe_toy_trajectories.py --report-only  # re-read outputs/probes/toy_trajectories

Writes ``toy_trajectories.csv`` (one row per run) to ``--out`` (default docs/results/probes).
Runs already under ``--root`` are reused, so an interrupted probe resumes.
"""

from __future__ import annotations

import pandas as pd
import probe_runs

from higbench.paper.toy import aim_at_target, initial_phase_end, y2_gap_left
from higbench.problems.toy import target_function
from higbench.runfile.reader import load_logs

SEEDS = (0, 1, 2)
UPDATES = 10_000
RUNS = {0.01: ("adam", "hig"), 1.0: ("adam", "gn")}  # γ -> the optimizers toy-6 reads there


def jobs() -> list[list[str]]:
    return [
        [
            "problem=toy",
            f"problem.gamma={gamma:g}",
            f"optimizer={opt}",
            f"seed={seed}",
            f"budget.max_updates={UPDATES}",
            "budget.seconds=3600",
            "eval_unit=updates",
            f"eval_every={UPDATES // 250}",
        ]  # fmt: skip
        for gamma, opts in RUNS.items()
        for opt in opts
        for seed in SEEDS
    ]


def measure(runs: pd.DataFrame) -> pd.DataFrame:
    """One row per run: its trajectory's share left along y_2 and, at γ=1, its aim after GN's initial phase."""
    import torch

    rows = []
    for _, r in runs.iterrows():
        y = load_logs(r["path"])["probe_output"]
        x = torch.tensor([[float(r.get("problem.probe_x", 0.5) or 0.5)]], dtype=torch.float64)
        rows.append({"gamma": r["problem.gamma"], "optimizer": r["optimizer.name"], "seed": int(r["seed"]),
                     "status": r["status"], "updates": int(r["steps"]), "path": r["path"], "y": y,
                     "target": target_function(x)[0].numpy()})  # fmt: skip
    table = pd.DataFrame(rows)
    gn = {row.seed: initial_phase_end(row.y, row.target) for row in table[table["optimizer"] == "gn"].itertuples()}
    table["y2_left"] = [y2_gap_left(y, t) for y, t in zip(table["y"], table["target"])]
    table["aim"] = [
        aim_at_target(row.y, row.target, gn[row.seed]) if row.gamma == 1.0 and row.seed in gn else float("nan")
        for row in table.itertuples()
    ]
    return table.drop(columns=["y", "target", "path"]).sort_values(["gamma", "optimizer", "seed"])


def main(argv=None) -> None:
    args = probe_runs.parse(
        probe_runs.parser("toy-6's trajectories over three seeds (see docstring).", "toy_trajectories"),
        "probe_toy_trajectories.py",
        argv,
    )
    if not args.report_only:
        probe_runs.launch([probe_runs.as_job([*j, *args.set], "toy_trajectories") for j in jobs()], args.root, args.jobs)
    runs, _ = probe_runs.runs_under(args.root)
    table = measure(runs[runs["problem.name"] == "toy"])
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / "toy_trajectories.csv", index=False, float_format="%.4g")
    print(table.to_string(index=False))


if __name__ == "__main__":
    main()
