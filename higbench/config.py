"""Validation of a composed config: the schemas, and the checks Hydra cannot do.

* Top-level keys: the ``RunConfig`` dataclass below, registered in Hydra's ConfigStore as
  ``higbench_schema`` and first in conf/config.yaml's defaults, so Hydra itself types the
  keys and refuses unknown ones while composing.
* ``problem``: the ``Config`` dataclass of the problem class named by ``problem._target_``
  (next to the class, ranges beside the fields; see ``higbench.problems.base``).
* ``optimizer``: the optimizer's own constructor, called on a dummy parameter: torch's
  checks for torch.optim classes, ``JacobianPower``'s for GN/HIG.
* Across keys: one of the budgets set, the batch size against the data set, ``device``,
  ``threads`` and ``${hydra:...}`` references that this job's Hydra config cannot resolve.
  Files are not read here: ``init_from``'s run file is read once, by the plan
  (``higbench.runner.plan``).

``validate(cfg)`` raises ``ConfigError`` for the first problem; the CLI turns it into
``higbench: error: key=value: why`` and exit code 2 before anything is written.
"""

from __future__ import annotations

import dataclasses
import hashlib
import re
from typing import Any, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from higbench.cards import CARD_KEY, conf_dir, optimizer_help, problem_help
from higbench.errors import ABSENT, ConfigError, dotted_get, leaves, show
from higbench.optim.choice import OptimizerChoice, check_optimizer, constructor_args, optimizer_choice, optimizer_kwargs  # noqa: F401
from higbench.optim.contract import needs_inverse_simulator
from higbench.schema import check, keys_where, locate, value

__all__ = ["ConfigError", "show", "validate", "RunConfig", "Budget", "to_plain", "check_hydra_references"]

DEVICES = ("cpu", "cuda", "auto")  # or cuda:<index>


@dataclasses.dataclass
class Budget:
    seconds: Optional[float] = value(gt=0, in_job_dir=False)  # noqa: UP045 - OmegaConf reads Optional, not "X | None"
    max_updates: Optional[int] = value(ge=1, in_job_dir=False)  # noqa: UP045


# Keys that change nothing of a run's result are ``identity=False``; see ``schema.value``.
_COSMETIC = dict(identity=False, resumable=True, in_job_dir=False)


@dataclasses.dataclass
class RunConfig:
    """The top-level keys: their types and rules. Their values are conf/config.yaml's, written
    there once (and documented there and in --help); only the keys a config group fills
    (problem, optimizer, sink) start as None here."""

    problem: Any = value(None, sizing=True)  # checked against its problem class's Config
    optimizer: Any = value(None, sizing=True)  # checked by its constructor (sizing: all but lr)
    seed: int = value(ge=0, le=2**63 - 1)
    batch_size: int = value(ge=1, sizing=True)
    budget: Budget = dataclasses.field(default_factory=Budget, metadata={"resumable": True})
    eval_every: float = value(gt=0, resumable=True, in_job_dir=False)
    eval_unit: str = value(choices=("seconds", "updates"))
    device: str = value(resumable=True, sizing=True)
    dtype: str = value(choices=("float32", "float64"), sizing=True)
    threads: Any = value(**_COSMETIC)  # auto | null | an integer >= 1
    init_from: Optional[str] = value(sizing=True)  # noqa: UP045
    progress: bool = value(**_COSMETIC)
    checkpoint_every: Optional[float] = value(gt=0, **_COSMETIC)  # noqa: UP045
    resume: Any = value(**_COSMETIC)  # null | true | false | a run dir or run file
    memory_limit_mb: Optional[float] = value(gt=0, sizing=True, **_COSMETIC)  # noqa: UP045
    tensorboard: bool = value(**_COSMETIC)  # also write TensorBoard event files (higbench.runner.tensorboard)
    sink: Any = value(None, **_COSMETIC)  # side sinks, NAME -> {_target_, ...}: the conf/sink/ group (higbench.runner.sinks)


@dataclasses.dataclass(frozen=True)
class Checked:
    """What ``validate`` found: the top-level keys typed, the problem node, the optimizer resolved."""

    run: RunConfig
    problem: DictConfig  # read-only, its defaults filled in
    optimizer: OptimizerChoice


# The lists each rule is read from (derived from the metadata above, never written twice):
COSMETIC_KEYS = keys_where(RunConfig, "identity", False)  # not part of a run's identity
RESUMABLE_KEYS = keys_where(RunConfig, "resumable")  # may change on resume=
JOB_DIR_EXCLUDED_KEYS = keys_where(RunConfig, "in_job_dir", False, nested=True)  # conf/config.yaml exclude_keys
SIZING_KEYS = keys_where(RunConfig, "sizing")  # what the pre-flight's network build depends on
DIRNAME_BYTES = 200  # a job directory's name at most (file systems: 255, with the job number before it)


