"""The pre-run checks of the front door: a Hydra callback, ``Preflight``, and the one-line errors.

Hydra calls ``on_run_start`` / ``on_multirun_start`` of the callbacks listed under
``hydra.callbacks`` (conf/config.yaml) after composing the config and before it creates
any directory. A single run is decided there, in one pass, before anything is written: its
``Plan`` (``higbench.runner.plan.make_plan``: the config validated and typed, the output
policy, the inputs read once), handed to its job through this command line's
``Invocation``. A sweep's jobs are all validated there (each distinct network built once,
``train.check_build``), so that a bad job refuses the sweep before any runs; each job then
plans itself in its own directory, not validated again. Any problem is one line on stderr,
``higbench: error: <key>=<value>: <why>``, and exit code 2, with nothing written;
``composition_error`` makes such a line of Hydra's own composition errors.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import itertools
import os
import sys
import time
import traceback
from pathlib import Path
from types import MappingProxyType

from hydra.core.global_hydra import GlobalHydra
from hydra.core.hydra_config import HydraConfig
from hydra.errors import HydraException, MissingConfigException, OverrideParseException
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf, open_dict, read_write
from omegaconf.errors import ConfigTypeError, OmegaConfBaseException, ValidationError

from higbench.config import (
    SIZING_KEYS,
    Checked,
    check_bool_overrides,
    check_hydra_references,
    config_dir,
    to_plain,
    validate,
)
from higbench.errors import ConfigError, dotted_get, fail, given_value
from higbench.optim.choice import constructor_args, optimizer_class
from higbench.runfile.reader import RUN_FILE
from higbench.runner.plan import Plan, make_plan
from higbench.runner.rundir import RunDir, check_output_dir, run_file_of

MAX_PRECHECK_JOBS = 256  # larger sweeps: the first 256 jobs are checked up front, all in-job


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
    if full_key and isinstance(cause, ConfigTypeError):  # a mapping for a list, a list for a mapping: not an unknown key
        value = given_value(overrides, str(full_key)) or "?"
        return ConfigError(str(full_key), value, f"{_kind_there(cause)} ({_first_line(cause.msg)})")
    if full_key:
        return _unknown_key(str(full_key), overrides)
    return _unparsed_override(overrides) or ConfigError("overrides", " ".join(overrides), _first_line(exc))


def _kind_there(cause: ConfigTypeError) -> str:
    """What a value replacing the node of a ConfigTypeError must be (the node's own kind)."""
    kind = getattr(cause, "object_type", None)
    if kind is list or kind is tuple:
        return "must be a list, as the value there is"
    if kind is dict or dataclasses.is_dataclass(kind):
        return "must be a mapping, as the value there is"
    return "has the wrong type for the value there"


def _first_line(exc) -> str:
    text = str(exc).strip()
    return " ".join(text.splitlines()[0].split()) if text else type(exc).__name__


def _unknown_key(full_key: str, overrides: list[str]) -> ConfigError:
    """``problem.foo=1``: the key is not there; list the keys that are (from a composition without it)."""

    def under(override: str) -> bool:  # the key itself, or a key below it (nosuch.key=3: Hydra names nosuch)
        key = override.split("=", 1)[0].lstrip("+~")
        return key == full_key or key.startswith(full_key + ".")

    value = given_value(overrides, full_key)
    if value is None:  # a key below an unknown one: name the key and value the user gave
        given = next((o.lstrip("+~") for o in overrides if under(o)), None)
        if given is not None and "=" in given:
            full_key, value = given.split("=", 1)[0], given.split("=", 1)[1]
    value = "<missing>" if value is None else value
    parent = full_key.rsplit(".", 1)[0] if "." in full_key else ""
    others = [o for o in overrides if not under(o)]
    base = None
    with contextlib.suppress(HydraException, OmegaConfBaseException):
        base = _compose_plain(others)
    node = dotted_get(base, parent, None) if base is not None and parent else base
    while parent and base is not None and not isinstance(node, dict):  # the parent is unknown too: list where it is not
        parent = parent.rsplit(".", 1)[0] if "." in parent else ""
        node = dotted_get(base, parent, None) if parent else base
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


def is_basic_sweeper(config: DictConfig) -> bool:
    """Whether the sweep crosses its overrides as Hydra's basic sweeper does (higbench's
    ``EveryBatchSweeper`` is that sweeper with every batch run)."""
    target = str(OmegaConf.select(config, "hydra.sweeper._target_", default=""))
    return target.endswith(("BasicSweeper", "EveryBatchSweeper"))


def sweep_jobs(config: DictConfig) -> list[list[str]]:
    """Override lists of the jobs a multirun launches: all of them for Hydra's basic sweeper
    (its ``params`` and the command line's comma lists, crossed), the first one for others
    (Optuna samples its jobs as it goes; those are checked in-job)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    lines = list(config.hydra.overrides.task)
    basic = is_basic_sweeper(config)
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


# -- one command line: what Hydra's callback hands its jobs ----------------------------------


@dataclasses.dataclass
class Invocation:
    """What one ``higbench`` command line shares between Hydra's callback and its jobs.

    Hydra calls the callback and the task function separately, with the config only; this is
    the one channel between them (``cli.main`` opens a fresh one per command line, so nothing
    leaks from one in-process call to the next). A joblib worker, a process of its own,
    starts with an empty one and plans its jobs itself.
    """

    plan: Plan | None = None  # a single run's plan, made by the callback, taken by its job
    jobs: int = 0  # sweep jobs this process ran, and how many failed (the sweep's last line)
    failed: int = 0
    job_started: bool = False  # errors after a job started are the job's, not the command line's
    main: bool = False  # opened by ``cli.main`` (False: a launcher's worker process, or code calling the job)
    validated: list[tuple[dict, Checked]] = dataclasses.field(default_factory=list)  # a sweep's jobs, by the callback
    sweep_dir: str | None = None  # a sweep's directory, known to the parent (its Ctrl-C line)


_INVOCATION: contextvars.ContextVar[Invocation] = contextvars.ContextVar("higbench_invocation")


@contextlib.contextmanager
def new_invocation():
    token = _INVOCATION.set(Invocation(main=True))
    try:
        yield _INVOCATION.get()
    finally:
        _INVOCATION.reset(token)


def invocation() -> Invocation:
    """This command line's shared state (a fresh one where no command line opened it)."""
    current = _INVOCATION.get(None)
    if current is None:
        current = Invocation()
        _INVOCATION.set(current)
    return current


def take_plan(cfg: DictConfig, output_dir: Path, overrides: list[str], *, multirun: bool) -> Plan:
    """The job's plan: the callback's (a single run), else made now (sweep jobs; a job the
    callback validated is not validated again)."""
    current = invocation()
    planned, current.plan = current.plan, None
    if planned is not None and not multirun:
        return planned
    task = to_plain(cfg)
    checked = next((c for t, c in current.validated if t == task), None)
    try:
        return make_plan(task, output_dir, overrides, multirun=multirun, checked=checked)
    except ConfigError as exc:
        run_dir = RunDir(Path(output_dir) / RUN_FILE)
        if multirun and task.get("resume") and run_dir.run_file.exists():  # this job's run cannot continue
            return Plan(MappingProxyType(task), run_dir, "keep", str(exc).split(": ", 1)[-1])
        raise


def _checked_task(config: DictConfig) -> tuple[dict, Checked | None]:
    """The task part of a composed config (with its hydra node), and its validation (a resumed
    run's config is validated once merged with the stored one, by the plan)."""
    with contextlib.suppress(Exception):  # ${hydra:...} resolves against this job's Hydra config
        HydraConfig.instance().set_config(config)
    check_hydra_references(config)
    task = to_plain(config)
    check_bool_overrides(OmegaConf.to_container(config.hydra.overrides.task, resolve=False))  # as typed
    return task, None if task.get("resume") else validate(task)


def check_run(config: DictConfig) -> Plan:
    """The plan of a single run, before Hydra makes its directory (ConfigError otherwise).

    For ``resume=<run>`` Hydra's run directory becomes the run's own directory (unless
    ``hydra.run.dir`` is given). The checks that need the network (``init_from`` weights
    that fit it, the memory guard) run in the job, before its run file exists.
    """
    from higbench.runner.progress import announce, start_text

    task, checked = _checked_task(config)
    overrides = [*config.hydra.overrides.hydra, *config.hydra.overrides.task]
    if task.get("resume") and given_value(overrides, "hydra.run.dir") is None:
        with read_write(config.hydra), open_dict(config.hydra):
            config.hydra.run.dir = str(run_file_of(task["resume"], None).parent)
    output_dir = Path(os.path.abspath(str(config.hydra.run.dir)))  # as Hydra's runtime.output_dir
    plan = make_plan(task, output_dir, list(config.hydra.overrides.task), multirun=False, checked=checked)
    # on a terminal, a line at once: torch, the build and the checks take seconds
    announce(plan.run.progress, start_text(plan.start_config()) + " - checking", transient=True)
    return plan


def check_sweep(config: DictConfig) -> int | None:
    """Every job of a multirun (see ``sweep_jobs``), before Hydra makes the sweep directory.

    A bad job refuses the whole sweep before any job runs; a job validated here is not
    validated again in the job (``Invocation.validated``). Returns how many jobs the sweeper
    launches together (``launched_together``), where known.
    """
    from higbench.runner.train import check_build

    loader = GlobalHydra.instance().config_loader()
    checked = []
    for job in sweep_jobs(config) or [[]]:
        try:
            job_config = loader.load_sweep_config(config, job)
        except (HydraException, OmegaConfBaseException) as exc:
            raise composition_error(exc, job) from None
        checked.append(_checked_task(job_config))
    together = launched_together(config, len(checked))
    if together is None:  # not known here: the launcher's workers are the bound (``cli.parallel_jobs``)
        os.environ.pop("HIGBENCH_SWEEP_JOBS", None)
    else:  # an environment variable: joblib's workers, spawned after this, are other processes
        os.environ["HIGBENCH_SWEEP_JOBS"] = str(together)
    sweep_dir = Path(str(config.hydra.sweep.dir))
    check_output_dir(sweep_dir, "hydra.sweep.dir")
    if (sweep_dir / "multirun.yaml").is_symlink():
        why = "its multirun.yaml is a symbolic link; higbench never writes through links"
        raise ConfigError("hydra.sweep.dir", str(sweep_dir), why)
    if any(task.get("resume") for task, _ in checked):
        return together  # which jobs resume is known only in their directories: checked in-job
    invocation().validated = checked
    seen = set()
    for task, job_checked in checked:  # the network-sized checks once per distinct network and batch
        sizing = {k: task.get(k) for k in SIZING_KEYS}
        sizing["optimizer"] = {k: v for k, v in task["optimizer"].items() if k != "lr"}
        key = OmegaConf.to_yaml(sizing)
        if key not in seen:
            seen.add(key)
            check_build(Plan.for_run(task, sweep_dir / RUN_FILE, checked=job_checked))
    return together


def launched_together(config: DictConfig, listed: int) -> int | None:
    """How many jobs the sweeper hands its launcher at once, so at most this many share the
    machine: Hydra's basic sweeper all it lists (``listed``; in batches of ``max_batch_size``),
    the joblist sweeper its whole file (``sweep_jobs`` lists only the command line's job for
    it); None where unknown before the sweep (Optuna asks for its trials as it goes)."""
    target = str(OmegaConf.select(config, "hydra.sweeper._target_", default=""))
    if is_basic_sweeper(config):
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


# Hydra's wart: its basic sweeper stops after the batch that held a failed job
# (hydra.sweeper.max_batch_size), and a default sweeper set in conf/config.yaml would win over an
# experiment's own (conf/experiment/toy_optuna.yaml); so the sweep's config is changed here, after
# composing and before Hydra builds the sweeper from it
# (tests/test_cli.py::test_a_failed_job_does_not_stop_the_later_batches).
def run_every_batch(config: DictConfig) -> None:
    """Hydra's basic sweeper replaced by the same sweeper that runs every batch (``EveryBatchSweeper``)."""
    from hydra_plugins.higbench_joblist_sweeper.every_batch_sweeper import EVERY_BATCH_SWEEPER, HYDRA_BASIC_SWEEPER

    if OmegaConf.select(config, "hydra.sweeper._target_", default=None) == HYDRA_BASIC_SWEEPER:
        with read_write(config), open_dict(config):
            config.hydra.sweeper._target_ = EVERY_BATCH_SWEEPER


class Preflight(Callback):
    """Hydra calls these after composing and before creating any directory (conf/config.yaml)."""

    def __init__(self) -> None:
        self._multirun_yaml: tuple[Path, bytes] | None = None  # a sweep run again: its first multirun.yaml

    def on_run_start(self, config: DictConfig, **kwargs) -> None:
        invocation().plan = _checked(check_run, config)

    def on_multirun_start(self, config: DictConfig, **kwargs) -> None:
        _checked(check_sweep, config)
        run_every_batch(config)
        invocation().sweep_dir = os.path.abspath(str(config.hydra.sweep.dir))
        existing = Path(str(config.hydra.sweep.dir)) / "multirun.yaml"
        self._multirun_yaml = (existing, existing.read_bytes()) if existing.is_file() else None

    # Hydra's wart: a sweep run again into its directory overwrites the sweep's multirun.yaml
    # (tests/sweeps/test_sweep_launchers.py, the sweep completed with resume=true).
    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        """Put the sweep's first multirun.yaml back; Hydra's new one goes to multirun-rerun-<time>.yaml."""
        if self._multirun_yaml is None:
            return
        path, original = self._multirun_yaml
        with contextlib.suppress(OSError):
            if path.is_file() and path.read_bytes() != original:
                os.replace(path, path.with_name(f"multirun-rerun-{time.strftime('%Y%m%d-%H%M%S')}.yaml"))
            if not path.exists():
                path.write_bytes(original)


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
