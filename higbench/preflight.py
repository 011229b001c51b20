"""The pre-run checks of the front door: a Hydra callback, ``Preflight``, and the run plan.

Hydra calls ``on_run_start`` / ``on_multirun_start`` of the callbacks listed under
``hydra.callbacks`` (conf/config.yaml) after composing the config and before it creates
any directory. One pass decides everything a run needs, before anything is written:

1. validate the config (``higbench.config``: keys, types, ranges);
2. decide the output/resume policy (``plan_run``: a new run, a run to continue, a dead run
   to start again, a sweep job to keep), refusing links higbench would write through and
   stored configs naming callables higbench does not register;
3. build the problem and network once on the CPU (``train.preflight``: ``init_from``
   weights that fit, the GN/HIG memory guard).

The plan of a single run is handed to the job (``take_plan``), which only claims its
directory and runs. Sweep jobs are planned in the job (each in its own directory); a job
the callback already validated is not validated again. Any problem is one line on
stderr, ``higbench: error: <key>=<value>: <why>``, and exit code 2, with nothing written.
``composition_error`` makes such a line of Hydra's own composition errors.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import os
import sys
import time
import traceback
from pathlib import Path

from hydra.core.global_hydra import GlobalHydra
from hydra.core.hydra_config import HydraConfig
from hydra.errors import HydraException, MissingConfigException, OverrideParseException
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf, open_dict, read_write
from omegaconf.errors import OmegaConfBaseException, ValidationError

from higbench.config import (
    SIZING_KEYS,
    check_bool_overrides,
    check_hydra_references,
    config_dir,
    constructor_args,
    optimizer_class,
    to_plain,
    validate,
)
from higbench.errors import ConfigError, dotted_get, fail
from higbench.runfile.reader import RUN_FILE

MAX_PRECHECK_JOBS = 256  # larger sweeps: the first 256 jobs are checked up front, all in-job
# Everything higbench (and Hydra for it) writes in a run directory: none may be a link.
WRITTEN_NAMES = (".hydra", *(f".hydra/{n}.yaml" for n in ("config", "hydra", "overrides")), "higbench.log")
WRITTEN_NAMES += (RUN_FILE, f"{RUN_FILE}.ckpt")


CLUSTER_LAUNCHERS = ("joblib", "submitit_local", "submitit_slurm", "slurm")  # pyproject's `cluster` extra


# -- Hydra's composition errors as one line ---------------------------------------------------


def composition_error(exc: Exception, overrides: list[str]) -> ConfigError:
    """A one-line ConfigError from Hydra's composition errors (unknown key, config, syntax)."""
    if isinstance(exc, MissingConfigException) and exc.missing_cfg_file and exc.options is not None:
        group, _, choice = str(exc.missing_cfg_file).rpartition("/")
        why = f"no such config; valid choices: {', '.join(exc.options)}"
        if group == "hydra/launcher" and choice in CLUSTER_LAUNCHERS:
            why += f'; {choice} comes with the cluster extra: pip install -e ".[cluster]"'
        return ConfigError(group or "config", choice, why)
    if isinstance(exc, OverrideParseException):
        key, _, value = str(exc.override).partition("=")
        return ConfigError(key, value, f"cannot parse this override ({_first_line(exc)})")
    cause = exc.__cause__ if exc.__cause__ is not None else exc
    full_key = getattr(cause, "full_key", None)
    if full_key and isinstance(cause, ValidationError):  # a bad type: Hydra's check against the schema
        value = given_value(overrides, str(full_key)) or "?"
        return ConfigError(str(full_key), value, _first_line(cause.msg if hasattr(cause, "msg") else cause))
    if full_key:
        return _unknown_key(str(full_key), overrides)
    return _unparsed_override(overrides) or ConfigError("overrides", " ".join(overrides), _first_line(exc))


def _first_line(exc) -> str:
    text = str(exc).strip()
    return " ".join(text.splitlines()[0].split()) if text else type(exc).__name__


