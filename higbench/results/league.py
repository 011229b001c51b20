"""The league: which optimizer for which problem, with tuning counted in, and statistics that
mean what they say at the number of seeds used.

    space = load_space("adam")                          # conf/search/adam.yaml
    trial_points("adam", space, n=16, study=0)          # this optimizer's own Sobol stream
    tuning_seed(study=0)                                # 1000: never a confirmation seed
    choose_trial(trials, curves, target)                # (best trial, the rule it was chosen by)
    league_frames(runs, curves, spaces)                 # (scored runs, time to targets, targets)
    format_league(runs, curves, spaces)                 # the report
    final_loss_table(scored)                            # per task: medians, seeds, intervals, tests

The protocol (docs/results/league/README.md): every optimizer gets the same number of trials,
scrambled Sobol points of its declared search space (conf/search/), from a stream of its own
(``trial_points``); the trial that is best on what is scored (time to the validation target when
validation curves exist, else the final validation loss) is its setting; that setting runs on
fresh confirmation seeds and the problem's held-out variants, and only those runs are scored, on
the test loss. The statistics are in ``higbench.results.stats``: per task the median with every
seed, an order-statistics interval with its exact coverage, P(X < Y) against the leader (lowest
median) and an exact one-sided Mann-Whitney test, Holm-corrected over the task's comparisons;
across tasks rliable's IQM and probability of improvement with stratified-bootstrap intervals.
The time-to-target score follows AlgoPerf (Dahl et al. 2023); ``algoperf_*`` below.
"""

from __future__ import annotations

import math
import warnings
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from scipy import stats as scipy_stats

from higbench.results import stats
from higbench.results.algoperf import (  # noqa: F401  (re-exported: the league's score, one import away)
    MIN_TARGET_RERUNS,
    TAU_MAX,
    VALIDATION_METRIC,
    algoperf_table,
    budget_from_target,
    format_targets,
    integrated_score,
    no_targets,
    problems_in_play,
    reach,
    targets_from_reruns,
    time_to_target,
    validation_target,
)
from higbench.results.hardware import hardware_line, machine_of, split_by_hardware  # noqa: F401  (re-exported)
from higbench.results.targets import of_runs

TEST_METRIC = "final_test_loss"  # read once, for the table
HIG = "hig"
LONG_ROLE, LONG_PAPER_ROLE = "long", "long-paper"  # the long budget (results.long_budget): a tuned setting; a shipped one
LONG_ROLES = (LONG_ROLE, LONG_PAPER_ROLE)
ROLES = ("tune", "confirm", "paper", "default", "target-tune", "target", *LONG_ROLES)  # league_role, where the driver records it
TARGET_ROLE = "target"  # a target-setting rerun: a reference optimizer's tuned setting at the target-setting budget
SHIPPED_ROLES = ("paper", "default")  # an optimizer at its shipped settings: the paper's, else the defaults
SCORED_ROLES = ("confirm", *SHIPPED_ROLES)
TUNE_ROLES = ("tune", "target-tune")  # a league tuning trial; a reference's trial in the target setting
TUNING_SEED_BASE = 1000  # tuning seeds are 1000 + study; confirmation seeds stay below
MAX_STUDIES = 1000
TUNING_SEEDS = (TUNING_SEED_BASE,)  # study 0's: the driver before studies; scoring leaves out every seed >= 1000


# -- search spaces and the trials ------------------------------------------------------------


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


def all_spaces(directory: Path | None = None) -> dict[str, dict]:
    """Every shipped search space: optimizer name -> space (conf/search/*.yaml)."""
    d = directory or search_dir()
    return {p.stem: load_space(p.stem, d) for p in sorted(d.glob("*.yaml"))}


def in_space(space: Mapping[str, Mapping], key: str, value: float) -> bool:
    """Whether ``value`` of ``key`` lies in the space's range (an integer log key: its powers of
    two in range, as ``sobol_trials`` rounds)."""
    s = space[key]
    return s["low"] * (1 - 1e-9) <= float(value) <= s["high"] * (1 + 1e-9)


