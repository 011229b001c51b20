"""The league: which optimizer for which problem, with tuning counted in, and intervals.

    space = load_space("adam")                        # conf/search/adam.yaml
    trials = sobol_trials(space, n=6, seed=0)         # [{"optimizer.lr": 3.1e-3, ...}, ...]
    iqm(values); bootstrap_ci(strata, statistic)       # rliable's interval estimates
    probability_of_improvement(x, y)                  # P(X < Y), lower is better
    integrated_score(ratios, tau_max)                 # AlgoPerf: normalised area under rho

The protocol (``scripts/league.py`` runs it): every optimizer gets the same number of
quasi-random trials (scrambled Sobol points in its declared search space, log ranges) on the
tuning seeds; the best trial by *validation* loss at the budget is its setting; that setting
then runs on fresh confirmation seeds and on the problem's held-out variants
(``problem.held_out``), and only those runs are scored, on the *test* loss. The scores follow
rliable (Agarwal et al. 2021: interquartile mean, stratified bootstrap, probability of
improvement) and AlgoPerf (Dahl et al. 2023: the integrated performance profile). rliable
itself is not a dependency: its release pins an old ``arch`` (and seaborn) for a few functions,
which are written here instead, each tested on hand-made frames with known answers
(tests/results/test_league.py).
"""

from __future__ import annotations

import math
import warnings
import zlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from scipy import stats

from higbench.results.targets import of_runs, reach_index

CONFIDENCE = 0.95
BOOTSTRAP_REPS = 2000
TAU_MAX = 4.0  # AlgoPerf's: a setting more than 4x slower than the fastest scores nothing on that pair
VALIDATION_METRIC = "final_val_loss"  # what tuning reads; never a test-loss column (tests check it)
TEST_METRIC = "final_test_loss"  # read once, for the table


# -- search spaces ---------------------------------------------------------------------------


def search_dir() -> Path:
    from higbench.config import config_dir

    return Path(config_dir()) / "search"


def load_space(optimizer: str, directory: Path | None = None) -> dict[str, dict]:
    """The search space of ``optimizer``: {override key: {low, high, log, integer}} from
    conf/search/<optimizer>.yaml; ValueError naming the key and value of a bad entry."""
    path = (directory or search_dir()) / f"{optimizer}.yaml"
    if not path.is_file():
        raise ValueError(f"optimizer={optimizer}: no search space ({path.name} in conf/search/)")
    raw = yaml.safe_load(path.read_text()) or {}
    space = {}
    for key, spec in (raw.get("space") or {}).items():
        if not isinstance(spec, dict) or "low" not in spec or "high" not in spec:
            raise ValueError(f"{path.name}: space.{key}={spec!r}: expected {{low: ..., high: ...}}")
        low, high = float(spec["low"]), float(spec["high"])
        log = bool(spec.get("log", True))
        if not (low < high) or (log and low <= 0):
            raise ValueError(f"{path.name}: space.{key}: low={low:g}, high={high:g}: need 0 < low < high (log) or low < high")
        space[str(key)] = {"low": low, "high": high, "log": log, "integer": bool(spec.get("integer", False))}
    if not space:
        raise ValueError(f"{path.name}: space: empty")
    return space


def sobol_trials(space: Mapping[str, Mapping], n: int, seed: int = 0) -> list[dict[str, float | int]]:
    """``n`` scrambled Sobol points of ``space`` (scipy.stats.qmc), mapped to each key's range
    (log-uniform where ``log``; rounded to the nearest power of two for an ``integer`` log key,
    to the nearest integer otherwise). Values have 3 significant digits, so overrides stay readable."""
    keys = list(space)
    with warnings.catch_warnings():  # a count that is not a power of two loses balance, not validity
        warnings.simplefilter("ignore", UserWarning)
        points = stats.qmc.Sobol(d=len(keys), scramble=True, seed=seed).random(n)
    trials = []
    for point in points:
        trial: dict[str, float | int] = {}
        for key, u in zip(keys, point):
            s = space[key]
            if s["log"]:
                value = math.exp(math.log(s["low"]) + u * (math.log(s["high"]) - math.log(s["low"])))
            else:
                value = s["low"] + u * (s["high"] - s["low"])
            if s["integer"]:
                trial[key] = int(2 ** round(math.log2(value))) if s["log"] else int(round(value))
            else:
                trial[key] = float(f"{value:.3g}")
        trials.append(trial)
    return trials


