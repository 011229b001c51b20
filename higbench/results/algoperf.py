"""AlgoPerf's score (Dahl et al. 2023) on the league's runs: validation targets and budgets from
target-setting runs, and time to the target within the budget as the score.

    validation_target({"adam": finals, "adamw": finals})   # (reference, its median final val loss)
    budget_from_target(seconds_to_target)                  # 3x the reference's median time to it
    targets_from_reruns(reruns, curves)                    # both, per task, from the runs' tables
    algoperf_table(scored, curves, targets, budgets)       # per setting: seconds per problem, score

Pure functions of run tables and curves (``higbench.results.index.load_runs``' frames or the
league's exported tables); the league (``higbench.results.league``) reads them from here.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from higbench.results import stats
from higbench.results.targets import reach_index

TAU_MAX = 4.0  # AlgoPerf's: a setting more than 4x slower than the fastest scores nothing on that problem
VALIDATION_METRIC = "final_val_loss"  # what tuning reads; never a test-loss column (tests check it)


def reach(curves: pd.DataFrame, target: float, loss: str = "test_loss") -> tuple[float, float]:
    """(training clock, updates) at the first evaluation of one run's ``curves`` whose ``loss`` is
    at or below ``target`` (``targets.reach_index``, the one rule); (inf, inf) when none is."""
    i = reach_index(curves[loss].to_numpy(dtype=float), target)
    if i is None:
        return math.inf, math.inf
    return float(curves["wall_time"].iloc[i]), float(curves["step"].iloc[i])


# -- AlgoPerf's score: targets from target-setting runs, budgets, time to target ----------------


def integrated_score(ratios: Sequence[float], tau_max: float = TAU_MAX) -> float:
    """The area under rho(tau) from 1 to ``tau_max`` over (tau_max - 1), rho being the fraction of
    problems with ratio <= tau: 1 for a setting fastest on every problem, 0 for one never within
    ``tau_max``. Exact for the step function: a problem of ratio r adds (tau_max - max(r, 1)) /
    (tau_max - 1) when r <= tau_max. NaN ratios (no setting reached the target) count as unsolved."""
    r = np.asarray(ratios, dtype=float)
    if not len(r):
        return math.nan
    r = np.where(np.isnan(r), np.inf, r)
    area = np.where(r <= tau_max, tau_max - np.maximum(r, 1.0), 0.0)
    return float(area.sum() / (len(r) * (tau_max - 1.0)))


MIN_TARGET_RERUNS = 5


def validation_target(
    reference_final_val: Mapping[str, Sequence[float]], min_reruns: int = MIN_TARGET_RERUNS
) -> tuple[str, float]:
    """(reference optimizer, target) from target-setting runs: each reference optimizer's tuned
    setting rerun at the budget; its median final validation loss over >= ``min_reruns`` reruns;
    the target is the lowest such median (AlgoPerf's). ValueError when a reference has fewer reruns."""
    medians = {}
    for name, losses in reference_final_val.items():
        x = np.asarray(losses, dtype=float)
        if len(x) < min_reruns:
            raise ValueError(f"target-setting runs: {name} has {len(x)} reruns; need at least {min_reruns}")
        medians[name] = float(np.median(np.where(np.isfinite(x), x, math.inf)))
    best = min(medians, key=lambda n: (medians[n], n))
    if not math.isfinite(medians[best]):
        raise ValueError("target-setting runs: no reference optimizer has a finite median validation loss")
    return best, medians[best]


def budget_from_target(reference_seconds_to_target: Sequence[float], factor: float = 3.0) -> float:
    """The problem's budget: ``factor`` (AlgoPerf: 3) times the reference's median training-clock
    seconds to its own validation target over its reruns; ValueError when the median is not finite."""
    median = float(np.median(np.asarray(reference_seconds_to_target, dtype=float)))
    if not math.isfinite(median):
        raise ValueError("budget: the reference reached its own target on fewer than half its reruns")
    return factor * median


TARGET_COLUMNS = ["task", "reference", "target", "budget_s", "reruns", "medians", "seconds_to_target"]


def no_targets() -> pd.DataFrame:
    """The target setting of no reruns: ``targets_from_reruns``' frame with no task."""
    return pd.DataFrame(columns=TARGET_COLUMNS)


def targets_from_reruns(reruns: pd.DataFrame, curves: pd.DataFrame, factor: float = 3.0) -> pd.DataFrame:
    """Per task, from its target-setting reruns (rows with ``task``, ``optimizer.name``, ``status``,
    ``final_val_loss`` and the curves' join key): the reference whose median final validation loss
    is lowest, that median as the validation target (``validation_target``: at least
    ``MIN_TARGET_RERUNS`` reruns per reference), and the budget, ``factor`` x that reference's
    median training-clock seconds to its own target (``budget_from_target``). One row per task:
    task, reference, target, budget_s, reruns, every reference's median, the seconds per rerun.
    A task whose references give no finite target is left out (the report says so)."""
    key = "run" if "run" in curves and "run" in reruns else "path"
    by_run = dict(tuple(curves.groupby(key, observed=True))) if len(curves) else {}
    rows = []
    for task, group in reruns.groupby("task", sort=True):
        losses = {str(o): stats.scored_loss(g[VALIDATION_METRIC], g["status"]) for o, g in group.groupby("optimizer.name")}
        try:
            reference, target = validation_target(losses)
        except ValueError as exc:
            warnings.warn(f"task {task}: no validation target ({exc})", stacklevel=2)
            continue
        ref = group[group["optimizer.name"] == reference]
        seconds = [time_to_target(by_run.get(r[key]), r["status"], target, math.inf) for _, r in ref.iterrows()]
        rows.append({"task": task, "reference": reference, "target": target,
                     "budget_s": budget_from_target(seconds, factor), "reruns": len(ref),
                     "medians": {o: float(np.median(x)) for o, x in losses.items()},
                     "seconds_to_target": [float(s) for s in seconds]})  # fmt: skip
    return pd.DataFrame(rows, columns=TARGET_COLUMNS)


def format_targets(found: pd.DataFrame) -> str:
    """The target setting as text: per task the reference, the validation target (the lowest median
    final validation loss of a reference over its reruns), every reference's median, and the budget
    with the reference's seconds to the target on each rerun (inf: not reached)."""
    if found.empty:
        return "target setting: no validation targets (no reference reruns in the tables)"
    lines = ["target setting (validation targets and budgets, AlgoPerf's way): per task the reference with the lowest "
             "median final validation loss over its reruns; the budget is 3x its median seconds to that target"]  # fmt: skip
    for _, row in found.iterrows():
        medians = ", ".join(f"{o} {m:.3g}" for o, m in sorted(row["medians"].items()))
        seconds = ", ".join("inf" if not math.isfinite(t) else f"{t:.3g}" for t in row["seconds_to_target"])
        lines.append(f"  {row['task']}: target {row['target']:.4g} ({row['reference']}; medians: {medians}), budget "
                     f"{row['budget_s']:.3g} s (seconds to target per rerun: {seconds})")  # fmt: skip
    return "\n".join(lines)


def time_to_target(curve: pd.DataFrame | None, status: str, target: float, budget: float) -> float:
    """Training-clock seconds at which one run's validation loss first reaches ``target``; inf
    when it never does within ``budget``, or the run diverged before (scored one way: worst)."""
    if curve is None or curve.empty:
        return math.inf
    seconds = reach(curve, target, loss="val_loss")[0]
    return seconds if seconds <= budget else math.inf


def problems_in_play(
    scored: pd.DataFrame, targets: Mapping[str, float], held_out: Mapping[str, Sequence[str]] | None = None
) -> tuple[list[str], list[str]]:
    """(problems scored, problems with a target but no scored run yet). A league run in pieces has
    targets for every problem before it has confirmation runs on each; a problem nobody has run
    yet is left out of the score (and said so), not scored as failed by every setting."""
    variants = {v for vs in (held_out or {}).values() for v in vs}
    ran = set(scored["task"])
    problems = sorted(p for p in targets if p not in variants)
    return [p for p in problems if p in ran], [p for p in problems if p not in ran]


def algoperf_table(
    scored: pd.DataFrame,
    curves: pd.DataFrame,
    targets: Mapping[str, float],
    budgets: Mapping[str, float],
    held_out: Mapping[str, Sequence[str]] | None = None,
    tau_max: float = TAU_MAX,
) -> pd.DataFrame:
    """Per setting, AlgoPerf's score: per problem (the keys of ``targets`` with scored runs, each
    weighing the same; ``problems_in_play``) the median over seeds of the seconds to the problem's
    validation target within its budget (inf when fewer than half reach it), the ratio to the
    fastest setting, and the integrated score over problems. Held-out variants (``held_out``:
    problem -> its variant tasks, each with its own target and budget) are gates, not problems,
    as in AlgoPerf: a setting whose median on a variant is inf fails that gate ('gates failed')
    and its time on the variant's problem becomes inf in ``score``; ``score, gates ignored`` is
    the area without that rule, to show what the gates cost. A variant the setting has no runs
    on is 'gates not run', neither failed nor passed."""
    key = "run" if "run" in curves and "run" in scored else "path"
    by_run = dict(tuple(curves.groupby(key, observed=True))) if len(curves) else {}

    def median_time(task: str, setting: str) -> float:
        group = scored[(scored["task"] == task) & (scored["league_setting"] == setting)]
        if group.empty:
            return math.nan
        t = [time_to_target(by_run.get(r[key]), r["status"], targets[task], budgets[task]) for _, r in group.iterrows()]
        return float(np.sort(t)[(len(t) - 1) // 2])  # the lower median: inf unless half the seeds reach it

    settings = sorted(set(scored["league_setting"]))
    problems, _ = problems_in_play(scored, targets, held_out)
    times = pd.DataFrame({p: {s: median_time(p, s) for s in settings} for p in problems}, index=settings)
    gates = {s: {(p, v): median_time(v, s) for p in problems for v in (held_out or {}).get(p, []) if v in targets}
             for s in settings}  # fmt: skip
    gated = times.copy()  # AlgoPerf: a failed gate makes the problem's time inf, before the fastest is taken
    for setting, results in gates.items():
        for (problem, _), t in results.items():
            if math.isinf(t):
                gated.loc[setting, problem] = math.inf
    ratios, ungated = _ratios(gated), _ratios(times)
    rows = []
    for setting in settings:
        rows.append({"setting": setting, "score": integrated_score(ratios.loc[setting].to_numpy(dtype=float), tau_max),
                     "score, gates ignored": integrated_score(ungated.loc[setting].to_numpy(dtype=float), tau_max),
                     **{f"s to target: {p}": times.loc[setting, p] for p in problems},
                     "gates failed": ", ".join(v for (_, v), t in gates[setting].items() if math.isinf(t)),
                     "gates not run": ", ".join(v for (_, v), t in gates[setting].items() if math.isnan(t))})  # fmt: skip
    table = pd.DataFrame(rows)
    if not table["gates not run"].astype(bool).any():
        table = table.drop(columns="gates not run")
    return table.sort_values(["score", "score, gates ignored"], ascending=False, kind="stable").reset_index(drop=True)


def _ratios(times: pd.DataFrame) -> pd.DataFrame:
    """Each setting's time over the fastest on each problem (NaN where no setting reached it)."""
    fastest = times.min(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return times / fastest.where(np.isfinite(fastest) & (fastest > 0))