def _unknown_key(full_key: str, overrides: list[str]) -> ConfigError:
    """``problem.foo=1``: the key is not there; list the keys that are (from a composition without it)."""
    value = given_value(overrides, full_key)
    value = "<missing>" if value is None else value
    parent = full_key.rsplit(".", 1)[0] if "." in full_key else ""
    others = [o for o in overrides if o.split("=", 1)[0].lstrip("+~") != full_key]
    base = None
    with contextlib.suppress(HydraException, OmegaConfBaseException):
        base = _compose_plain(others)
    node = dotted_get(base, parent, None) if base is not None and parent else base
    valid = sorted(node.keys()) if isinstance(node, dict) else []
    if parent == "optimizer" and isinstance(node, dict) and node.get("_target_"):
        leaf = full_key.rsplit(".", 1)[-1]
        with contextlib.suppress(ConfigError):
            if leaf in constructor_args(optimizer_class(node)):
                # A constructor argument the optimizer's YAML does not list: Hydra adds it with `+`.
                yaml_file = f"conf/optimizer/{node.get('name')}.yaml"
                return ConfigError(full_key, value, f"not set in {yaml_file}; add it with +{full_key}={value}")
    if parent == "problem" and isinstance(node, dict) and full_key.rsplit(".", 1)[-1] in _problem_fields(node):
        # A key of the problem's Config its YAML does not list (a custom problem's base keys,
        # e.g. init): the command line may set it as if listed (``main`` adds it with ++).
        error = ConfigError(full_key, value, f"not set in the problem's YAML; add it with +{full_key}={value}")
        error.addable = True
        return error
    where = f" under {parent}" if parent else ""
    return ConfigError(full_key, value, f"unknown key; valid keys{where}: {', '.join(map(str, valid))}")


def _problem_fields(problem: dict) -> tuple[str, ...]:
    from higbench.config import problem_class

    with contextlib.suppress(ConfigError):
        return tuple(f.name for f in dataclasses.fields(problem_class(problem).Config))
    return ()


