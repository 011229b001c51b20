"""Time to target and performance profiles (AlgoPerf-style) from the results index.

    runs = load_runs("outputs")                    # time_to_<t> at each run's problem.targets
    targets = targets.of_runs(runs)                # per problem: its config's targets
    runs = runs.assign(setting=setting_labels(runs))
    times = time_to_target(runs, targets)          # one row per (problem, target, setting)
    rho = performance_profile(times, taus)         # one column per setting

For each (problem, target) pair, a setting's time is the median over its seeds of the
training clock at which the test loss first reached the target, a seed that never reached
it counting as infinite. The median is the lower one for an even number of seeds, so a pair
is unsolved (infinite time) exactly when fewer than half of the seeds reach the target.
The ratio is that time over the fastest setting's on the same pair; rho(tau) is the fraction
of pairs a setting solves within tau times the fastest (Dolan and More 2002; AlgoPerf's
scoring uses the same profile).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from higbench.results.index import DONE_STATUSES, threshold_column
from higbench.results.index import NOT_SETTING_KEYS as INDEX_NOT_SETTING_KEYS

# Override keys that do not make a different setting (for runs without a ``setting_config``,
# e.g. a hand-made table): index.NOT_SETTING_KEYS, and the problem (what panels split by).
NOT_SETTING_KEYS = ("problem", *(k for k in INDEX_NOT_SETTING_KEYS if k not in ("budget",)), "budget.seconds",
                    "budget.max_updates")  # fmt: skip
# Keys compared within one optimizer: the per-(problem, optimizer) defaults differ between
# optimizers by design (conf/problem_optimizer), so only a value that varies among one
# optimizer's runs names a setting. Any other key that varies within a problem (problem.gamma,
# dtype, device) is named on every setting of that problem.
PER_OPTIMIZER_KEYS = ("optimizer.", "batch_size")
# What --best selects over within a setup (the paper's table 2 tunes the learning rate and the
# batch size); every other key that changes a result makes a setup of its own.
BEST_OVER = ("optimizer.lr", "batch_size")


def setting_labels(runs: pd.DataFrame, keys: Sequence[str] | None = None, leave_out: Sequence[str] = ()) -> pd.Series:
    """A label per run naming its optimizer setting: the one setting key of --plot, --profile
    and --best (runs with one label are seeds of one setting).

    keys: config columns that define a setting (e.g. ``optimizer.name,optimizer.lr``);
    default: every config key that changes a result (``index.setting_config``: all but the
    seed, the budget, the evaluation schedule and the cosmetic keys), labelled by the
    optimizer's name and the keys whose values differ (``adam lr=0.001``,
    ``gn problem.gamma=0.01``). Runs without a ``setting_config`` column are labelled from
    their command-line overrides instead.
    leave_out: config keys that do not count either (--best's setups leave out the keys it
    selects over, ``BEST_OVER``).
    """
    if not len(runs):
        return pd.Series([], dtype=object)
    if keys:
        return runs[list(keys)].astype(str).agg(" ".join, axis=1)
    labels = runs.apply(lambda row: _label_from_overrides(row, leave_out), axis=1).astype(object)
    has = runs["setting_config"].notna() if "setting_config" in runs else pd.Series(False, index=runs.index)
    if has.any():  # rows without one: unreadable files, hand-made tables
        labels[has] = _labels_from_config(runs[has], leave_out)
    return labels


def _label_from_overrides(row: pd.Series, leave_out: Sequence[str] = ()) -> str:
    name, kept = str(row.get("optimizer.name")), []
    for item in str(row.get("overrides") or "").split():
        key, _, value = item.lstrip("+~").partition("=")
        if key == "optimizer":
            name = value
        elif key not in NOT_SETTING_KEYS and key not in leave_out and not key.startswith("hydra."):
            kept.append(item.lstrip("+").removeprefix("optimizer."))
    return " ".join([name, *kept])


def _value(v: object) -> str:
    return f"{v:g}" if isinstance(v, float) else json.dumps(v) if isinstance(v, list) else str(v)


def _labels_from_config(runs: pd.DataFrame, leave_out: Sequence[str] = ()) -> pd.Series:
    """Per problem: the optimizer's name, then key=value for each key that tells settings apart."""
    configs = runs["setting_config"].map(lambda text: {k: v for k, v in json.loads(text).items() if k not in leave_out})
    ids = configs.map(lambda c: json.dumps(c, sort_keys=True))
    problems = runs.get("problem.name", pd.Series("", index=runs.index)).astype(str)
    optimizers = configs.map(lambda c: str(c.get("optimizer.name")))
    labels = pd.Series("", index=runs.index, dtype=object)
    for _, idx in problems.groupby(problems).groups.items():
        keys = sorted({k for c in configs[idx] for k in c} - {"optimizer.name", "problem.name"})

        def varies(key: str, among: pd.Index) -> bool:
            return len({json.dumps(configs[i].get(key), default=str) for i in among}) > 1

        for opt, among in optimizers[idx].groupby(optimizers[idx]).groups.items():
            shown = [k for k in keys if varies(k, among if k.startswith(PER_OPTIMIZER_KEYS) else idx)]
            for i in among:
                parts = [f"{k.removeprefix('optimizer.')}={_value(configs[i].get(k))}" for k in shown]
                labels[i] = " ".join([opt, *parts])
        # Settings that still share a label (a key only one setting has, shown nowhere): numbered
        for label, same in labels[idx].groupby(labels[idx]).groups.items():
            distinct = list(dict.fromkeys(ids[same]))
            if len(distinct) > 1:
                for i in same:
                    labels[i] = f"{label} #{distinct.index(ids[i]) + 1}"
    return labels