def sobol_trials(space: Mapping[str, Mapping], n: int, seed: int = 0) -> list[dict[str, float | int]]:
    """``n`` scrambled Sobol points of ``space`` (scipy.stats.qmc), mapped to each key's range
    (log-uniform where ``log``; rounded to the nearest power of two for an ``integer`` log key,
    to the nearest integer otherwise). Values have 3 significant digits, so overrides stay readable."""
    keys = list(space)
    with warnings.catch_warnings():  # a count that is not a power of two loses balance, not validity
        warnings.simplefilter("ignore", UserWarning)
        points = scipy_stats.qmc.Sobol(d=len(keys), scramble=True, seed=seed).random(n)
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


def stream_seed(optimizer: str, study: int) -> int:
    """The Sobol scrambling seed of one optimizer's study: a stable hash (CRC-32) of both, so
    two optimizers with same-shaped spaces never share points, and a rerun gets the same ones."""
    return zlib.crc32(f"{optimizer}/study{int(study)}".encode())


def trial_points(optimizer: str, space: Mapping[str, Mapping], n: int, study: int = 0) -> list[dict[str, float | int]]:
    """The ``n`` trials of ``optimizer`` in ``study``: scrambled Sobol points of ``space`` from the
    optimizer's own stream (``stream_seed``). More trials keep the first ones."""
    return sobol_trials(space, n, seed=stream_seed(optimizer, study))


def tuning_seed(study: int) -> int:
    """The training seed of every trial of ``study`` (1000 + study): distinct per study, and never
    a confirmation seed (those stay below 1000)."""
    if not (0 <= int(study) < MAX_STUDIES):
        raise ValueError(f"study={study}: must be in [0, {MAX_STUDIES})")
    return TUNING_SEED_BASE + int(study)


def best_trial(trials: pd.DataFrame, metric: str = VALIDATION_METRIC) -> pd.Series | None:
    """The trial with the lowest median ``metric`` over its tuning seeds (a diverged or unfinished
    run counts as inf); ``trials`` has a ``trial`` column. None when no trial finished.

    Only the validation loss is read: passing a test-loss column is refused."""
    if "test" in metric:
        raise ValueError(f"metric={metric}: tuning reads the validation loss only")
    if trials.empty:
        return None
    loss = pd.Series(stats.scored_loss(trials[metric], trials["status"]), index=trials.index)
    per_trial = loss.groupby(trials["trial"]).median()
    if not np.isfinite(per_trial.to_numpy(dtype=float)).any():
        return None
    best = per_trial.idxmin()
    return trials[trials["trial"] == best].iloc[0]


def choose_trial(
    trials: pd.DataFrame, curves: pd.DataFrame | None = None, target: float | None = None
) -> tuple[pd.Series | None, str]:
    """(best trial, the rule it was chosen by). Tuning selects on what is scored: with validation
    curves (``curves`` keyed by ``path`` or ``run`` as ``trials``, with ``val_loss``) and a
    validation ``target``, the lowest median time to that target over the trial's seeds (not
    reached: inf; ties: the lower median final validation loss); otherwise the lowest median
    final validation loss (``best_trial``). The rule is said, so the report can state it."""
    key = "run" if "run" in trials else "path"
    if target is None or curves is None or curves.empty or "val_loss" not in curves or key not in curves:
        return best_trial(trials), "final validation loss (median over tuning seeds)"
    by_run = dict(tuple(curves.groupby(key, observed=True)))
    seconds = [
        reach(by_run[r], target, loss="val_loss")[0] if r in by_run else math.inf
        for r in trials[key]
    ]  # fmt: skip
    loss = stats.scored_loss(trials[VALIDATION_METRIC], trials["status"])
    times = pd.Series(np.where(trials["status"] == "completed", seconds, math.inf), index=trials.index)
    per_trial = pd.DataFrame({"time": times.groupby(trials["trial"]).median(),
                              "loss": pd.Series(loss, index=trials.index).groupby(trials["trial"]).median()})  # fmt: skip
    rule = f"time to the validation target {target:g} (median over tuning seeds; ties: final validation loss)"
    if not np.isfinite(per_trial["time"]).any():
        return best_trial(trials), f"final validation loss (no trial reached the validation target {target:g})"
    best = per_trial.sort_values(["time", "loss"], kind="stable").index[0]
    return trials[trials["trial"] == best].iloc[0], rule


# -- time to a target, per run, from the curves ----------------------------------------------


# -- the scored runs -------------------------------------------------------------------------