def _unparsed_override(overrides: list[str]) -> ConfigError | None:
    """The first override Hydra's grammar cannot parse, as a ConfigError (None: they all parse)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    for line in overrides:
        try:
            OverridesParser.create().parse_overrides([line])
        except (HydraException, ValueError) as exc:  # ValueError: an integer of over 4300 digits
            key, _, value = line.partition("=")
            return ConfigError(key, value, f"cannot parse this override ({_first_line(exc)})")
    return None


def _compose_plain(overrides: list[str]) -> dict:
    """The task config of ``overrides``, unresolved (in the running Hydra app, or a new one)."""
    from hydra import compose, initialize_config_dir

    if GlobalHydra.instance().is_initialized():
        return OmegaConf.to_container(compose("config", overrides=overrides), resolve=False)
    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        return OmegaConf.to_container(compose("config", overrides=overrides), resolve=False)


def given_value(overrides: list[str], key: str) -> str | None:
    """The value ``key`` is given on the command line (the last one: it wins), or None."""
    for o in reversed(overrides):
        k, sep, v = o.partition("=")
        if k.lstrip("+~") == key:
            return v if sep else "<missing>"
    return None


def sweep_jobs(config: DictConfig) -> list[list[str]]:
    """Override lists of the jobs a multirun launches: all of them for Hydra's basic sweeper
    (its ``params`` and the command line's comma lists, crossed), the first one for others
    (Optuna samples its jobs as it goes; those are checked in-job)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    lines = list(config.hydra.overrides.task)
    basic = "BasicSweeper" in str(OmegaConf.select(config, "hydra.sweeper._target_", default=""))
    params = OmegaConf.select(config, "hydra.sweeper.params", default=None) if basic else None
    if params is not None:
        lines = [f"{k}={v}" for k, v in OmegaConf.to_container(params, resolve=False).items()] + lines
    parser = OverridesParser.create(config_loader=GlobalHydra.instance().config_loader())
    axes: dict[str, list[str]] = {}  # per key, as Hydra's sweeper: the command line wins over params
    for o in parser.parse_overrides(lines):
        if not o.is_sweep_override():
            axes[o.get_key_element()] = [o.input_line]
        elif o.is_discrete_sweep():
            axes[o.get_key_element()] = [f"{o.get_key_element()}={v}" for v in o.sweep_string_iterator()]
        else:
            axes.pop(o.get_key_element(), None)  # an interval (Optuna's): not listed
    jobs = [list(job) for job in itertools.islice(itertools.product(*axes.values()), MAX_PRECHECK_JOBS)]
    return jobs if basic else jobs[:1]


# -- what a stored config may build ----------------------------------------------------------


def registered_targets() -> set[str]:
    """``_target_`` of every problem and optimizer config in Hydra's search path (conf/, and
    ``hydra.searchpath`` given on the command line) and of every registered Problem class."""
    from hydra.core.object_type import ObjectType

    from higbench.problems.base import registry

    targets = {f"{c.__module__}.{c.__qualname__}" for c in registry().values()}
    if not GlobalHydra.instance().is_initialized():
        from hydra import initialize_config_dir

        with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
            return targets | registered_targets()
    for source in GlobalHydra.instance().config_loader().get_sources():
        for group in ("problem", "optimizer"):
            if not source.is_group(group):
                continue
            for name in source.list(group, ObjectType.CONFIG):
                with contextlib.suppress(Exception):  # a YAML that does not load names nothing
                    target = source.load_config(f"{group}/{name}").config.get("_target_")
                    targets.add(str(target)) if target else None
    return targets


def check_stored_targets(stored: dict, composed: dict, resume_value) -> None:
    """Refuse a stored config (a run file's, or .hydra/config.yaml) naming a ``_target_`` that
    no higbench config registers: it would be built (called) before anything else is checked."""
    allowed = registered_targets() | {str(dotted_get(composed, f"{g}._target_", "")) for g in ("problem", "optimizer")}
    for key, target in _targets(stored):
        if str(target) not in allowed:
            why = f"its stored config names {key}={target}, which no problem or optimizer config registers; refusing to build it"
            raise ConfigError("resume", resume_value, why)


PATH_KEYS = ("init_from",)  # config keys naming a file higbench opens


def check_stored_paths(stored: dict, overrides: list[str], resume_value) -> None:
    """A stored config (someone else's file) never makes higbench open a file: a path it
    names must be given again on this command line, where the user names what is opened."""
    for key in PATH_KEYS:
        path = stored.get(key)
        if path and given_value(overrides, key) != str(path):
            why = (
                f"its stored config names {key}={path}; a stored config never makes higbench open a file: "
                f"give {key}={path} on the command line to start it again from that file"
            )
            raise ConfigError("resume", resume_value, why)


def _targets(node, prefix: str = ""):
    if isinstance(node, dict):
        for k, v in node.items():
            if k == "_target_":
                yield f"{prefix}{k}", v
            yield from _targets(v, f"{prefix}{k}.")
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _targets(v, f"{prefix}{i}.")


# -- the run plan: what the job does, decided once --------------------------------------------


@dataclasses.dataclass
class RunPlan:
    """What a job does with its directory, decided before anything is written."""

    task: dict  # the config it trains with (a resumed run's stored config, with allowed changes)
    run_path: Path
    resume: bool = False  # continue ``run_path`` from its checkpoint
    restart: str | None = None  # ``run_path`` recorded nothing (why): moved aside, started again
    kept: str | None = None  # a sweep job whose run stays as it is (why)

    def start_config(self) -> DictConfig:
        """The config the start line and the run show: the stored run's when it resumes."""
        return OmegaConf.create({**self.task, "resume": True if self.resume else None})


def check_no_links(out: Path, key: str) -> None:
    """Refuse a run directory where something higbench writes is a symbolic link."""
    for name in WRITTEN_NAMES:
        path = Path(out) / name
        if path.is_symlink():
            why = f"{path} is a symbolic link (to {os.readlink(path)}); higbench never writes through links"
            raise ConfigError(key, str(out), why)


def check_tensorboard_dir(task: dict, out: Path, key: str) -> None:
    """``tensorboard=true``: its directory in the run dir is absent or a real directory (a link
    would take the event files elsewhere; a file or a dangling link would fail mid-run)."""
    from higbench.runner.tensorboard import TENSORBOARD_DIR

    path = Path(out) / TENSORBOARD_DIR
    if not task.get("tensorboard") or not os.path.lexists(path):
        return
    if path.is_symlink():
        why = f"{path} is a symbolic link (to {os.readlink(path)}); higbench never writes through links"
        raise ConfigError(key, str(out), why)
    if not path.is_dir():
        raise ConfigError(key, str(out), f"{path} exists and is not a directory; tensorboard=true writes its event files there")


def plan_run(task: dict, output_dir: Path, overrides: list[str], *, multirun: bool) -> RunPlan:
    """The one decision about a job's directory (ConfigError when it must not run)."""
    from higbench.runner import checkpoint
    from higbench.runner.output_location import check_output_dir

    output_dir = Path(output_dir)
    if task.get("resume"):
        run_path = checkpoint.run_file_of(task["resume"], output_dir)
        check_output_dir(run_path.parent, "resume")
        check_no_links(run_path.parent, "resume")
        merged, continues, empty = resume_plan(task, run_path, overrides, multirun=multirun)
        check_tensorboard_dir(merged, run_path.parent, "resume")
        return RunPlan(merged, run_path, resume=continues, restart=empty)
    run_path = output_dir / RUN_FILE
    check_output_dir(output_dir, "hydra.run.dir", RUN_FILE)
    check_no_links(output_dir, "hydra.run.dir")
    check_tensorboard_dir(task, output_dir, "hydra.run.dir")
    if not os.path.lexists(run_path):
        return RunPlan(task, run_path)
    empty = checkpoint.recorded_nothing(run_path)
    if empty:
        return RunPlan(task, run_path, restart=empty)
    if multirun:  # a sweep run again into its directory: its runs stay as they are
        return RunPlan(task, run_path, kept="already holds a run (resume=true completes interrupted and failed jobs)")
    raise ConfigError(
        "hydra.run.dir",
        str(output_dir),
        f"already holds a run file ({RUN_FILE}); refusing to overwrite it "
        f"(resume={output_dir} continues it, or pick a new hydra.run.dir)",
    )


def resume_plan(task: dict, run_path: Path, overrides: list[str], *, multirun: bool) -> tuple[dict, bool, str | None]:
    """The config a ``resume=`` job runs, whether it continues ``run_path``'s checkpoint, and
    why it starts again instead (the run recorded nothing), if it does.

    A sweep job that never started starts now; a run that recorded nothing starts again
    from the beginning with its own config; anything else continues from its checkpoint
    (ConfigError when it cannot: finished, no checkpoint, another run's, a changed key).
    """
    from higbench.runner import checkpoint

    if multirun and not run_path.exists():
        return {**task, "resume": None}, False, None
    if multirun:  # a job stopped before its first checkpoint (killed with its sweep): run it again
        lost = checkpoint.stopped_without_checkpoint(run_path)
        if lost:
            return {**task, "resume": None}, False, lost
    empty = checkpoint.recorded_nothing(run_path)
    if empty:
        stored = task if multirun else _parse_stored(_stored_config(run_path, task["resume"]), task["resume"])
    else:
        _status, stored_yaml = checkpoint.inspect_run(run_path, task["resume"])
        stored = _parse_stored(stored_yaml, task["resume"])
    check_stored_targets(stored, task, task["resume"])  # before anything of it is built
    merged = checkpoint.resume_config(stored, task, overrides)
    if empty:  # started again from its stored config: it would read the file its init_from names
        check_stored_paths(stored, overrides, task["resume"])
        validate(merged)
    else:  # continued: the weights are the checkpoint's; the stored init_from is a record, never opened
        validate({**merged, "init_from": None})
    if not empty:
        checkpoint.check_owner(checkpoint.load(run_path), run_path, task["resume"])  # readable, of this run
    return merged, not empty, empty


def _parse_stored(yaml_text: str, resume_value) -> dict:
    """A stored config, parsed with the run-file reader's bounds (size, aliases expanded)."""
    from higbench.runfile.reader import UnreadableRunFile, parse_config

    try:
        return parse_config(yaml_text)
    except UnreadableRunFile as exc:
        raise ConfigError("resume", resume_value, f"its stored config is refused: {exc}") from None


def _stored_config(run_file: Path, resume_value) -> str:
    """Config YAML of a run: from its run file, else (a file killed at creation) Hydra's copy."""
    from higbench.runfile.reader import UnreadableRunFile, read_head

    with contextlib.suppress(UnreadableRunFile):
        stored = read_head(run_file).config_yaml
        if stored:
            return stored
    saved = run_file.parent / ".hydra" / "config.yaml"
    if saved.is_file() and not saved.is_symlink():
        return saved.read_text()
    raise ConfigError("resume", resume_value, f"{run_file} recorded nothing and its config is unknown (no .hydra/config.yaml)")


# -- the callback ----------------------------------------------------------------------------

_PLANNED: list[RunPlan] = []  # a single run's plan, made by the callback, taken by the job
_VALIDATED: set[frozenset[str]] = set()  # override sets of sweep jobs the callback validated


def take_plan(cfg: DictConfig, output_dir: Path, overrides: list[str], *, multirun: bool) -> RunPlan:
    """The job's plan: the callback's (a single run), else made now (sweep jobs, no callback)."""
    if _PLANNED and not multirun:
        return _PLANNED.pop()
    task = to_plain(cfg)
    if not task.get("resume") and frozenset(overrides) not in _VALIDATED:
        validate(task)
    try:
        return plan_run(task, output_dir, overrides, multirun=multirun)
    except ConfigError as exc:
        run_path = Path(output_dir) / RUN_FILE
        if multirun and task.get("resume") and run_path.exists():  # this job's run cannot continue
            return RunPlan(task, run_path, kept=str(exc).split(": ", 1)[-1])
        raise


def _checked_task(config: DictConfig) -> dict:
    """The task part of a composed config (with its hydra node), validated (a resumed run's
    config is validated once merged with the stored one, in ``resume_plan``)."""
    with contextlib.suppress(Exception):  # ${hydra:...} resolves against this job's Hydra config
        HydraConfig.instance().set_config(config)
    check_hydra_references(config)
    check_bool_overrides(list(config.hydra.overrides.task))
    task = to_plain(config)
    if not task.get("resume"):
        validate(task)
    return task


def check_run(config: DictConfig) -> RunPlan:
    """Everything a single run needs, before Hydra makes its directory (ConfigError otherwise).

    For ``resume=<run>`` Hydra's run directory becomes the run's own directory (unless
    ``hydra.run.dir`` is given).
    """
    from higbench.runner.progress import announce, start_text

    task = _checked_task(config)
    overrides = [*config.hydra.overrides.hydra, *config.hydra.overrides.task]
    explicit_dir = given_value(overrides, "hydra.run.dir") is not None
    if task.get("resume") and not explicit_dir:
        from higbench.runner import checkpoint

        with read_write(config.hydra), open_dict(config.hydra):
            config.hydra.run.dir = str(checkpoint.run_file_of(task["resume"], None).parent)
    output_dir = Path(os.path.abspath(str(config.hydra.run.dir)))  # as Hydra's runtime.output_dir
    plan = plan_run(task, output_dir, list(config.hydra.overrides.task), multirun=False)
    # on a terminal, a line at once: torch and the pre-flight take seconds
    announce(task.get("progress", True), start_text(plan.start_config()) + " - checking", transient=True)
    from higbench.runner.train import preflight  # imports torch: only once the cheap checks pass

    task = {**plan.task, "init_from": None} if plan.resume else plan.task  # weights: the checkpoint's
    preflight(OmegaConf.create(task), resume_from=plan.run_path if plan.resume else None)
    return plan


def check_sweep(config: DictConfig) -> None:
    """Every job of a multirun (see ``sweep_jobs``), before Hydra makes the sweep directory."""
    from higbench.runner.output_location import check_output_dir
    from higbench.runner.train import preflight

    loader = GlobalHydra.instance().config_loader()
    tasks = []
    for job in sweep_jobs(config) or [[]]:
        try:
            job_config = loader.load_sweep_config(config, job)
        except (HydraException, OmegaConfBaseException) as exc:
            raise composition_error(exc, job) from None
        tasks.append(_checked_task(job_config))
        _VALIDATED.add(frozenset(job_config.hydra.overrides.task))
    together = launched_together(config, len(tasks))
    if together is None:  # not known here: the launcher's workers are the bound (``cli.parallel_jobs``)
        os.environ.pop("HIGBENCH_SWEEP_JOBS", None)
    else:
        os.environ["HIGBENCH_SWEEP_JOBS"] = str(together)  # the jobs (and joblib's workers, spawned after) read it
    sweep_dir = Path(str(config.hydra.sweep.dir))
    check_output_dir(sweep_dir, "hydra.sweep.dir")
    if (sweep_dir / "multirun.yaml").is_symlink():
        raise ConfigError(
            "hydra.sweep.dir", str(sweep_dir), "its multirun.yaml is a symbolic link; higbench never writes through links"
        )
    _remember_multirun_yaml(sweep_dir)
    if any(task.get("resume") for task in tasks):
        return  # which jobs resume is known only in their directories: checked in-job
    seen = set()
    for task in tasks:  # the network-sized checks once per distinct network and batch
        sizing = {k: task.get(k) for k in SIZING_KEYS}
        sizing["optimizer"] = {k: v for k, v in task["optimizer"].items() if k != "lr"}
        key = OmegaConf.to_yaml(sizing)
        if key not in seen:
            seen.add(key)
            preflight(OmegaConf.create(task))


def launched_together(config: DictConfig, listed: int) -> int | None:
    """How many jobs the sweeper hands its launcher at once, so at most this many share the
    machine: Hydra's basic sweeper all it lists (``listed``; in batches of ``max_batch_size``),
    the joblist sweeper its whole file (``sweep_jobs`` lists only the command line's job for
    it); None where unknown before the sweep (Optuna asks for its trials as it goes)."""
    target = str(OmegaConf.select(config, "hydra.sweeper._target_", default=""))
    if "BasicSweeper" in target:
        batch = OmegaConf.select(config, "hydra.sweeper.max_batch_size", default=None)
        return min(listed, int(batch)) if batch else listed
    if "JobListSweeper" in target:
        from hydra_plugins.higbench_joblist_sweeper.joblist_sweeper import read_jobs

        with contextlib.suppress(OSError, ValueError, TypeError, OmegaConfBaseException):  # the sweeper says why
            return len(read_jobs(str(OmegaConf.select(config, "hydra.sweeper.jobs_file"))))
    return None


def refuse(exc: BaseException | str, code: int = 2) -> None:
    """``higbench: error: <one line>``, replacing the terminal's transient "checking" line; exit."""
    from higbench.runner.progress import clear_transient

    clear_transient()
    fail(exc, code)


def _checked(check, config: DictConfig):
    """Run a check; Hydra turns a callback's exceptions into warnings and goes on, so exit here."""
    try:
        return check(config)
    except ConfigError as exc:
        refuse(exc)
    except RecursionError:
        refuse(ConfigError("hydra.run.dir", "...", "a path nested too deep to check"))
    except Exception:  # noqa: BLE001 - not bad input: the traceback, exit 1, before anything is written
        traceback.print_exc()
        sys.exit(1)


class Preflight(Callback):
    """Hydra calls these after composing and before creating any directory (conf/config.yaml)."""

    def on_run_start(self, config: DictConfig, **kwargs) -> None:
        _PLANNED[:] = [_checked(check_run, config)]

    def on_multirun_start(self, config: DictConfig, **kwargs) -> None:
        _checked(check_sweep, config)

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        _restore_multirun_yaml()


def sweep_configs(overrides: list[str], part: str = "job") -> list[tuple[list[str], str]]:
    """``higbench -m ... --cfg job``: each job's composed config as YAML, with its overrides.

    ``part``: job (the task config), hydra, or all, as Hydra's ``--cfg``.
    """
    from hydra import initialize_config_dir
    from hydra.types import RunMode

    with initialize_config_dir(config_dir=config_dir(), version_base="1.3", job_name="higbench"):
        gh = GlobalHydra.instance()
        config = gh.hydra.compose_config("config", overrides, run_mode=RunMode.MULTIRUN, with_log_configuration=False)
        loader = gh.config_loader()
        shown = []
        for job in sweep_jobs(config) or [[]]:
            job_config = loader.load_sweep_config(config, job)
            with read_write(job_config), open_dict(job_config):
                if part == "job":
                    del job_config["hydra"]
                elif part == "hydra":
                    job_config = OmegaConf.create({"hydra": job_config.hydra})
            shown.append((list(job), OmegaConf.to_yaml(job_config)))
    return shown


def precheck(overrides: list[str]) -> DictConfig:
    """The checks of ``higbench <overrides>`` (one run) in this process; ConfigError if refused."""
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=config_dir(), version_base="1.3", job_name="higbench"):
        try:
            config = compose("config", overrides=list(overrides), return_hydra_config=True)
        except (HydraException, OmegaConfBaseException) as exc:
            raise composition_error(exc, list(overrides)) from None
        check_run(config)
    return config


_MULTIRUN_YAML: tuple[Path, bytes] | None = None


def _remember_multirun_yaml(sweep_dir: Path) -> None:
    """A sweep run again into its directory: keep the sweep's own multirun.yaml."""
    global _MULTIRUN_YAML
    existing = sweep_dir / "multirun.yaml"
    _MULTIRUN_YAML = (existing, existing.read_bytes()) if existing.is_file() else None


def _restore_multirun_yaml() -> None:
    """Put the sweep's first multirun.yaml back; Hydra's new one goes to multirun-rerun-<time>.yaml."""
    if _MULTIRUN_YAML is None:
        return
    path, original = _MULTIRUN_YAML
    with contextlib.suppress(OSError):
        if path.is_file() and path.read_bytes() != original:
            os.replace(path, path.with_name(f"multirun-rerun-{time.strftime('%Y%m%d-%H%M%S')}.yaml"))
        if not path.exists():
            path.write_bytes(original)