def budget_labels(runs: pd.DataFrame) -> pd.Series:
    """'60s', '1000 updates' or '60s|1000 updates' per run, from its budget config."""

    def one(row: pd.Series) -> str:
        parts = []
        seconds, updates = row.get("budget.seconds"), row.get("budget.max_updates")
        if seconds is not None and not pd.isna(seconds):
            parts.append(f"{float(seconds):g}s")
        if updates is not None and not pd.isna(updates):
            parts.append(f"{int(updates)} updates")
        return "|".join(parts) or "none"

    return runs.apply(one, axis=1) if len(runs) else pd.Series([], dtype=object)


def parse_targets(items: Sequence[str]) -> dict[str, list[float]]:
    """['poisson=1,0.1', 'toy=1e-3'] -> {'poisson': [1.0, 0.1], 'toy': [0.001]}; ValueError says which."""
    targets: dict[str, list[float]] = {}
    for item in items:
        name, sep, values = item.partition("=")
        if not sep or not name or not values:
            raise ValueError(f"--targets {item}: expected PROBLEM=LOSS[,LOSS...], e.g. poisson=1,0.1")
        try:
            levels = [float(v) for v in values.split(",") if v]
        except ValueError:
            raise ValueError(f"--targets {item}: the target losses must be numbers") from None
        if not levels or any(not (v > 0 and math.isfinite(v)) for v in levels):
            raise ValueError(f"--targets {item}: the target losses must be positive and finite")
        targets[name] = levels
    return targets


def all_targets(targets: Mapping[str, Sequence[float]]) -> tuple[float, ...]:
    """Every target level once: the thresholds ``load_runs`` computes columns for."""
    return tuple(sorted({t for levels in targets.values() for t in levels}, reverse=True))


