"""Probe: a league problem's chosen and shipped settings again, one run at a time, on another device.

A GPU league (every optimizer tuned and confirmed on one GPU) takes hours; a GPU lent for minutes
can still answer a narrower question. This probe takes the settings the CPU league chose for a
problem (each optimizer's tuning trials, at the published validation target, by the league's own
rule ``league.choose_trial``) and the shipped ones, trains them at the league's budget per run on
the device ``--set`` names, one run at a time, seed 0 of every setting before seed 1, and says per
run how many updates it made and when it reached the published target. A run that would not end
before ``--deadline`` seconds is not started (the report names it). The tuning stays the CPU's:
a setting chosen there is not re-tuned for the device.

    python scripts/probe_league_device.py --problem poisson --set device=cuda --seeds 2 --deadline 520
    python scripts/probe_league_device.py --problem poisson --report-only --root DIR

Writes ``league_device_<problem>.csv`` (one row per run, beside the CPU league's figures for the
same setting; ``_<seconds>s`` in the name with ``--seconds``) and the runs' validation curves
(``.png``) to ``--out`` (default docs/results/probes).
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np
import pandas as pd
import probe_runs

from higbench.jobs import run_missing
from higbench.league import tables
from higbench.results import league
from higbench.results.algoperf import time_to_target

PUBLISHED = probe_runs.ROOT / "docs" / "results" / "league" / "cpu"
SET_AGAIN = ("progress=", "threads=", "seed=", "budget.seconds=", "eval_every=")  # set by every probe run
EVALUATIONS = 100  # per run, as the league's
START_S = 25.0  # a run's start-up and closing beyond its budget (CUDA start, the run file), for --deadline


def published(problem: str) -> tuple[pd.DataFrame, pd.DataFrame, float, float]:
    """The problem's tuning trials and their curves, its validation target and its budget per run."""
    runs, curves = tables.read([PUBLISHED])
    runs = runs[runs["problem.name"] == problem]
    if not (runs["league_role"] == "target").any():
        raise SystemExit(f"--problem {problem}: the published league has no target setting of it")
    target = float(
        league.targets_from_reruns(runs[runs["league_role"] == "target"], curves).set_index("task").loc[problem, "target"]
    )
    tune = runs[(runs["league_role"] == "tune") & (runs["task"] == problem)]
    if tune.empty:
        raise SystemExit(f"--problem {problem}: the published league has no tuning trials of it")
    budget = float(tune["overrides"].str.extract(r"budget\.seconds=([\d.]+)")[0].astype(float).median())
    return tune, curves[curves["path"].isin(set(tune["path"]))], target, budget


def chosen(tune: pd.DataFrame, curves: pd.DataFrame, optimizer: str, target: float) -> tuple[list[str], str, pd.DataFrame]:
    """(the chosen trial's overrides without seed and budget, the rule, that trial's tuning runs)."""
    # a trial is one point of one study: the tables' ``trial`` is its number within its study
    trials = tune[tune["optimizer.name"] == optimizer].assign(trial=lambda t: t["league_job"])
    if trials.empty:
        raise SystemExit(f"--tuned {optimizer}: no published tuning trials of it")
    best, rule = league.choose_trial(trials, curves, target)
    if best is None:
        raise SystemExit(f"--tuned {optimizer}: no tuning trial finished")
    kept = [t for t in str(best["overrides"]).split() if not t.startswith(SET_AGAIN)]
    return kept, rule, trials[trials["trial"] == best["trial"]]


def settings(args, tune, curves, target) -> dict[str, dict]:
    """label -> {overrides, rule, cpu: that setting's CPU tuning runs (tuned only)}."""
    out = {}
    for o in [s for s in args.tuned.split(",") if s]:
        overrides, rule, cpu = chosen(tune, curves, o, target)
        out[o] = {"overrides": overrides, "rule": rule, "cpu": cpu}
    for o in [s for s in args.paper.split(",") if s]:
        out[f"{o} (paper)"] = {"overrides": [f"problem={args.problem}", f"optimizer={o}"], "rule": "shipped", "cpu": None}
    return out


def job_overrides(setting: dict, seed: int, budget: float, extra: list[str]) -> list[str]:
    return ["threads=1", "progress=false", *setting["overrides"], f"seed={seed}", f"budget.seconds={budget:g}",
            f"eval_every={budget / EVALUATIONS:g}", *extra]  # fmt: skip


def train(args, table: dict, budget: float) -> list[str]:
    """Seed-major, one run at a time, none started past the deadline: the labels not run."""
    start, skipped = time.monotonic(), []
    for seed in range(args.seeds):
        for label, setting in table.items():
            job = probe_runs.as_job(job_overrides(setting, seed, budget, args.set), f"league_device {label}")
            if time.monotonic() - start + budget + START_S > args.deadline:
                skipped.append(f"{label} seed {seed}")
                continue
            run_missing([job], args.root, n_jobs=1, log=lambda text: print(text, file=sys.stderr, flush=True))
    return skipped