def _override_items(overrides: str) -> list[tuple[str, str]]:
    return [tuple(i.lstrip("+~").split("=", 1)) for i in str(overrides or "").split() if "=" in i]


def task_label(row: pd.Series) -> str:
    """The problem and its variant: 'toy', or 'toy gamma=0.001' for a held-out variant. A league
    job names its variant (``<role>/<problem>/<variant or base>/...``; tuning is on the problem),
    so a ``--set problem.*`` that every job of the problem carries is not a variant; without the
    job's name (an older league's runs.csv), the run's ``problem.*`` overrides are."""
    job = row.get("league_job")
    if isinstance(job, str) and job:
        parts = job.split("/")
        items = parts[2].split() if parts[0] not in TUNE_ROLES and len(parts) > 3 and parts[2] != "base" else []
    else:
        items = [f"{k}={v}" for k, v in _override_items(row.get("overrides")) if k.startswith("problem.")]
    return " ".join([str(row["problem.name"]), *sorted(item.removeprefix("problem.") for item in items)])


def setting_label(row: pd.Series, spaces: Mapping[str, Mapping]) -> str:
    """'adam' for a tuned setting; 'adam (paper)' and 'adam (default)' for the shipped settings.
    Where the run carries ``league_role`` the role says which (paper: conf/problem_optimizer/,
    the paper's; default: the optimizer's own defaults); otherwise a run whose overrides set no
    key of its search space is '(paper)'."""
    name = str(row["optimizer.name"])
    role = row.get("league_role")
    if isinstance(role, str) and role in SHIPPED_ROLES:
        return f"{name} ({role})"
    if isinstance(role, str) and role == "confirm":
        return name
    keys = set(spaces.get(name, {}))
    tuned = any(k in keys for k, _ in _override_items(row.get("overrides")))
    return name if tuned else f"{name} (paper)"


def one_run_per_identity(runs: pd.DataFrame) -> pd.DataFrame:
    """One run per identity (``config_id``, which includes the seed): two leagues into one root
    trained some jobs twice, and the copies are not extra seeds. Keeps the first by ``path``/``run``."""
    if "config_id" not in runs or runs.empty:
        return runs
    key = "run" if "run" in runs else "path"
    ordered = runs.sort_values(key, kind="stable") if key in runs else runs
    return ordered.drop_duplicates("config_id", keep="first").sort_index()


def is_tuning_seed(seed) -> pd.Series:
    """Whether a seed is a tuning seed (``tuning_seed``: 1000 and above)."""
    return pd.to_numeric(seed, errors="coerce") >= TUNING_SEED_BASE


def league_runs(runs: pd.DataFrame, spaces: Mapping[str, Mapping], tuning_seeds: Sequence[int] | None = None) -> pd.DataFrame:
    """The scored runs: done (completed or diverged), one per identity, with ``task`` and
    ``league_setting`` columns. With ``league_role``: roles confirm, paper and default; without
    it: every run not on a tuning seed (``tuning_seeds``, or every seed from 1000)."""
    from higbench.results.index import DONE_STATUSES

    done = runs[runs["status"].isin(DONE_STATUSES)]
    if "league_role" in done:
        done = done[done["league_role"].isin(SCORED_ROLES)]
    else:
        seeds = pd.to_numeric(done["seed"], errors="coerce")
        done = done[~(is_tuning_seed(seeds) if tuning_seeds is None else seeds.isin(tuning_seeds))]
    done = one_run_per_identity(done)
    if done.empty:
        return done.assign(task=pd.Series(dtype=object), league_setting=pd.Series(dtype=object))
    labelled = done.assign(
        task=done.apply(task_label, axis=1), league_setting=done.apply(lambda r: setting_label(r, spaces), axis=1)
    )
    check_one_setting_per_label(labelled)
    return split_by_hardware(labelled)


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
    """One row per (scored run, target): training-clock seconds to the target on the test loss
    (inf when not reached, diverged runs included)."""
    rows = []
    key = "run" if "run" in curves and "run" in runs else "path"
    by_run = dict(tuple(curves.groupby(key, observed=True))) if len(curves) else {}
    for _, run in runs.iterrows():
        curve = by_run.get(run[key])
        for target in targets.get(run["task"], []):
            seconds = reach(curve, target)[0] if curve is not None else math.inf
            rows.append({"task": run["task"], "setting": run["league_setting"], "seed": run["seed"], "target": target,
                         "seconds": seconds})  # fmt: skip
    return pd.DataFrame(rows, columns=["task", "setting", "seed", "target", "seconds"])


