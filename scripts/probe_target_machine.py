"""Probe: the target setting of the CPU league again, on the machine that trains the league now.

The league's validation targets and budgets (piece 1) were set on the rebuild's first machine;
its dipole and Poisson pieces train on a second machine of the same class that trains these
networks 1.5-3.3x faster (docs/results/league/machines.txt). This probe reruns the same
target-setting reruns (each reference's chosen setting, the same 5 seeds and seconds, from the
published tables) on the machine it runs on, and sets the targets as the protocol would
(``algoperf.targets_from_reruns``). Per task it prints both machines' reference medians, the
target and budget each would set, how fast the reference reaches the published target here,
and the updates per second of each reference on each machine.

    python scripts/probe_target_machine.py --jobs 1                # ~15 min on one core
    python scripts/probe_target_machine.py --report-only           # re-read outputs/probes/target_machine

Writes ``target_machine.csv`` (one row per task) to ``--out`` (default docs/results/probes).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import probe_runs

from higbench.league import tables
from higbench.results import league
from higbench.results.algoperf import targets_from_reruns, time_to_target

PUBLISHED = probe_runs.ROOT / "docs" / "results" / "league" / "cpu"
BASE_TASKS = ("toy", "oscillator", "dipole", "poisson")  # the problems; their held-out variants are not rerun
NOT_RERUN = ("progress=", "threads=")  # set again by every probe run


def published_reruns() -> tuple[pd.DataFrame, pd.DataFrame]:
    """The published target-setting reruns of the base tasks, and their curves."""
    runs, curves = tables.read([PUBLISHED])
    reruns = runs[(runs["league_role"] == "target") & runs["task"].isin(BASE_TASKS)]
    return reruns, curves[curves["path"].isin(set(reruns["path"]))]


def jobs(reruns: pd.DataFrame) -> list[list[str]]:
    """Each published rerun's overrides, the same seed and seconds, on one thread."""
    out = []
    for overrides in sorted(reruns["overrides"]):
        kept = [t for t in str(overrides).split() if not t.startswith(NOT_RERUN)]
        out.append(["threads=1", "progress=false", *kept])
    return out


def rates(runs: pd.DataFrame) -> pd.Series:
    """Median updates per training-clock second per (task, reference)."""
    done = runs[runs["status"] == "completed"]
    return (
        (done["steps"].astype(float) / done["train_time_s"].astype(float))
        .groupby([done["task"], done["optimizer.name"]])
        .median()
    )


def summarise(published: pd.DataFrame, published_curves: pd.DataFrame, here: pd.DataFrame, here_curves: pd.DataFrame):
    """One row per task: each machine's target setting, and the reference's time here to the published target."""
    theirs = targets_from_reruns(published, published_curves).set_index("task")
    ours = targets_from_reruns(here, here_curves).set_index("task")
    rate_then, rate_now = rates(published), rates(here)
    by_path = dict(tuple(here_curves.groupby("path")))
    rows = []
    for task in theirs.index.intersection(ours.index):
        then, now = theirs.loc[task], ours.loc[task]
        ref = here[(here["task"] == task) & (here["optimizer.name"] == then["reference"])]
        to_published = [time_to_target(by_path.get(r["path"]), r["status"], then["target"], math.inf) for _, r in ref.iterrows()]
        rows.append({
            "task": task, "reference_then": then["reference"], "target_then": then["target"], "budget_then_s": then["budget_s"],
            "reference_now": now["reference"], "target_now": now["target"], "budget_now_s": now["budget_s"],
            "target_ratio": now["target"] / then["target"],
            "now_to_target_then_s": float(np.median(to_published)),
            "medians_then": then["medians"], "medians_now": now["medians"],
            "rate_ratio": {o: round(float(rate_now[task, o] / rate_then[task, o]), 2)
                           for o in sorted(then["medians"]) if (task, o) in rate_now and (task, o) in rate_then},
        })  # fmt: skip
    return pd.DataFrame(rows)


def main(argv=None) -> None:
    args = probe_runs.parse(
        probe_runs.parser("The target setting again on this machine (see docstring).", "target_machine"),
        "probe_target_machine.py",
        argv,
    )
    published, published_curves = published_reruns()
    if not args.report_only:
        todo = [probe_runs.as_job([*j, *args.set], "target_machine") for j in jobs(published)]
        probe_runs.launch(todo, args.root, args.jobs)
    here, here_curves = probe_runs.runs_under(args.root)
    here = here.assign(task=here.apply(league.task_label, axis=1))
    table = summarise(published, published_curves, here, here_curves)
    machines = league.machine_of(here).replace("", "not recorded").unique()
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / "target_machine.csv", index=False)
    with pd.option_context("display.width", 250, "display.max_colwidth", 80):
        print(f"reruns here: {len(here)} on {', '.join(machines)}")
        print(table.round(4).to_string(index=False))


if __name__ == "__main__":
    main()