def tuning_seed(study: int) -> int:
    """The seed of tuning study ``study`` (1000, 1001, ...): never a confirmation seed."""
    return 1000 + study


def trial_points(optimizer: str, space: Mapping[str, Mapping], n: int, study: int = 0) -> list[dict[str, float | int]]:
    """The ``n`` trial points of ``optimizer`` in study ``study``: Sobol points scrambled with a
    seed of their own per (optimizer, study), so studies draw apart and more trials keep the first."""
    return sobol_trials(space, n, seed=zlib.crc32(f"{optimizer}/{study}".encode()))


def best_trial(trials: pd.DataFrame, metric: str = VALIDATION_METRIC) -> pd.Series | None:
    """The trial with the lowest median ``metric`` over its tuning seeds (a diverged or unfinished
    run counts as inf); ``trials`` has a ``trial`` column. None when no trial finished.

    Only the validation loss is read: passing a test-loss column is refused."""
    if "test" in metric:
        raise ValueError(f"metric={metric}: tuning reads the validation loss only")
    if trials.empty:
        return None
    loss = pd.to_numeric(trials[metric], errors="coerce").where(trials["status"] == "completed")
    per_trial = loss.fillna(math.inf).groupby(trials["trial"]).median()
    if not np.isfinite(per_trial.to_numpy(dtype=float)).any():
        return None
    best = per_trial.idxmin()
    return trials[trials["trial"] == best].iloc[0]


# -- interval estimates (rliable) ------------------------------------------------------------


def iqm(values: Sequence[float]) -> float:
    """Interquartile mean: the mean of the middle 50% (scipy's trim_mean, 25% cut at each end;
    rliable's definition). inf counts as a value (a run that never reached a target)."""
    x = np.asarray(values, dtype=float)
    x = x[~np.isnan(x)]
    if not len(x):
        return math.nan
    if np.isinf(x).any():  # trim_mean would form inf - inf; trim by hand with the same rule
        x = np.sort(x)
        cut = int(0.25 * len(x))
        kept = x[cut : len(x) - cut]
        return float(np.mean(kept)) if not np.isinf(kept).any() else float(kept[np.isinf(kept)][0])
    return float(stats.trim_mean(x, 0.25))


def _iqm_rows(matrix: np.ndarray) -> np.ndarray:
    """``iqm`` of every row at once (the bootstrap's replicates)."""
    m = np.sort(matrix, axis=1)
    cut = int(0.25 * m.shape[1])
    kept = m[:, cut : m.shape[1] - cut]
    with np.errstate(invalid="ignore"):
        return kept.mean(axis=1)  # inf stays inf (a run that never reached the target)


def bootstrap_ci(
    strata: Sequence[Sequence[float]],
    statistic: Callable[[np.ndarray], float],
    reps: int = BOOTSTRAP_REPS,
    confidence: float = CONFIDENCE,
    seed: int = 0,
) -> tuple[float, float, float]:
    """(point, low, high): ``statistic`` of all values, and the percentile interval of the
    stratified bootstrap: each replicate resamples every stratum (a problem) with replacement, in
    its own size, and pools them (rliable's ``StratifiedBootstrap``)."""
    groups = [g[~np.isnan(g)] for g in (np.asarray(s, dtype=float) for s in strata)]
    groups = [g for g in groups if len(g)]
    if not groups:
        return math.nan, math.nan, math.nan
    point = statistic(np.concatenate(groups))
    rng = np.random.default_rng(seed)
    # reps x n: each row one replicate, every stratum resampled in its own size
    matrix = np.concatenate([g[rng.integers(0, len(g), (reps, len(g)))] for g in groups], axis=1)
    draws = _iqm_rows(matrix) if statistic is iqm else np.apply_along_axis(statistic, 1, matrix)
    # inverted_cdf: an observed replicate at each end, never inf - inf between two of them
    lo, hi = np.quantile(draws, [(1 - confidence) / 2, (1 + confidence) / 2], method="inverted_cdf")
    return float(point), float(lo), float(hi)


