"""The league's protocol as jobs: the configs it reads (shipped, or the user's through
``--searchpath``), the ``--set`` overrides and what the league keeps for itself, the search spaces,
and the jobs of each phase, named ``<role>/<problem>/...``:

    tuning_jobs("toy", "adam", trials=16, seconds=24, studies=2)            # tune/toy/adam/<study>/<trial>
    tuning_jobs("toy", "adam", 16, 10, 2, role="target-tune")               # the target setting's trials
    confirmation_jobs("toy", "adam", setting, seeds, 24, variants)          # confirm/toy/<variant>/adam
    confirmation_jobs("toy", "adam", None, seeds, 24, variants)             # paper/... or default/...

A job's identity is its overrides (``higbench.jobs``), never its name: the same overrides under
another role are the same run. The driver (``higbench.league.driver``) runs the phases and scores.
"""

from __future__ import annotations

import inspect
import math
import os
from pathlib import Path
from typing import Any

from hydra.core.override_parser.overrides_parser import OverridesParser

from higbench.errors import override_value as fmt
from higbench.jobs import Job
from higbench.results import league
from higbench.results.league import LONG_PAPER_ROLE, LONG_ROLE

EVALUATIONS = 100  # per run: time-to-target ratios up to TAU_MAX = 4 are resolved (a target at 1/25 of the budget)
SEARCHPATH_ENV = "HIGBENCH_SEARCHPATH"  # read by hydra_plugins/higbench_searchpath


class LeagueError(Exception):
    """Bad input or a refused file: one line, exit 2, before any run where it can be told."""


def fail(text: str):
    raise LeagueError(f"league: error: {text}")


# -- configs: shipped, or the user's through --searchpath ------------------------------------


def search_folders() -> list[Path]:
    return [Path(p) for p in os.environ.get(SEARCHPATH_ENV, "").split(os.pathsep) if p]


def use_searchpath(folders: list[Path]) -> None:
    """Compose with the user's config folders (problem/, optimizer/, search/) from here on: in this
    process and in every run it launches (the environment is inherited)."""
    for folder in folders:
        if not folder.is_dir():
            fail(f"--searchpath {folder}: no such folder")
    value = os.pathsep.join(str(f.resolve()) for f in folders)
    if value:
        from hydra.core.plugins import Plugins

        from hydra_plugins.higbench_searchpath import HigbenchSearchPath

        # Hydra finds plugins by listing hydra_plugins/ folders on the path; an editable install has
        # none to list: registered here, and its folder's parent put on the launched runs' PYTHONPATH
        Plugins.instance().register(HigbenchSearchPath)
        plugins_parent = str(Path(inspect.getfile(HigbenchSearchPath)).resolve().parents[2])
        paths = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
        os.environ["PYTHONPATH"] = os.pathsep.join([*paths, plugins_parent] if plugins_parent not in paths else paths)
        os.environ[SEARCHPATH_ENV] = value
    else:
        os.environ.pop(SEARCHPATH_ENV, None)


def config_names(group: str) -> list[str]:
    """The configs of a group (problem, optimizer): shipped and in the --searchpath folders."""
    from higbench.config import config_dir

    folders = [Path(config_dir()), *search_folders()]
    return sorted({p.stem for folder in folders for p in (folder / group).glob("*.yaml")})


def space_of(optimizer: str) -> dict:
    """The search space of ``optimizer``: SEARCHPATH/search/<name>.yaml first, else conf/search/."""
    for folder in search_folders():
        if (folder / "search" / f"{optimizer}.yaml").is_file():
            return league.load_space(optimizer, folder / "search")
    try:
        return league.load_space(optimizer)
    except ValueError as exc:
        where = " or ".join([*(f"{f}/search/" for f in search_folders()), "conf/search/"])
        raise ValueError(f"{exc}; give it one in {where} (keys with low, high, log: see conf/search/adam.yaml)") from None


def all_spaces() -> dict:
    spaces = league.all_spaces()
    for folder in search_folders():
        if (folder / "search").is_dir():
            spaces.update(league.all_spaces(folder / "search"))
    return spaces


def has_paper_settings(problem: str, optimizer: str) -> bool:
    """Whether higbench ships the pair's settings (conf/problem_optimizer/: the paper's)."""
    from higbench.config import config_dir

    return (Path(config_dir()) / "problem_optimizer" / f"{problem}_{optimizer}.yaml").is_file()