def confirmation_under_way(runs: pd.DataFrame) -> dict[str, str]:
    """Per problem whose league tuning is in the tables and whose confirmation is not whole yet: what
    is still missing. Whole: every tuned optimizer has confirmation runs on each of the problem's
    tasks; every optimizer run at its shipped settings on some problem of the tables (the driver's
    ``--paper``, the same for every problem of a league) and tuned on this one has shipped runs on
    each of its tasks; and every confirmed or shipped setting as many seeds as the most any has.
    A sitting stopped mid-confirmation leaves some settings run and others not (the driver runs
    the tuned settings first, the shipped ones last); a leader among those would be a leader
    among the settings that happened to run first, so such a problem is not scored."""
    from higbench.results.index import DONE_STATUSES

    if "league_role" not in runs or runs.empty:
        return {}
    done = runs[runs["status"].isin(DONE_STATUSES)]
    shipped_anywhere = set(done.loc[done["league_role"].isin(SHIPPED_ROLES), "optimizer.name"])
    out = {}
    for problem, group in done.groupby("problem.name", sort=True):
        tuned = set(group.loc[group["league_role"] == "tune", "optimizer.name"]) - set(_without_a_setting(group))
        scored = one_run_per_identity(group[group["league_role"].isin(SCORED_ROLES)])
        if not tuned or scored.empty:
            continue
        tasks = scored.apply(task_label, axis=1)
        shipped = scored["league_role"].isin(SHIPPED_ROLES)
        missing = _not_on_every_task(tuned, scored[~shipped], tasks[~shipped], set(tasks))
        missing_shipped = _not_on_every_task(tuned & shipped_anywhere, scored[shipped], tasks[shipped], set(tasks))
        seeds = scored.groupby([tasks, scored["optimizer.name"], scored["league_role"]]).size()
        short = seeds[seeds < seeds.max()]
        if missing or missing_shipped or len(short):
            parts = [f"not yet run on every task: {', '.join(missing)}"] if missing else []
            if missing_shipped:
                parts.append(f"not yet run at its shipped settings on every task: {', '.join(missing_shipped)}")
            parts += (
                [f"{len(short)} of {len(seeds)} (task, setting) pairs at fewer than {seeds.max()} seeds"] if len(short) else []
            )
            out[str(problem)] = "; ".join(parts)
    return out


def _without_a_setting(runs: pd.DataFrame) -> list[str]:
    """The optimizers (sorted) tuned in ``runs`` (one problem's) from whose trials the driver chose
    nothing (``best_trial`` is None: every trial diverged or failed on some tuning seed), so they
    have no setting to confirm. Tables without the validation loss: none."""
    tune = runs[runs["league_role"] == "tune"]
    if VALIDATION_METRIC not in tune or tune.empty:
        return []
    trials = tune.assign(trial=tune["league_job"] if "league_job" in tune else tune["path"])
    return sorted(o for o, group in trials.groupby("optimizer.name") if best_trial(group) is None)


def without_a_setting(runs: pd.DataFrame) -> dict[str, list[str]]:
    """Per problem, the optimizers its tuning chose no setting for (``_without_a_setting``)."""
    from higbench.results.index import DONE_STATUSES

    if "league_role" not in runs or runs.empty:
        return {}
    done = runs[runs["status"].isin(DONE_STATUSES)]
    found = {str(p): _without_a_setting(g) for p, g in done.groupby("problem.name", sort=True)}
    return {p: names for p, names in found.items() if names}


def _not_on_every_task(optimizers: set[str], runs: pd.DataFrame, tasks: pd.Series, every_task: set[str]) -> list[str]:
    """The ``optimizers`` (sorted) without a row in ``runs`` (labelled ``tasks``) on some task of ``every_task``."""
    ran = set(zip(tasks, runs["optimizer.name"]))
    return [o for o in sorted(optimizers) if any((t, o) not in ran for t in every_task)]