def probability_of_improvement(x: Sequence[float], y: Sequence[float]) -> float:
    """P(X < Y) + P(X = Y) / 2 for one run X of ``x`` and one run Y of ``y`` (lower is better:
    a loss or a time), the Mann-Whitney statistic over their sizes (rliable's, for lower scores)."""
    a, b = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if not len(a) or not len(b):
        return math.nan
    less = (a[:, None] < b[None, :]).mean()
    ties = (a[:, None] == b[None, :]).mean()
    return float(less + 0.5 * ties)


def probability_of_improvement_ci(
    pairs: Sequence[tuple[Sequence[float], Sequence[float]]],
    reps: int = BOOTSTRAP_REPS,
    confidence: float = CONFIDENCE,
    seed: int = 0,
) -> tuple[float, float, float]:
    """The mean over tasks of P(X < Y) (one (x, y) pair per task), with the stratified bootstrap's
    interval: x and y resampled apart within each task."""
    pairs = [(np.asarray(x, dtype=float), np.asarray(y, dtype=float)) for x, y in pairs if len(x) and len(y)]
    if not pairs:
        return math.nan, math.nan, math.nan
    point = float(np.mean([probability_of_improvement(x, y) for x, y in pairs]))
    rng = np.random.default_rng(seed)
    draws = [
        np.mean(
            [probability_of_improvement(x[rng.integers(0, len(x), len(x))], y[rng.integers(0, len(y), len(y))]) for x, y in pairs]
        )
        for _ in range(reps)
    ]
    lo, hi = np.quantile(draws, [(1 - confidence) / 2, (1 + confidence) / 2], method="inverted_cdf")
    return point, float(lo), float(hi)


# -- AlgoPerf's integrated score -------------------------------------------------------------


def integrated_score(ratios: Sequence[float], tau_max: float = TAU_MAX) -> float:
    """The area under rho(tau) from 1 to ``tau_max`` over (tau_max - 1), rho being the fraction of
    pairs with ratio <= tau: 1 for a setting fastest on every pair, 0 for one never within
    ``tau_max``. Exact for the step function: a pair of ratio r adds (tau_max - max(r, 1)) /
    (tau_max - 1) when r <= tau_max. NaN ratios (no setting solved the pair) count as unsolved."""
    r = np.asarray(ratios, dtype=float)
    if not len(r):
        return math.nan
    r = np.where(np.isnan(r), np.inf, r)
    area = np.where(r <= tau_max, tau_max - np.maximum(r, 1.0), 0.0)
    return float(area.sum() / (len(r) * (tau_max - 1.0)))


# -- time and updates to a target, per run, from the curves ----------------------------------


def reach(curves: pd.DataFrame, target: float, loss: str = "test_loss") -> tuple[float, float]:
    """(training clock, updates) at the first evaluation of one run's ``curves`` whose ``loss`` is
    at or below ``target`` (``targets.reach_index``, the one rule); (inf, inf) when none is."""
    i = reach_index(curves[loss].to_numpy(dtype=float), target)
    if i is None:
        return math.inf, math.inf
    return float(curves["wall_time"].iloc[i]), float(curves["step"].iloc[i])


# -- the league from indexed runs ------------------------------------------------------------

TUNING_SEEDS = (1000,)  # seeds of the tuning trials; never a confirmation seed (scores leave them out)
HIG = "hig"


def _override_items(overrides: str) -> list[tuple[str, str]]:
    return [tuple(i.lstrip("+~").split("=", 1)) for i in str(overrides or "").split() if "=" in i]