def problem_config(problem: str) -> dict:
    """The composed problem node (targets, budgets, variants) of ``problem``, with the --set
    overrides of ``problem.*`` that every job of it trains with, so that the driver reads what
    the runs do (``--set problem.target_seconds=2``: the target setting's budget). A --set value
    that does not compose is left to ``check_set``, which names it."""
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from higbench.jobs import compose, hydra_conf

    sets = [f"{key}={fmt(value)}" for scope, key, value in EXTRA
            if scope in (None, problem) and key.lstrip("+~").startswith("problem.")]  # fmt: skip
    with hydra_conf():
        try:
            return compose((f"problem={problem}", *sets))["problem"]
        except (HydraException, OmegaConfBaseException):
            return compose((f"problem={problem}",))["problem"]


def has_validation(problem: str, node: dict) -> bool:
    """Whether the problem's runs have a validation loss (what tuning reads): its config's
    ``val_size``, or one given with --set for every optimizer of it."""
    given = [v for scope, key, v in EXTRA if key.lstrip("+") == "problem.val_size" and scope in (None, problem)]
    try:
        return int(given[-1] if given else node.get("val_size") or 0) > 0
    except (TypeError, ValueError):
        return True  # not a number: the --set check names it


# -- the protocol's flags ---------------------------------------------------------------------

LEAGUE_KEYS = {"problem", "optimizer", "seed", "budget.seconds", "eval_every", "problem.held_out"}
EXTRA: list[tuple[str | None, str, Any]] = []  # (scope, key, value as Hydra reads it) of --set; set by main


def extra_overrides(problem: str, optimizer: str) -> dict[str, Any]:
    """The --set overrides for one (problem, optimizer): unscoped ones, and those scoped to the
    problem, the optimizer or ``problem/optimizer``; the narrower scope wins a key."""
    ranks = {None: 0, problem: 1, optimizer: 1, f"{problem}/{optimizer}": 2}
    chosen = sorted(((ranks[scope], key, value) for scope, key, value in EXTRA if scope in ranks), key=lambda c: c[:2])
    return {key: value for _, key, value in chosen}


def base_overrides(problem: str, optimizer: str, seed: int, seconds: float) -> dict:
    extra = extra_overrides(problem, optimizer)
    return {"problem": problem, "optimizer": optimizer, "seed": seed, "budget.seconds": seconds,
            "eval_every": float(f"{seconds / EVALUATIONS:.3g}"), **extra}  # fmt: skip


def per_problem(text: str | None, flag: str, cast=float) -> dict[str | None, float]:
    """``'4,toy=16'`` -> {None: 4, 'toy': 16}: a bare value is every problem's, ``problem=value``
    one problem's. One line naming the flag on a bad item."""
    values: dict[str | None, float] = {}
    for item in filter(None, (text or "").split(",")):
        name, _, value = item.rpartition("=") if "=" in item else (None, "", item)
        try:
            values[name or None] = cast(value)
        except ValueError:
            fail(f"{flag} {text}: {item!r} is not a number or problem=number")
    return values


def parse_set(item: str) -> tuple[str | None, str, str]:
    """``'poisson/hig:device=cuda'`` -> ('poisson/hig', 'device', 'cuda'); ``'threads=1'`` -> (None, 'threads', '1')."""
    head, sep, value = item.partition("=")
    if not sep or not head.rpartition(":")[2]:
        fail(f"--set {item}: expected [SCOPE:]KEY=VALUE")
    scope, _, key = head.rpartition(":")
    if key.lstrip("+~") in LEAGUE_KEYS:
        fail(f"--set {item}: {key} is the league's own (--problems, --optimizers, --seeds, --seconds, --variants)")
    return scope or None, key, set_value(item, key, value)


def set_value(item: str, key: str, text: str):
    """The value as Hydra's override grammar reads it (a list stays a list, a number a number),
    as a single run reads ``KEY=VALUE``: a job renders it back exactly (``errors.override_value``).
    Kept as text it was quoted into a string (``optimizer.betas='[0.8,0.99]'``) and every job failed."""
    from hydra.errors import HydraException

    try:
        (override,) = OverridesParser.create().parse_overrides([f"{key}={text}"])
        return override.value()
    except HydraException as exc:
        fail(f"--set {item}: {' '.join(str(exc).split())[:200]}")