def league_frames(runs: pd.DataFrame, curves: pd.DataFrame, spaces: Mapping[str, Mapping], tuning_seeds=None,
                  under_way: Mapping[str, str] | None = None):  # fmt: skip
    """(scored runs, seconds to each target per scored run, targets per task); a problem whose
    confirmation is under way (``under_way``, else ``confirmation_under_way(runs)``) is left out
    of all three."""
    scored = league_runs(runs, spaces, tuning_seeds)
    under_way = confirmation_under_way(runs) if under_way is None else under_way
    if under_way and "problem.name" in scored:
        scored = scored[~scored["problem.name"].astype(str).isin(under_way)]
    scored = with_first_losses(scored, curves)
    targets = task_targets(scored) if len(scored) else {}
    return scored, reach_table(scored, curves, targets), targets


# -- per task: the final loss ----------------------------------------------------------------


def final_loss_seeds(scored: pd.DataFrame, metric: str = TEST_METRIC) -> dict[str, dict[str, np.ndarray]]:
    """{task: {setting: scored losses of its seeds}} (diverged: inf)."""
    out: dict[str, dict[str, np.ndarray]] = {}
    for (task, setting), group in scored.groupby(["task", "league_setting"], sort=True):
        out.setdefault(task, {})[setting] = stats.scored_column(group, metric)
    return out


def with_first_losses(runs: pd.DataFrame, curves: pd.DataFrame) -> pd.DataFrame:
    """``runs`` with each run's first evaluated test and validation loss (``first_test_loss``,
    ``first_val_loss``; NaN without a curve): the scoring reads a completed run that ended above
    its first evaluation as a finite blow-up (``stats.scored_loss``), and a row whose seeds all
    stayed there as a constant predictor (``stats.flag_row``)."""
    key = "run" if "run" in curves and "run" in runs else "path"
    firsts = {}
    for column in ("test_loss", "val_loss"):
        first = math.nan
        if len(curves) and key in curves and key in runs and column in curves:
            first = runs[key].map(curves.groupby(key, observed=True)[column].first()).astype(float)
        firsts[f"first_{column}"] = first
    return runs.assign(**firsts)


def final_loss_table(
    scored: pd.DataFrame, metric: str = TEST_METRIC, constant_loss: Mapping[str, float] | None = None
) -> pd.DataFrame:
    """Per task and setting (sorted by median, the leader first): the median of ``metric``, every
    seed, the order-statistics interval and its coverage, P(leader < X), the exact one-sided
    Mann-Whitney p-value, Holm-adjusted over the task's comparisons, the verdict, and a flag
    (``stats.flag_row``: diverged on every seed, or a constant predictor: at the task's
    ``constant_loss``, or, where the runs carry their first evaluation (``with_first_losses``), no
    move from it). A seed that ended above its first evaluation is scored as diverged."""
    first = scored.get(metric.replace("final_", "first_", 1))
    rows = []
    for task, by_setting in final_loss_seeds(scored, metric).items():
        for row in stats.compare_to_leader(by_setting):
            group = scored[(scored["task"] == task) & (scored["league_setting"] == row["setting"])]
            moved_from = None if first is None else first[group.index]  # a NaN (no curve) is never "no move"
            flag = stats.flag_row(group[metric], group["status"], (constant_loss or {}).get(task), moved_from)
            interval = row.pop("interval")
            rows.append({"task": task, **row, "low": interval.low, "high": interval.high,
                         "coverage": interval.coverage, "n": interval.n, "flag": flag or ""})  # fmt: skip
    return pd.DataFrame(rows)


DIVERGED_TEXT = "diverged, or ended above its first evaluation: inf, the worst"


def _g(v: float) -> str:
    return "inf" if v == math.inf else f"{v:.2g}"