def lower_median(values: Sequence[float]) -> float:
    """The median, the lower of the two middle values for an even count (inf counts as a value)."""
    ordered = np.sort(np.asarray(values, dtype=float))
    return float(ordered[(len(ordered) - 1) // 2]) if len(ordered) else math.inf


def _reach_times(group: pd.DataFrame, column: str, horizon: float) -> np.ndarray:
    """Per run: training clock at the target, inf when not reached (or only after ``horizon``)."""
    t = pd.to_numeric(group[column], errors="coerce").to_numpy(dtype=float) if column in group else np.full(len(group), np.nan)
    return np.where(np.isfinite(t) & (t <= horizon), t, np.inf)


def comparison_horizon(runs: pd.DataFrame) -> float:
    """The training clock that every run of a problem had: inf when all share one time budget,
    else the clock at which the shortest-budget runs stopped (a run may overshoot its budget by
    up to one update). Targets reached after it do not count, so a longer budget buys nothing.

    Only runs that ran out their budget (``completed``) set it: a diverged run stopped early
    for its own reason, and its short clock must not cut the others' comparison short (it
    simply never reaches the later targets)."""
    seconds = pd.to_numeric(runs.get("budget.seconds", pd.Series(np.nan, index=runs.index)), errors="coerce")
    if seconds.nunique(dropna=False) <= 1:
        return math.inf
    status = runs.get("status", pd.Series("completed", index=runs.index))
    shortest = runs[(seconds == seconds.min()) & (status == "completed")]
    clock = pd.to_numeric(shortest.get("train_time_s", pd.Series(dtype=float)), errors="coerce").dropna()
    return float(clock.min()) if len(clock) else float(seconds.min())


def time_to_target(runs: pd.DataFrame, targets: Mapping[str, Sequence[float]], setting: str = "setting") -> pd.DataFrame:
    """One row per (problem, target, setting): ``seeds``, ``reached`` (seeds at the target),
    ``time_s`` (lower median over the seeds of its done runs, completed or diverged; inf
    when fewer than half reached it), ``ratio`` (time over the fastest setting's on the
    pair; inf when unsolved, NaN when no setting solved the pair) and ``horizon_s`` (the
    shortest budget of the problem's runs: a target reached only after it counts as not
    reached, so every setting gets the same time)."""
    rows = []
    for problem, levels in targets.items():
        group = runs[(runs["problem.name"] == problem) & runs["status"].isin(DONE_STATUSES)]
        if group.empty:
            continue
        horizon = comparison_horizon(group)
        for target in levels:
            column = threshold_column(target)
            for name, runs_of_setting in group.groupby(setting, sort=True):
                times = _reach_times(runs_of_setting, column, horizon)
                rows.append(
                    {
                        "problem": problem,
                        "target": target,
                        "setting": name,
                        "seeds": len(times),
                        "reached": int(np.isfinite(times).sum()),
                        "time_s": lower_median(times),
                        "horizon_s": horizon,
                    }
                )
    df = pd.DataFrame(rows, columns=["problem", "target", "setting", "seeds", "reached", "time_s", "horizon_s"])
    if df.empty:  # no problem with targets among the runs
        return df.assign(ratio=pd.Series(dtype=float))
    best = df.groupby(["problem", "target"])["time_s"].transform("min")
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(np.isfinite(best), df["time_s"] / best.where(best > 0, np.nan), np.nan)
    # The fastest setting reaching a target at the initial evaluation (t = 0): ratio 1 for
    # every setting also at 0, the others' ratio undefined (the target says nothing).
    at_zero = (best == 0).to_numpy()
    ratio = np.where(at_zero & (df["time_s"] == 0).to_numpy(), 1.0, np.where(at_zero, np.nan, ratio))
    return df.assign(ratio=ratio)


def performance_profile(times: pd.DataFrame, taus: Sequence[float]) -> pd.DataFrame:
    """rho(tau) per setting: the fraction of (problem, target) pairs whose ratio is <= tau.

    Every pair counts in the denominator, also one that no setting solved (AlgoPerf's rule:
    such a pair lowers every setting's rho alike). Index: tau; columns: settings.
    """
    pairs = times[["problem", "target"]].drop_duplicates()
    n = len(pairs)
    out = {}
    for name, group in times.groupby("setting", sort=True):
        ratios = group["ratio"].to_numpy(dtype=float)
        ratios = np.where(np.isnan(ratios), np.inf, ratios)
        out[name] = [float((ratios <= tau).sum()) / n if n else math.nan for tau in taus]
    return pd.DataFrame(out, index=pd.Index(list(taus), name="tau"))


def format_table(times: pd.DataFrame, with_ratio: bool = True) -> str:
    """The time-to-target table: one row per (problem, target), one column per setting;
    cells 'time s (ratio x)' or 'not reached (k/n seeds)'."""
    if times.empty:
        return "(no runs of the problems with targets)"

    def cell(row: pd.Series) -> str:
        if not np.isfinite(row["time_s"]):
            return f"- ({row['reached']}/{row['seeds']})"
        ratio = f" ({row['ratio']:.2g}x)" if with_ratio and np.isfinite(row["ratio"]) else ""
        return f"{row['time_s']:.3g}s{ratio}"

    table = times.assign(cell=times.apply(cell, axis=1)).pivot_table(
        index=["problem", "target"], columns="setting", values="cell", aggfunc="first"
    )
    table.index = [f"{p} <= {t:g}" for p, t in table.index]
    table.columns.name = None
    return table.fillna("").to_string()