def flat_dirname(name: str) -> str:
    """A sweep job's directory name from Hydra's ``override_dirname``, one level deep.

    A ``/`` in a value (an ``init_from`` path) would nest directories: it becomes ``%2F``, and
    ``%`` becomes ``%25``, so two different values never share a name (a sweep run again
    finds each job's directory by its name). conf/config.yaml's ``hydra.sweep.subdir`` uses it.
    A name longer than ``DIRNAME_BYTES`` (a long ``init_from`` path; file systems allow 255 bytes
    with the job number before it) keeps its start and ends in a hash of the whole name.
    """
    flat = str(name).replace("%", "%25").replace("/", "%2F").encode()
    if len(flat) <= DIRNAME_BYTES:
        return flat.decode()
    return flat[: DIRNAME_BYTES - 17].decode(errors="ignore") + "~" + hashlib.sha256(flat).hexdigest()[:16]


def register_with_hydra() -> None:
    """What conf/config.yaml needs from Python: the schema (``higbench_schema``, first in its
    defaults), higbench's sweepers, the ``higbench.flat_dirname`` resolver of its sweep subdir, the keys a job's
    directory name leaves out (``higbench.job_dir_excluded_keys``, from the schema) and the
    problem and optimizer blocks of its help (``higbench.problem_help``, ``higbench.optimizer_help``,
    from the cards). Idempotent.
    Hydra hands both to its launchers' workers with its other global state."""
    ConfigStore.instance().store(name="higbench_schema", node=RunConfig)
    OmegaConf.register_new_resolver("higbench.flat_dirname", flat_dirname, replace=True)
    # hydra.job.config.override_dirname.exclude_keys: the keys the schema keeps out of job names
    OmegaConf.register_new_resolver("higbench.job_dir_excluded_keys", lambda: list(JOB_DIR_EXCLUDED_KEYS), replace=True)
    # hydra.help.template: the problem and optimizer blocks of --help, one line per card
    OmegaConf.register_new_resolver("higbench.problem_help", problem_help, replace=True)
    OmegaConf.register_new_resolver("higbench.optimizer_help", optimizer_help, replace=True)
    # Its sweepers (joblist, and the basic sweeper that runs every batch): Hydra's plugin scan
    # misses hydra_plugins/ of an editable install (tests/figures/test_figures_units.py::
    # test_joblist_sweeper_runs_a_job_list).
    from hydra_plugins.higbench_joblist_sweeper.joblist_sweeper import register

    register()


def config_dir() -> str:
    """conf/ of a checkout (or editable install), else the copy shipped in the wheel.

    Everything that composes higbench's config asks for it here, so the schema and resolver
    it needs are registered here (``register_with_hydra``), not as a side effect of an import.
    """
    register_with_hydra()
    return str(conf_dir())


def to_plain(cfg: DictConfig | dict) -> dict:
    """The config as plain Python containers, interpolations resolved (errors name the key)."""
    if isinstance(cfg, dict):
        return cfg
    if "hydra" in cfg:  # a config composed with its hydra node: validate the task part only
        from omegaconf import open_dict, read_write

        cfg = cfg.copy()
        with read_write(cfg), open_dict(cfg):
            del cfg["hydra"]
    try:
        data = OmegaConf.to_container(cfg, resolve=True)
    except OmegaConfBaseException as exc:
        key = getattr(exc, "full_key", None) or "?"
        raw = dotted_get(OmegaConf.to_container(cfg, resolve=False), str(key), "?")  # the value as written
        message = " ".join(str(exc.msg if hasattr(exc, "msg") else exc).split())
        raise ConfigError(str(key), raw if key != "?" else "?", f"cannot be resolved ({message})") from None
    assert isinstance(data, dict)
    data.pop("hydra", None)
    return data


def validate(cfg: DictConfig | dict) -> Checked:
    """Raise ConfigError for the first bad key or value; else the config, typed. Builds
    nothing but the optimizer's trial on a dummy parameter, writes nothing."""
    data = to_plain(cfg)
    top: RunConfig = check(RunConfig, data, typed=True)
    if top.budget.seconds is None and top.budget.max_updates is None:
        raise ConfigError("budget", "{seconds:null,max_updates:null}", "set at least one of budget.seconds, budget.max_updates")
    device, threads, resume = top.device, top.threads, top.resume
    if device not in DEVICES and not re.fullmatch(r"cuda:\d+", device):
        raise ConfigError("device", device, f"must be one of {', '.join(DEVICES)} (or cuda:<index>)")
    if not (threads is None or threads == "auto" or (type(threads) is int and threads >= 1)):
        raise ConfigError("threads", threads, "must be auto, null or an integer >= 1")
    if type(threads) is int and threads > max_threads():  # libgomp would fail to allocate them (a traceback)
        raise ConfigError("threads", threads, f"must be at most {max_threads()} (8 per core of this machine, at least 256)")
    if not (resume is None or isinstance(resume, bool) or (isinstance(resume, str) and resume)):
        raise ConfigError("resume", resume, "must be null, true, false, or the path of a run directory or run file")
    if top.init_from == "":
        raise ConfigError("init_from", "", "must be the path of a run file or null")

    problem = _validate_problem(data.get("problem"))
    for size_key in ("train_size", "epoch_size"):
        size = problem.get(size_key)
        if isinstance(size, int) and top.batch_size > size:
            why = f"must not exceed problem.{size_key}={size} (no full batch would fit)"
            raise ConfigError("batch_size", top.batch_size, why)
    optimizer = check_optimizer(data.get("optimizer"), device)
    if needs_inverse_simulator(optimizer.cls):  # SIP
        if not problem_class(data["problem"]).has_inverse_simulator():
            name = data["optimizer"].get("name", data["optimizer"]["_target_"])
            raise ConfigError("optimizer", name, f"problem {problem['name']} has no inverse simulator")

    if device.startswith("cuda"):
        import torch

        if not torch.cuda.is_available():
            raise ConfigError("device", device, "CUDA is not available on this machine (use cpu or auto)")
    # init_from's file is read (and checked) once, by the plan: higbench.runner.rundir.final_weights
    return Checked(top, _read_only({**problem, **data["problem"]}), optimizer)  # the problem's node, its defaults filled in