def label_of(run: pd.Series, table: dict) -> str:
    """The setting a run under the root belongs to, by its overrides."""
    tokens = set(str(run["overrides"]).split())
    for label, setting in table.items():
        if set(setting["overrides"]) <= tokens and f"optimizer={run['optimizer.name']}" in setting["overrides"]:
            return label
    return "?"


def cpu_figures(setting: dict, target: float, budget: float) -> dict:
    """The CPU league's tuning runs of a tuned setting: updates per second, time to the target."""
    cpu = setting["cpu"]
    if cpu is None:
        return {"cpu_updates_per_s": math.nan, "cpu_time_to_target_s": math.nan}
    return {"cpu_updates_per_s": float((cpu["steps"].astype(float) / cpu["train_time_s"].astype(float)).median()),
            "cpu_time_to_target_s": float(np.median([time_to_target(c, s, target, budget) for c, s in
                                                      zip(cpu["curve"], cpu["status"], strict=True)]))}  # fmt: skip


def report(args, table: dict, target: float, budget: float, league_budget: float, curves: pd.DataFrame) -> pd.DataFrame:
    here, here_curves = probe_runs.runs_under(args.root)
    by_path = dict(tuple(here_curves.groupby("path")))
    cpu_curves = dict(tuple(curves.groupby("path")))
    for setting in table.values():
        if setting["cpu"] is not None:
            setting["cpu"] = setting["cpu"].assign(curve=setting["cpu"]["path"].map(cpu_curves.get))
    rows = []
    for _, run in here.sort_values(["optimizer.name", "seed"]).iterrows():
        label = label_of(run, table)
        steps, seconds = float(run["steps"]), float(run["train_time_s"])
        rows.append({"setting": label, "seed": int(run["seed"]), "device": run.get("env.device_name", ""),
                     "status": run["status"], "updates": int(steps), "train_s": round(seconds, 1),
                     "updates_per_s": round(steps / seconds, 2) if seconds > 0 else math.nan,
                     "time_to_target_s": time_to_target(by_path.get(run["path"]), run["status"], target, budget),
                     "final_val_loss": float(run["final_val_loss"]), "target": target, "budget_s": budget,
                     **(cpu_figures(table[label], target, league_budget) if label in table else {}),
                     "overrides": " ".join(table[label]["overrides"]) if label in table else run["overrides"]})  # fmt: skip
    return pd.DataFrame(rows)


def figure(args, table: dict, result: pd.DataFrame, target: float, path) -> None:
    """Validation loss against training clock, one line per run, the published target dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    here, curves = probe_runs.runs_under(args.root)
    label = dict(zip(here["path"], [label_of(r, table) for _, r in here.iterrows()], strict=True))
    fig, ax = plt.subplots(figsize=(6.4, 4))
    colors = dict(zip(table, plt.cm.tab10.colors, strict=False))
    for run_path, curve in curves.groupby("path"):
        seed = int(here.loc[here["path"] == run_path, "seed"].iloc[0])
        ax.plot(curve["wall_time"], curve["val_loss"], color=colors.get(label[run_path], "grey"), lw=1.2,
                ls=("-", "--", ":")[seed % 3], label=f"{label[run_path]}, seed {seed}")  # fmt: skip
    ax.axhline(target, color="k", ls="--", lw=0.8, label=f"the CPU league's target {target:.3g}")
    ax.set(yscale="log", xlabel="training clock (s)", ylabel="validation loss",
           title=f"{args.problem}: the CPU league's settings on {result['device'].iloc[0]}, one run at a time")  # fmt: skip
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> None:
    p = probe_runs.parser("A league problem's chosen and shipped settings on another device (see docstring).", "league_device")
    p.add_argument("--problem", default="poisson")
    p.add_argument("--tuned", default="adamw,hig,adam", help="optimizers whose CPU-league choice is run")
    p.add_argument("--paper", default="hig,adam,gn", help="optimizers run at their shipped settings")
    p.add_argument("--seeds", type=int, default=2)
    p.add_argument("--seconds", type=float, help="budget per run (default: the league's)")
    p.add_argument("--deadline", type=float, default=math.inf, help="seconds after which no run starts")
    args = probe_runs.parse(p, "probe_league_device.py", argv)
    tune, curves, target, budget = published(args.problem)
    league_budget, budget = budget, args.seconds or budget
    table = settings(args, tune, curves, target)
    for label, setting in table.items():
        print(f"{label}: {' '.join(setting['overrides'])} ({setting['rule']})", file=sys.stderr)
    skipped = [] if args.report_only else train(args, table, budget)
    result = report(args, table, target, budget, league_budget, curves)
    args.out.mkdir(parents=True, exist_ok=True)
    name = f"league_device_{args.problem}" + (f"_{budget:g}s" if args.seconds else "")
    result.to_csv(args.out / f"{name}.csv", index=False)
    if len(result):
        figure(args, table, result, target, args.out / f"{name}.png")
    with pd.option_context("display.width", 250, "display.max_colwidth", 60):
        print(result.drop(columns=["overrides"]).round(4).to_string(index=False))
    if skipped:
        print(f"not started (deadline {args.deadline:g} s): {', '.join(skipped)}")


if __name__ == "__main__":
    main()