def searchpath_of_set(items: list[str]) -> tuple[list[str], list[Path]]:
    """``--set hydra.searchpath=[file://DIR,...]`` is --searchpath DIR: (the other items, the folders)."""
    rest, folders = [], []
    for item in items:
        key, _, value = item.partition("=")
        if key.lstrip("+") == "hydra.searchpath":
            folders += [Path(v.strip().strip("'\"").removeprefix("file://")) for v in value.strip("[]").split(",") if v.strip()]
        else:
            rest.append(item)
    return rest, folders


def refusal(problem: str, optimizer: str, with_set: bool = True, extras: bool = True) -> str | None:
    """Why ``optimizer`` cannot run on ``problem`` (the CLI's one line: SIP without an inverse
    simulator, a package's missing extra), or None. ``with_set=False`` leaves the --set
    overrides out: re-reading runs trained on a GPU needs none here. ``extras=False``: a missing
    extra raises ``MissingExtra`` instead: a league that trains must not quietly lose SOAP."""
    from higbench.config import validate
    from higbench.errors import ConfigError, MissingExtra
    from higbench.jobs import compose, hydra_conf
    from higbench.preflight import composition_error

    overrides = [f"problem={problem}", f"optimizer={optimizer}"]
    overrides += [f"{k}={fmt(v)}" for k, v in extra_overrides(problem, optimizer).items()] if with_set else []
    try:
        with hydra_conf():
            cfg = compose(tuple(overrides))
        validate(cfg)
    except MissingExtra as exc:
        if not extras:
            raise
        return str(exc)
    except ConfigError as exc:
        return str(exc)
    except Exception as exc:  # Hydra's composition errors (an unknown key in --set): the CLI's line
        return str(composition_error(exc, overrides))
    return None


def check_protocol(trials: dict, budgets: dict, problems: list[str], optimizers: list[str]) -> None:
    """Before any run: each named problem and optimizer exists, each per-problem count or budget
    and each --set scope names one, and counts and budgets are positive and finite. A typo in a
    scope would otherwise train on the wrong device without a word. Names outside this league's
    --problems pass: one set of flags serves each problem's command and the --report-only over all."""
    known = {"problem": config_names("problem"), "optimizer": config_names("optimizer")}
    where = "conf/{}/" + "".join(f" or {f}/{{}}/" for f in search_folders())
    for group, names in (("problem", problems), ("optimizer", optimizers)):
        for name in names:
            if name not in known[group]:
                fail(f"--{group}s {name}: no {group} {name} ({where.format(*[group] * (1 + len(search_folders())))}: "
                     f"{', '.join(known[group])})")  # fmt: skip
    problems, optimizers = sorted({*problems, *known["problem"]}), sorted({*optimizers, *known["optimizer"]})
    for flag, values in (("--trials", trials), ("--seconds", budgets)):
        for name, value in values.items():
            if name is not None and name not in problems:
                fail(f"{flag} {name}={value:g}: no problem {name} (conf/problem/: {', '.join(problems)})")
            if not (value > 0 and math.isfinite(value)):
                fail(f"{flag} {value:g}: must be positive and finite")
    for scope, key, value in EXTRA:
        names = scope.split("/") if scope else []
        ok = (
            not names
            or (len(names) == 1 and names[0] in problems + optimizers)
            or (len(names) == 2 and names[0] in problems and names[1] in optimizers)
        )
        if not ok:
            why = "is not a problem, an optimizer or problem/optimizer (conf/problem/, conf/optimizer/)"
            fail(f"--set {scope}:{key}={value}: {scope} {why}")


def check_set(problem: str, optimizers: list[str]) -> None:
    """A --set that makes an optimizer refuse a problem it runs without it is the user's value,
    not the optimizer's limit: one line naming it, before any run."""
    for optimizer in optimizers:
        extra = extra_overrides(problem, optimizer)
        if extra and refusal(problem, optimizer, with_set=False) is None and (why := refusal(problem, optimizer)):
            given = " ".join(f"{k}={fmt(v)}" for k, v in extra.items())
            fail(f"--set ({problem}, {optimizer}: {given}): {why}")


# -- the jobs ---------------------------------------------------------------------------------


def variant_overrides(variant: str) -> dict:
    return dict(item.split("=", 1) for item in variant.split())


TUNE_ROLES = league.TUNE_ROLES
RERUN_ROLE = league.TARGET_ROLE  # a reference's tuned setting rerun on the confirmation seeds at the target-setting budget