def task_label(row: pd.Series) -> str:
    """The problem and its variant: 'toy', or 'toy gamma=0.001' for a held-out variant (the
    run's ``problem.*`` overrides)."""
    variant = sorted(
        f"{k.removeprefix('problem.')}={v}" for k, v in _override_items(row.get("overrides")) if k.startswith("problem.")
    )
    return " ".join([str(row["problem.name"]), *variant])


def setting_label(row: pd.Series, spaces: Mapping[str, Mapping]) -> str:
    """'adam' for a tuned setting (its overrides set keys of its search space), 'adam (paper)' for
    the shipped defaults (conf/problem_optimizer/: the paper's settings where it has them)."""
    name = str(row["optimizer.name"])
    keys = set(spaces.get(name, {}))
    tuned = any(k in keys for k, _ in _override_items(row.get("overrides")))
    return name if tuned else f"{name} (paper)"


def league_runs(runs: pd.DataFrame, spaces: Mapping[str, Mapping], tuning_seeds: Sequence[int] = TUNING_SEEDS) -> pd.DataFrame:
    """The scored runs: done (completed or diverged), not on a tuning seed, with ``task`` and
    ``league_setting`` columns."""
    from higbench.results.index import DONE_STATUSES

    done = runs[runs["status"].isin(DONE_STATUSES) & ~pd.to_numeric(runs["seed"], errors="coerce").isin(tuning_seeds)]
    if done.empty:
        return done.assign(task=pd.Series(dtype=object), league_setting=pd.Series(dtype=object))
    labelled = done.assign(
        task=done.apply(task_label, axis=1), league_setting=done.apply(lambda r: setting_label(r, spaces), axis=1)
    )
    check_one_setting_per_label(labelled)
    return labelled


def check_one_setting_per_label(runs: pd.DataFrame) -> None:
    """Each (task, label) must be the seeds of one setting (``index.setting_config``): the label
    names an optimizer, tuned or at the paper's settings, and two tuned configurations of it on
    one task (two learning rates confirmed) would be scored as one. ValueError naming them."""
    if "setting_config" not in runs:
        return
    counts = runs.groupby(["task", "league_setting"])["setting_config"].nunique()
    mixed = counts[counts > 1]
    if len(mixed):
        (task, label), n = next(iter(mixed.items()))
        raise ValueError(
            f"task {task}: {label} has runs of {n} different settings (index.setting_config); the league scores one "
            "configuration per optimizer and task on its confirmation seeds: keep one under the root"
        )


def task_targets(runs: pd.DataFrame) -> dict[str, list[float]]:
    """Each task's targets: its problem config's (``targets.of_runs``: stored, else shipped)."""
    return of_runs(runs, by="task")


def reach_table(runs: pd.DataFrame, curves: pd.DataFrame, targets: Mapping[str, Sequence[float]]) -> pd.DataFrame:
    """One row per (scored run, target): seconds and updates to the target on the test loss
    (inf when not reached; a diverged run reaches what its curve reached before it stopped)."""
    rows = []
    by_path = dict(tuple(curves.groupby("path", observed=True))) if len(curves) else {}
    for _, run in runs.iterrows():
        curve = by_path.get(run["path"])
        for target in targets.get(run["task"], []):
            seconds, updates = reach(curve, target) if curve is not None else (math.inf, math.inf)
            rows.append(
                {"task": run["task"], "setting": run["league_setting"], "seed": run["seed"], "target": target,
                 "seconds": seconds, "updates": updates}
            )  # fmt: skip
    return pd.DataFrame(rows, columns=["task", "setting", "seed", "target", "seconds", "updates"])