def typed(cfg: DictConfig | dict) -> Checked:
    """A config's typed parts, without its checks: for code that calls ``train`` itself with a
    config it vouches for (``runner.plan.Plan.for_run``; tests train outside the bounds)."""
    data = to_plain(cfg)
    run = OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(RunConfig), data))
    problem = {**OmegaConf.to_container(OmegaConf.structured(problem_class(data["problem"]).Config)), **data["problem"]}
    return Checked(run, _read_only(problem), optimizer_choice(data["optimizer"]))


def _read_only(node: dict) -> DictConfig:
    return OmegaConf.create(node, flags={"readonly": True})


def max_threads() -> int:
    """The most threads a run may ask for: beyond a few per core they only oversubscribe."""
    import os

    return max(256, 8 * (os.cpu_count() or 1))


BOOL_KEYS = tuple(f.name for f in dataclasses.fields(RunConfig) if f.type in (bool, "bool"))


def check_bool_overrides(overrides: list[str]) -> None:
    """``progress=2``: OmegaConf would take any number for true; a switch is true or false."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    for line in overrides:
        key = line.partition("=")[0].lstrip("+~")
        if key not in BOOL_KEYS or "=" not in line:
            continue
        try:
            given = OverridesParser.create().parse_override(line).value()
        except Exception:  # noqa: BLE001 - Hydra's own composition says what does not parse
            continue
        if not isinstance(given, bool):
            raise ConfigError(key, line.partition("=")[2], "must be true or false")


def problem_class(problem: dict) -> type:
    """The ``Problem`` class of a ``problem`` node: its ``_target_``, else (older run files) its name."""
    from higbench.problems.base import Problem, registry

    target = problem.get("_target_")
    if target is None:
        classes = registry()
        if problem.get("name") not in classes:
            raise ConfigError("problem.name", problem.get("name"), f"unknown problem; valid: {', '.join(sorted(classes))}")
        return classes[problem["name"]]
    try:
        cls = locate(target)
    except (ImportError, AttributeError) as exc:
        why = f"cannot import this problem class ({type(exc).__name__}: {exc})"
        if isinstance(exc, ImportError) and not str(target).startswith("higbench."):
            why += f"; is the folder of its module {str(target).rpartition('.')[0]!r} on PYTHONPATH?"
        raise ConfigError("problem._target_", target, why) from None
    if not (isinstance(cls, type) and issubclass(cls, Problem)):
        raise ConfigError("problem._target_", target, "is not a higbench.problems.base.Problem subclass")
    return cls


def _validate_problem(problem: Any) -> dict:
    if not isinstance(problem, dict):
        raise ConfigError("problem", problem, "must be a mapping (pick one with problem=<name>)")
    cls = problem_class(problem)
    plain = check(cls.Config, {k: v for k, v in problem.items() if k != CARD_KEY}, "problem.")  # its card: higbench.cards
    if cls.name != "?" and plain["name"] != cls.name:  # the name a run file records must be the class's
        raise ConfigError("problem.name", plain["name"], f"is not the name of {cls.__module__}.{cls.__qualname__} ({cls.name})")
    return plain


_HYDRA_REFERENCE = re.compile(r"\$\{hydra:([^}]+)\}")


def check_hydra_references(cfg: DictConfig) -> None:
    """Refuse ``${hydra:<key>}`` in the task config where this job's Hydra config has no such key.

    Hydra resolves a missing key to None (``threads='${hydra:launcher.cpus_per_task}'`` with
    a launcher that has no ``cpus_per_task`` would silently become ``threads=null``).
    """
    raw = OmegaConf.to_container(cfg, resolve=False)
    raw.pop("hydra", None)
    launcher = OmegaConf.select(cfg, "hydra.launcher._target_", default="?")
    for key, node in leaves(raw):
        for ref in _HYDRA_REFERENCE.findall(node) if isinstance(node, str) else ():
            where = f"hydra.{ref.strip()}"
            if OmegaConf.select(cfg, where, default=ABSENT, throw_on_missing=False, throw_on_resolution_failure=False) is ABSENT:
                raise ConfigError(key, node, f"{where} does not exist in this job's Hydra config (launcher {launcher})")