def format_final_loss_table(table: pd.DataFrame, metric: str = TEST_METRIC) -> str:
    """The per-task table as text: one block per task, the leader first."""
    out = []
    for task, group in table.groupby("task", sort=False):
        lead = group[group["leader"]].iloc[0]
        ns = sorted(set(group["n"]))
        coverage = ", ".join(f"{c:.1%} at n={n}" for n, c in sorted(set(zip(group["n"], group["coverage"]))))
        comparisons = len(group) - 1
        smallest = stats.smallest_attainable_p(min(ns), min(ns))
        after_holm = min(1.0, smallest * comparisons)  # Holm multiplies the smallest p by the comparisons
        cannot = ": no ordering can be separated at this seed count" if after_holm >= stats.ALPHA else ""
        out += [
            f"-- {task}: leader (lowest median {metric}) {lead['setting']}; interval: order statistics for the "
            f"median, coverage {coverage}; test: exact one-sided Mann-Whitney (leader below X), Holm over "
            f"{comparisons} comparisons; smallest attainable p at n={min(ns)}: {smallest:.3g}, after Holm "
            f"{after_holm:.3g}{cannot}",
        ]
        lines = [("setting", "median", "seeds", "interval", "P(lead<X)", "p", "p Holm", "verdict")]
        for _, r in group.iterrows():
            verdict = "leader" if r["leader"] else ("separated" if r["separated"] else "not separated")
            if r["flag"]:
                verdict += f"; FLAGGED: {r['flag']}"
            lines.append((
                r["setting"], _g(r["median"]), " ".join(_g(v) for v in r["seeds"]), f"[{_g(r['low'])}, {_g(r['high'])}]",
                "" if r["leader"] else f"{r['p_leader_below']:.2f}", "" if r["leader"] else f"{r['p_value']:.3g}",
                "" if r["leader"] else f"{r['p_holm']:.3g}", verdict,
            ))  # fmt: skip
        widths = [max(len(line[i]) for line in lines) for i in range(len(lines[0]))]
        out += ["  ".join(c.ljust(w) for c, w in zip(line, widths)).rstrip() for line in lines]
    return "\n".join(out)


# -- across tasks (rliable) ------------------------------------------------------------------


def aggregate_table(scored: pd.DataFrame, metric: str = TEST_METRIC, reference: str = HIG, seed: int = 0) -> pd.DataFrame:
    """Across tasks, the rliable way, per setting: the IQM over (task, seed) of normalised scores
    (``stats.normalised_scores``: 1 at the task leader's median, 0 at the task's worst finite
    median or worse, diverged 0; a loss <= 0, float rounding, counts as the task's lowest positive
    loss), with the stratified bootstrap's percentile interval, and
    P(``reference`` < X) averaged over the tasks both ran. Settings are compared on the tasks
    they ran ('tasks')."""
    seeds = final_loss_seeds(scored, metric)
    for task, by_setting in seeds.items():  # a loss <= 0 is rounding (the dipole's 1 - |<psi, target>|^2 in float32)
        positive = np.concatenate([v[(v > 0) & np.isfinite(v)] for v in by_setting.values()])
        floor = positive.min() if len(positive) else 1.0
        seeds[task] = {name: np.where(v > 0, v, floor) for name, v in by_setting.items()}
    best, worst = {}, {}
    for task, by_setting in seeds.items():
        medians = np.array([np.median(v) for v in by_setting.values()])
        finite = medians[np.isfinite(medians)]
        if len(finite) >= 2 and finite.min() > 0 and finite.max() > finite.min():
            best[task], worst[task] = float(finite.min()), float(finite.max())
    rows = []
    settings = sorted({s for by_setting in seeds.values() for s in by_setting})
    for setting in settings:
        columns = [
            stats.normalised_scores(v[:, None], [worst[t]], [best[t]])[:, 0]
            for t, by_setting in seeds.items() if t in best and len(v := by_setting.get(setting, np.array([])))
        ]  # fmt: skip
        point, lo, hi = stats.stratified_bootstrap_ci(columns, stats.iqm, seed=seed)
        shared = [t for t, by_setting in seeds.items() if setting in by_setting and reference in by_setting]
        p = (
            float(np.mean([stats.probability_of_improvement(seeds[t][reference], seeds[t][setting]) for t in shared]))
            if shared and setting != reference else math.nan
        )  # fmt: skip
        rows.append({"setting": setting, "tasks": len(columns), "iqm": point, "low": lo, "high": hi,
                     f"P({reference} < X)": p, "tasks with both": len(shared) if setting != reference else 0})  # fmt: skip
    return pd.DataFrame(rows).sort_values("iqm", ascending=False, kind="stable").reset_index(drop=True)