def profile_times(reached: pd.DataFrame, unit: str) -> pd.DataFrame:
    """Per (task, target, setting) the lower median over seeds of ``unit`` (seconds or updates;
    unsolved when fewer than half reach it) and the ratio to the fastest setting: the frame
    ``results.profile.performance_profile`` reads (task as its problem)."""
    from higbench.results.profile import lower_median

    if reached.empty:
        return pd.DataFrame(columns=["problem", "target", "setting", "time", "ratio"])
    med = reached.groupby(["task", "target", "setting"])[unit].agg(lower_median).rename("time").reset_index()
    best = med.groupby(["task", "target"])["time"].transform("min")
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(np.isfinite(best), med["time"] / best.where(best > 0, np.nan), np.nan)
    ratio = np.where((best == 0) & (med["time"] == 0), 1.0, ratio)  # reached at the first evaluation
    return med.rename(columns={"task": "problem"}).assign(ratio=ratio)


def scores(times: pd.DataFrame, tau_max: float = TAU_MAX) -> pd.DataFrame:
    """Per setting: rho at tau 1, 2 and ``tau_max`` and the integrated score, best first."""
    from higbench.results.profile import performance_profile

    if times.empty:
        return pd.DataFrame(columns=["rho(1)", "rho(2)", f"rho({tau_max:g})", "score"])
    rho = performance_profile(times, [1.0, 2.0, tau_max]).T
    rho.columns = ["rho(1)", "rho(2)", f"rho({tau_max:g})"]
    pairs = times[["problem", "target"]].drop_duplicates()
    score = {}
    for name, group in times.groupby("setting"):
        ratios = pairs.merge(group, on=["problem", "target"], how="left")["ratio"]
        score[name] = integrated_score(ratios.to_numpy(dtype=float), tau_max)
    return rho.assign(score=pd.Series(score)).sort_values("score", ascending=False)


def interval_table(runs: pd.DataFrame, reached: pd.DataFrame, seed: int = 0) -> pd.DataFrame:
    """Per (task, setting): the IQM over seeds, with the bootstrap's 95% interval, of the final
    test loss, the final validation loss and the seconds and updates to each target."""
    rows = []
    for (task, setting), group in runs.groupby(["task", "league_setting"]):
        row = {"task": task, "setting": setting, "seeds": len(group)}
        for metric in (TEST_METRIC, VALIDATION_METRIC):
            values = pd.to_numeric(group.get(metric, pd.Series(dtype=float)), errors="coerce")
            # a diverged run's loss is what it reached before the NaN: scored as inf (the worst)
            values = values.where(group["status"] == "completed", math.inf).to_numpy(dtype=float)
            row[metric] = bootstrap_ci([values], iqm, seed=seed)
        mine = reached[(reached["task"] == task) & (reached["setting"] == setting)]
        for target, at in mine.groupby("target"):
            for unit in ("seconds", "updates"):
                row[f"{unit}_to_{target:g}"] = bootstrap_ci([at[unit].to_numpy(dtype=float)], iqm, seed=seed)
        rows.append(row)
    return pd.DataFrame(rows)


def improvement_table(runs: pd.DataFrame, reference: str = HIG, metric: str = TEST_METRIC, seed: int = 0) -> pd.DataFrame:
    """P(``reference`` ends below X) on ``metric`` for every other setting X: per task and the
    mean over the tasks both ran (stratified bootstrap's 95% interval). Diverged runs count as inf."""
    loss = pd.to_numeric(runs[metric], errors="coerce").where(runs["status"] == "completed", math.inf)
    runs = runs.assign(_loss=loss.fillna(math.inf))
    rows = []
    for other in sorted(set(runs["league_setting"]) - {reference}):
        pairs, per_task = [], {}
        for task, group in runs.groupby("task"):
            x = group.loc[group["league_setting"] == reference, "_loss"].to_numpy(dtype=float)
            y = group.loc[group["league_setting"] == other, "_loss"].to_numpy(dtype=float)
            if len(x) and len(y):
                pairs.append((x, y))
                per_task[task] = probability_of_improvement(x, y)
        point, lo, hi = probability_of_improvement_ci(pairs, seed=seed)
        rows.append({"versus": other, "tasks": len(pairs), "P": point, "low": lo, "high": hi, **per_task})
    return pd.DataFrame(rows)


