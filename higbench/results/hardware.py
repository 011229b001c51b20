"""One hardware class per task, and the machines behind it: the league's scorer splits a task
whose runs name more than one hardware class, and counts the machines of one class that trained
a task (one class is not one speed)."""

from __future__ import annotations

import pandas as pd


def split_by_hardware(runs: pd.DataFrame) -> pd.DataFrame:
    """One hardware class per task: a task whose runs name more than one ``hardware`` becomes one
    task per hardware ('poisson [NVIDIA H100]'), so no comparison crosses machines. Runs without
    the column are left as they are (the report says the hardware was not recorded)."""
    if "hardware" not in runs or runs.empty:
        return runs
    kinds = runs.groupby("task")["hardware"].transform("nunique")
    mixed = kinds > 1
    return runs.assign(task=runs["task"].where(~mixed, runs["task"] + " [" + runs["hardware"].astype(str) + "]"))


def machine_of(runs: pd.DataFrame) -> pd.Series:
    """Per run, which machine trained it: 'host, booted TIME' from its env, '' where the run did
    not record it (files written before runs named their machine)."""

    def text(name: str) -> pd.Series:
        return runs[name].astype(object).fillna("").astype(str) if name in runs else pd.Series("", index=runs.index)

    boot = text("env.boot_time")
    return (text("env.hostname") + ", booted " + boot).where(boot != "", "")


def hardware_line(scored: pd.DataFrame) -> str:
    """Each task's hardware class; where its scored runs name their machines and came from more
    than one, how many (one class of hardware, a cluster's nodes or a replaced machine, can
    differ in speed, and then equal seconds are not equal work); how many runs did not name one."""
    if "hardware" not in scored:
        return "hardware: not recorded in these runs (one hardware class per task cannot be checked)"
    machines = machine_of(scored)
    parts = []
    for task, group in scored.groupby("task"):
        named = machines[group.index]
        count = named[named != ""].nunique()
        parts.append(f"{task}: {group['hardware'].iloc[0]}" + (f" on {count} machines" if count > 1 else ""))
    unnamed = int((machines == "").sum())
    return ("hardware, one class per task (a task that mixed classes is split, named [hardware]): " + "; ".join(parts)
            + (f"; machine not recorded by {unnamed} of {len(scored)} scored runs" if unnamed else ""))  # fmt: skip