def per_problem_aggregates(scored: pd.DataFrame) -> list[str]:
    """The aggregate of ``aggregate_table`` over each problem's own tasks (the problem and its
    held-out variants), one table per problem, when more than one problem is scored: what the
    league says about one problem, re-computable beside what it says across all of them."""
    problems = scored["problem.name"].astype(str) if "problem.name" in scored else pd.Series(dtype=str)
    if problems.nunique() < 2:
        return []
    out = []
    for problem in sorted(problems.unique()):
        of_problem = scored[problems == problem]
        tasks = ", ".join(sorted(of_problem["task"].unique()))
        out += ["", f"across {problem}'s tasks alone ({tasks}): as above", aggregate_table(of_problem).to_string(index=False)]
    return out


# -- the decade targets' profile (time to the problem.targets on the test loss) ----------------


def profile_times(reached: pd.DataFrame, unit: str = "seconds") -> pd.DataFrame:
    """Per (task, target, setting) the lower median over seeds of ``unit`` (unsolved when fewer
    than half reach it) and the ratio to the fastest setting: the frame
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


def interval_table(runs: pd.DataFrame, reached: pd.DataFrame) -> pd.DataFrame:
    """Per (task, setting): (median, low, high) cells, the interval the order statistics' (its
    coverage in ``coverage``), of the final test and validation loss and the seconds to each target."""
    rows = []
    for (task, setting), group in runs.groupby(["task", "league_setting"]):
        row = {"task": task, "setting": setting, "seeds": len(group)}
        for metric in (TEST_METRIC, VALIDATION_METRIC):
            values = stats.scored_column(group, metric) if metric in group else np.full(len(group), math.inf)
            interval = stats.median_interval(values)
            row[metric] = (float(np.median(values)), interval.low, interval.high)
            row["coverage"] = interval.coverage
        mine = reached[(reached["task"] == task) & (reached["setting"] == setting)]
        for target, at in mine.groupby("target"):
            values = at["seconds"].to_numpy(dtype=float)
            interval = stats.median_interval(values)
            row[f"seconds_to_{target:g}"] = (float(np.median(values)), interval.low, interval.high)
        rows.append(row)
    return pd.DataFrame(rows)


# -- the report ------------------------------------------------------------------------------


def seeds_text(scored: pd.DataFrame) -> str:
    """'3 seeds' or '3-10 seeds' per task and setting."""
    counts = scored.groupby(["task", "league_setting"]).size()
    low, high = int(counts.min()), int(counts.max())
    return f"{low} seeds" if low == high else f"{low}-{high} seeds"


def format_league(
    runs: pd.DataFrame,
    curves: pd.DataFrame,
    spaces: Mapping[str, Mapping],
    tuning_seeds=None,
    validation_targets: Mapping[str, float] | None = None,
    budgets: Mapping[str, float] | None = None,
    held_out: Mapping[str, Sequence[str]] | None = None,
    frames: tuple[pd.DataFrame, pd.DataFrame, dict] | None = None,
    under_way: Mapping[str, str] | None = None,
) -> str:
    """The league as text: per task the final test loss (median, every seed, order-statistics
    interval, tests against the leader), flagged rows, the aggregate across tasks, AlgoPerf's
    score where target-setting runs gave ``validation_targets`` and ``budgets`` per task
    (``algoperf_table``; ``held_out``: problem -> its variant tasks, the gates), and the time to
    the problems' test-loss targets (equal wall clock; no equal-updates view: an update of L-BFGS
    or LM is many evaluations, so updates are not equal work). ``frames`` and ``under_way``:
    ``league_frames``'s and ``confirmation_under_way``'s, when the caller has them already."""
    still_confirming = confirmation_under_way(runs) if under_way is None else under_way
    scored, reached, targets = frames or league_frames(runs, curves, spaces, tuning_seeds, still_confirming)
    left_out = len(runs) - len(scored)
    under_way = [f"{p} ({why})" for p, why in still_confirming.items()]
    confirmation_lines = ["not scored until its confirmation is whole: " + "; ".join(under_way)] if under_way else []
    unset = without_a_setting(runs)
    confirmation_lines += (["no setting to confirm (every tuning trial diverged or failed): "
                        + "; ".join(f"{p}: {', '.join(names)}" for p, names in unset.items())] if unset else [])  # fmt: skip
    if scored.empty:
        return "\n".join([f"no scored runs (done, confirmation or shipped settings); {left_out} run(s) left out "
                          "(tuning, unfinished)", *confirmation_lines])  # fmt: skip
    out = [
        f"{len(scored)} scored runs ({scored['task'].nunique()} tasks, {scored['league_setting'].nunique()} settings, "
        f"{seeds_text(scored)} per task and setting); {left_out} run(s) left out "
        f"(tuning, unfinished, a second run of one identity{', or of a problem still confirming' if under_way else ''})",
        *confirmation_lines,
        hardware_line(scored),
        "",
        f"final test loss per task: median and every seed ({DIVERGED_TEXT})",
        format_final_loss_table(final_loss_table(scored)),
    ]
    with pd.option_context("display.width", 250, "display.max_columns", None, "display.float_format", "{:.3f}".format):
        out += ["", "across tasks (rliable): IQM over (task, seed) of normalised scores (1: the task leader's median, "
                "0: the task's worst finite median or diverged), percentile stratified bootstrap (nominal 95%; "
                "not exact at few seeds); P(hig < X) averaged over the tasks both ran"]  # fmt: skip
        out.append(aggregate_table(scored).to_string(index=False))
        out += per_problem_aggregates(scored)
        if validation_targets and budgets:
            playing, waiting = problems_in_play(scored, validation_targets, held_out)
            tasks = [t for t in validation_targets if t in playing or any(t in (held_out or {}).get(p, ()) for p in playing)]
            given = "; ".join(f"{t}: target {validation_targets[t]:.4g}, budget {budgets[t]:.3g} s" for t in tasks)
            out += ["", "AlgoPerf: seconds to the validation target within the budget (median over seeds; inf: fewer "
                    "than half reach it), each problem weighing the same; held-out variants are gates (a setting whose "
                    "median on a variant is inf counts as not reaching its problem's target, as in AlgoPerf; 'score, "
                    f"gates ignored': without that rule): {given}"]  # fmt: skip
            if waiting:
                out.append(f"not scored yet (targets set, no scored runs): {', '.join(waiting)}")
            table = algoperf_table(scored, curves, validation_targets, budgets, held_out)
            out.append(table.to_string(index=False))
        out += ["", "targets (problem.targets, test loss): " + "; ".join(f"{t}: {', '.join(f'{v:g}' for v in vs)}"
                                                                         for t, vs in targets.items())]  # fmt: skip
        out += [f"performance profile, equal wall clock (seconds to target; score: area under rho up to tau={TAU_MAX:g})"]
        out.append(scores(profile_times(reached)).to_string())
    return "\n".join(out)


# -- re-reading a published runs.csv (final losses only) -------------------------------------


def runs_csv_frame(path: Path) -> pd.DataFrame:
    """A published runs.csv (task, league_setting, seed, status, final losses, hardware, ...) as
    the scored-runs frame the tables read. It carries final losses only: no time to target."""
    df = pd.read_csv(path)
    missing = {"task", "league_setting", "seed", "status", TEST_METRIC} - set(df.columns)
    if missing:
        raise ValueError(f"{path}: missing columns {sorted(missing)}")
    df = one_run_per_identity(df)
    return split_by_hardware(df)


def format_runs_csv(path: Path, constant_loss: Mapping[str, float] | None = None) -> str:
    """The final-loss re-read of a published runs.csv: per task the table of ``final_loss_table``,
    then the aggregate across tasks."""
    scored = runs_csv_frame(path)
    out = [
        f"{len(scored)} scored runs from {Path(path).name} ({scored['task'].nunique()} tasks, "
        f"{seeds_text(scored)} per task and setting); final losses only "
        "(no curves: no time to target)",
        hardware_line(scored),
        "",
        "final test loss per task: median and every seed (diverged: inf, the worst; no curves, so a finite "
        "blow-up scores its value)",
        format_final_loss_table(final_loss_table(scored, constant_loss=constant_loss)),
        "",
        "across tasks (rliable): IQM over (task, seed) of normalised scores (1: the task leader's median, 0: the "
        "task's worst finite median or diverged), percentile stratified bootstrap (nominal 95%; not exact at 3 "
        "seeds); P(hig < X) averaged over the tasks both ran",
    ]
    with pd.option_context("display.width", 250, "display.max_columns", None, "display.float_format", "{:.3f}".format):
        out.append(aggregate_table(scored).to_string(index=False))
    return "\n".join(out)