def leaders(table: pd.DataFrame, metric: str = TEST_METRIC) -> pd.DataFrame:
    """Per task (an ``interval_table``): the setting with the lowest IQM ``metric``, the
    runner-up, whether the runner-up's interval reaches below the leader's upper bound (then
    the seeds do not separate them), and the rank of HIG tuned and at the paper's settings."""
    rows = []
    for task, group in table.groupby("task"):
        point = group[metric].map(lambda cell: cell[0] if isinstance(cell, tuple) else math.nan)
        ranked = group.assign(_point=point.fillna(math.inf)).sort_values("_point", kind="stable")
        first, second = ranked.iloc[0], ranked.iloc[1] if len(ranked) > 1 else None
        rank = {name: i + 1 for i, name in enumerate(ranked["setting"])}
        rows.append({
            "task": task, "best": first["setting"], metric: first[metric],
            "runner-up": None if second is None else second["setting"],
            "runner-up " + metric: None if second is None else second[metric],
            "separated": None if second is None else bool(second[metric][1] > first[metric][2]),
            "hig rank": rank.get(HIG), "hig (paper) rank": rank.get(f"{HIG} (paper)"), "settings": len(ranked),
        })  # fmt: skip
    return pd.DataFrame(rows)


def _ci(cell, inf: str = "not reached") -> str:
    if not isinstance(cell, tuple):
        return "" if cell is None or (isinstance(cell, float) and math.isnan(cell)) else str(cell)
    point, lo, hi = cell
    if not math.isfinite(point):
        return inf if point == math.inf else "-"
    return f"{point:.3g} [{lo:.3g}, {hi:.3g}]"


def league_frames(runs: pd.DataFrame, curves: pd.DataFrame, spaces: Mapping[str, Mapping], tuning_seeds=TUNING_SEEDS):
    """(scored runs, seconds and updates to each target per scored run, targets per task)."""
    scored = league_runs(runs, spaces, tuning_seeds)
    targets = task_targets(scored) if len(scored) else {}
    return scored, reach_table(scored, curves, targets), targets


def _task_table(group: pd.DataFrame) -> pd.DataFrame:
    """One task's rows as text cells: the final losses, then seconds and updates to each target
    that some setting reached (highest target first)."""
    reached = [c for c in group.columns if "_to_" in c and any(isinstance(v, tuple) and math.isfinite(v[0]) for v in group[c])]
    reached.sort(key=lambda c: (-float(c.split("_to_")[1]), c))
    cols = ["seeds", TEST_METRIC, VALIDATION_METRIC, *reached]
    shown = group.set_index("setting")[cols].copy()
    for c in cols[1:]:
        shown[c] = shown[c].map(
            lambda v, c=c: _ci(v, "inf (seeds diverged)" if c in (TEST_METRIC, VALIDATION_METRIC) else "not reached")
        )
    return shown.rename(columns=lambda c: c.replace("seconds_to_", "s to ").replace("updates_to_", "updates to "))