def tuning_jobs(problem: str, optimizer: str, trials: int, seconds: float, studies: int, role: str = "tune") -> list[Job]:
    """Each study's trials (``league.trial_points``) on its tuning seed (``league.tuning_seed``),
    named ``<role>/<problem>/<optimizer>/<study>/<trial>`` (role: tune, or target-tune)."""
    space = space_of(optimizer)
    jobs = []
    for study in range(studies):
        seed = league.tuning_seed(study)
        for i, trial in enumerate(league.trial_points(optimizer, space, trials, study)):
            overrides = {**base_overrides(problem, optimizer, seed, seconds), **trial}
            jobs.append(Job("league", f"{role}/{problem}/{optimizer}/{study}/{i}", overrides, seed))
    return jobs


def study_and_trial(job: Job) -> tuple[int | None, int | None]:
    parts = job.sweep.split("/")
    return (int(parts[3]), int(parts[4])) if parts[0] in TUNE_ROLES and len(parts) == 5 else (None, None)


def confirmation_jobs(problem: str, optimizer: str, setting: dict | None, seeds, seconds: float, variants,
                      role: str | None = None) -> list[Job]:  # fmt: skip
    """The setting (tuned, or the shipped one for ``setting=None``: the paper's where
    conf/problem_optimizer/ has the pair, else the defaults) on fresh seeds, on the problem and each
    held-out variant (``role``: target for the references' reruns)."""
    role = role or ("confirm" if setting is not None else "paper" if has_paper_settings(problem, optimizer) else "default")
    jobs = []
    for variant in ["", *variants]:
        for seed in seeds:
            overrides = {**base_overrides(problem, optimizer, seed, seconds), **variant_overrides(variant), **(setting or {})}
            jobs.append(Job("league", f"{role}/{problem}/{variant or 'base'}/{optimizer}", overrides, seed))
    return jobs


def long_jobs(problem: str, optimizer: str, setting: dict | None, seeds, seconds: float) -> list[Job]:
    """The long budget's runs of a tuned ``setting`` (role long), or of the shipped one
    (``None``: role long-paper), on the problem alone (no held-out variant)."""
    role = LONG_ROLE if setting is not None else LONG_PAPER_ROLE
    return confirmation_jobs(problem, optimizer, setting, seeds, seconds, [], role=role)


def long_budgets(args) -> dict[str | None, float]:
    """--long as {problem or None (every problem): seconds}."""
    return per_problem(args.long, "--long") if args.long else {}


def check_long(args, longs: dict, optimizers: list[str], problems: list[str]) -> None:
    """--long: a positive, finite budget per named problem, for optimizers the league tunes, in
    a league that tunes (--targets-only stops before any setting is chosen)."""
    if longs and args.targets_only:
        fail(f"--long {args.long}: --targets-only trains no league setting to train longer")
    for problem, seconds in longs.items():
        if problem is not None and problem not in problems:
            fail(f"--long {args.long}: {problem} is not in --problems")
        if not (math.isfinite(seconds) and seconds > 0):
            fail(f"--long {args.long}: a budget is a positive, finite number of seconds")
    if longs:
        for o in [o for o in args.long_optimizers.split(",") if o]:
            if o not in optimizers:
                fail(f"--long-optimizers {args.long_optimizers}: {o} is not in --optimizers (its tuned setting is the league's)")


def long_budget_jobs(args, longs: dict, problem: str, usable: list[str], paper: list[str], chosen: dict, seeds) -> list[Job]:
    """The long budget of a problem (``--long``): each long optimizer's chosen setting, and the
    shipped one of those in ``--paper``, on the first ``--long-seeds`` seeds; none without --long."""
    seconds = longs.get(problem, longs.get(None))
    if not seconds:
        return []
    names = [o for o in args.long_optimizers.split(",") if o in usable]
    first = list(seeds)[: args.long_seeds]
    jobs = [j for o in names if chosen.get(o) is not None for j in long_jobs(problem, o, chosen[o], first, seconds)]
    return jobs + [j for o in names if o in paper for j in long_jobs(problem, o, None, first, seconds)]


def target_seconds_of(problem: str, node: dict) -> float | None:
    """The target-setting runs' budget: the problem's ``target_seconds``, else a third of its
    ``league_seconds`` (the league's budget then comes out near it)."""
    seconds = node.get("target_seconds") or (node.get("league_seconds") or 0) / 3
    return float(seconds) if seconds else None