def format_league(runs: pd.DataFrame, curves: pd.DataFrame, spaces: Mapping[str, Mapping], tuning_seeds=TUNING_SEEDS) -> str:
    """The league as text: both profile views with the integrated score, the IQM table with
    intervals per task, and the probability that HIG improves on each other setting."""
    scored, reached, targets = league_frames(runs, curves, spaces, tuning_seeds)
    tuning = int(pd.to_numeric(runs["seed"], errors="coerce").isin(tuning_seeds).sum()) if len(runs) else 0
    if scored.empty:
        return f"no scored runs (done, not on a tuning seed {list(tuning_seeds)}); {tuning} tuning run(s) left out"
    out = [
        f"{len(scored)} scored runs ({scored['task'].nunique()} tasks, {scored['league_setting'].nunique()} settings,"
        f" seeds {sorted(set(pd.to_numeric(scored['seed']).astype(int)))}); {tuning} tuning run(s) left out",
        "targets (problem.targets): " + "; ".join(f"{t}: {', '.join(f'{v:g}' for v in vs)}" for t, vs in targets.items()),
    ]
    with pd.option_context("display.width", 250, "display.max_columns", None, "display.float_format", "{:.3f}".format):
        for unit, view in (("seconds", "equal wall clock"), ("updates", "equal updates")):
            out += ["", f"performance profile, {view} ({unit} to target; integrated score: area under rho up to tau={TAU_MAX:g})"]
            out.append(scores(profile_times(reached, unit)).to_string())
        table = interval_table(scored, reached)
        out += ["", "per task: IQM over seeds [95% stratified-bootstrap interval]; targets no setting reached are left out"]
        for task, group in table.groupby("task"):
            out += [f"-- {task}", _task_table(group).to_string()]
        best = leaders(table)
        for c in (TEST_METRIC, "runner-up " + TEST_METRIC):
            best[c] = best[c].map(lambda v: _ci(v, "inf (seeds diverged)"))
        out += ["", "lowest final test loss per task, IQM [95% interval]; separated: the runner-up's interval lies above"]
        out.append(best.to_string(index=False))
        for reference in (HIG, f"{HIG} (paper)"):  # HIG tuned as every optimizer, and at the paper's settings
            if reference not in set(scored["league_setting"]):
                continue
            improve = improvement_table(scored, reference)
            out += ["", f"P({reference} ends below X) on the final test loss, mean over tasks [95% interval]; per task after"]
            out.append(improve.to_string(index=False, float_format="{:.2f}".format))
    return "\n".join(out)


def all_spaces(directory: Path | None = None) -> dict[str, dict]:
    """Every shipped search space: optimizer name -> space (conf/search/*.yaml)."""
    d = directory or search_dir()
    return {p.stem: load_space(p.stem, d) for p in sorted(d.glob("*.yaml"))}


# -- figures ---------------------------------------------------------------------------------


def profile_band(reached: pd.DataFrame, unit: str, taus: Sequence[float], reps: int = 100, seed: int = 0) -> dict:
    """rho(tau) per setting, and its 95% band from resampling each (task, setting)'s seeds with
    replacement (the stratified bootstrap; the fastest setting of a pair is found again in each
    replicate): {setting: (rho, low, high)} on ``taus``."""
    from higbench.results.profile import performance_profile

    point = performance_profile(profile_times(reached, unit), taus)
    rng = np.random.default_rng(seed)
    rows = reached.reset_index(drop=True)
    # per (task, setting): the row numbers of each of its seeds (all targets of that run)
    blocks = [[np.asarray(ix) for ix in g.groupby("seed").groups.values()] for _, g in rows.groupby(["task", "setting"])]
    draws: dict[str, list] = {name: [] for name in point.columns}
    for _ in range(reps):
        picked = [block[i] for block in blocks for i in rng.integers(0, len(block), len(block))]
        rho = performance_profile(profile_times(rows.iloc[np.concatenate(picked)], unit), taus)
        for name in draws:
            draws[name].append(rho[name].to_numpy() if name in rho else np.zeros(len(taus)))
    return {
        name: (point[name].to_numpy(), *np.quantile(np.array(draws[name]), [0.025, 0.975], axis=0, method="inverted_cdf"))
        for name in point.columns
    }


def highlighted(bands: Mapping[str, tuple], tau_max: float = TAU_MAX, top: int = 5) -> set[str]:
    """The profile curves drawn in colour: the ``top`` settings by the area under rho (the
    integrated score's), and HIG tuned and at the paper's settings."""
    area = {name: float(np.mean(rho)) for name, (rho, _, _) in bands.items()}
    leaders = sorted(area, key=lambda name: -area[name])[:top]
    return {*leaders, *(n for n in (HIG, f"{HIG} (paper)") if n in bands)}


def plot_league(reached: pd.DataFrame, table: pd.DataFrame, out: Path, tau_max: float = TAU_MAX) -> list[Path]:
    """profile.png (rho in seconds and in updates, with bands) and time_to_target.png (per task,
    the IQM of seconds to each target with its interval, per setting)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    taus = np.linspace(1.0, tau_max, 61)
    settings = sorted(table["setting"].unique())
    colour = {name: plt.get_cmap("tab20")(i % 20) for i, name in enumerate(settings)}  # one colour per setting
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4), sharey=True)
    for ax, unit in zip(axes, ("seconds", "updates")):
        bands = profile_band(reached, unit, taus)
        shown = highlighted(bands, tau_max)
        for name, (rho, lo, hi) in sorted(bands.items()):
            if name not in shown:  # the rest thin and grey, so that the leaders and HIG can be read
                ax.step(taus, rho, where="post", color="0.75", lw=0.8, zorder=1)
                continue
            ax.step(taus, rho, where="post", label=name, lw=1.8, color=colour.get(name), zorder=3)
            ax.fill_between(taus, lo, hi, step="post", color=colour.get(name), alpha=0.12, zorder=2)
        ax.set_xlabel(f"tau ({unit} to target over the fastest)")
        ax.set_title(f"equal {'wall clock' if unit == 'seconds' else 'updates'} (grey: the other settings)", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left", ncol=2)
    axes[0].set_ylabel("rho(tau): fraction of (task, target) pairs")
    fig.tight_layout()
    paths = [out / "profile.png"]
    fig.savefig(paths[0], dpi=120)
    plt.close(fig)

    tasks = sorted(table["task"].unique())
    ncols = min(len(tasks), 3)
    nrows = -(-len(tasks) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.6 * ncols, 3.6 * nrows + 1.0), squeeze=False)
    for ax in axes.flat[len(tasks) :]:
        ax.set_visible(False)
    for ax, task in zip(axes.flat, tasks):
        rows = table[table["task"] == task]
        cols = [c for c in rows.columns if c.startswith("seconds_to_") and rows[c].map(lambda v: isinstance(v, tuple)).any()]
        cols.sort(key=lambda c: -float(c.split("_to_")[1]))  # this task's targets, highest first
        for _, row in rows.iterrows():
            k = settings.index(row["setting"])
            xs, ys, los, his = [], [], [], []
            for j, c in enumerate(cols):
                cell = row[c]
                if isinstance(cell, tuple) and math.isfinite(cell[0]):
                    xs.append(j + 0.6 * (k / max(len(settings) - 1, 1) - 0.5))
                    ys.append(cell[0])
                    los.append(cell[0] - cell[1])
                    his.append((cell[2] if math.isfinite(cell[2]) else cell[0]) - cell[0])
            if xs:
                ax.errorbar(xs, ys, yerr=[los, his], fmt="o", ms=4, capsize=2, color=colour[row["setting"]])
        ax.set_xticks(range(len(cols)), [f"{float(c.split('_to_')[1]):g}" for c in cols])
        ax.set_xlim(-0.5, len(cols) - 0.5)
        if ax.has_data():
            ax.set_yscale("log")
        else:
            ax.text(0.5, 0.5, "no setting reached a target", ha="center", transform=ax.transAxes, fontsize=8)
        ax.set_title(task, fontsize=9)
        ax.set_xlabel("test-loss target (not reached: no point)", fontsize=8)
        ax.grid(alpha=0.3)
    for row_axes in axes:
        row_axes[0].set_ylabel("seconds to target\n(IQM over seeds, 95% interval)", fontsize=8)
    handles = [plt.Line2D([], [], marker="o", ls="", color=colour[n], label=n) for n in settings]
    fig.legend(handles=handles, loc="lower center", ncol=min(len(settings), 9), fontsize=8)
    fig.tight_layout(rect=(0, 0.9 / (3.6 * nrows + 1.0), 1, 1))
    paths.append(out / "time_to_target.png")
    fig.savefig(paths[1], dpi=120)
    plt.close(fig)
    return paths
