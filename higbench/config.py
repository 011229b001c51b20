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
from higbench.errors import ConfigError, dotted_get, show
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
    """The top-level keys (defaults in conf/config.yaml; documented there and in --help)."""

    problem: Any = value(None, sizing=True)  # checked against its problem class's Config
    optimizer: Any = value(None, sizing=True)  # checked by its constructor (sizing: all but lr)
    seed: int = value(ge=0, le=2**63 - 1)
    batch_size: int = value(ge=1, sizing=True)
    budget: Budget = dataclasses.field(default_factory=Budget, metadata={"resumable": True})
    eval_every: float = value(gt=0, resumable=True, in_job_dir=False)
    eval_unit: str = value("seconds", choices=("seconds", "updates"))
    device: str = value(resumable=True, sizing=True)
    dtype: str = value(choices=("float32", "float64"), sizing=True)
    threads: Any = value("auto", **_COSMETIC)  # auto | null | an integer >= 1
    init_from: Optional[str] = value(None, sizing=True)  # noqa: UP045
    progress: bool = value(True, **_COSMETIC)
    checkpoint_every: Optional[float] = value(None, gt=0, **_COSMETIC)  # noqa: UP045
    resume: Any = value(None, **_COSMETIC)  # null | true | false | a run dir or run file
    memory_limit_mb: Optional[float] = value(None, gt=0, sizing=True, **_COSMETIC)  # noqa: UP045
    tensorboard: bool = value(False, **_COSMETIC)  # also write TensorBoard event files (higbench.runner.tensorboard)
    sink: Any = value(None, **_COSMETIC)  # side sinks, NAME -> {_target_, ...}: the conf/sink/ group (higbench.runner.sinks)


# The lists each rule is read from (derived from the metadata above, never written twice):
COSMETIC_KEYS = keys_where(RunConfig, "identity", False)  # not part of a run's identity
RESUMABLE_KEYS = keys_where(RunConfig, "resumable")  # may change on resume=
JOB_DIR_EXCLUDED_KEYS = keys_where(RunConfig, "in_job_dir", False, nested=True)  # conf/config.yaml exclude_keys
SIZING_KEYS = keys_where(RunConfig, "sizing")  # what the pre-flight's network build depends on
# optimizer keys that are not constructor arguments (its card: higbench.cards)
OPTIMIZER_META = ("name", "_target_", "kind", "extra", CARD_KEY)


def optimizer_kwargs(opt_cfg: Any) -> dict:
    """The constructor arguments of an ``optimizer`` node (lists become tuples, e.g. Adam's betas)."""
    kwargs = dict(opt_cfg) if isinstance(opt_cfg, dict) else OmegaConf.to_container(opt_cfg, resolve=True)
    for key in OPTIMIZER_META:
        kwargs.pop(key, None)
    return {k: tuple(v) if isinstance(v, list) else v for k, v in kwargs.items()}


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


def validate(cfg: DictConfig | dict) -> None:
    """Raise ConfigError for the first bad key or value. Builds nothing, writes nothing."""
    data = to_plain(cfg)
    top = check(RunConfig, data)
    if top["budget"].get("seconds") is None and top["budget"].get("max_updates") is None:
        raise ConfigError("budget", "{seconds:null,max_updates:null}", "set at least one of budget.seconds, budget.max_updates")
    device, threads, resume = top["device"], top["threads"], top["resume"]
    if device not in DEVICES and not re.fullmatch(r"cuda:\d+", device):
        raise ConfigError("device", device, f"must be one of {', '.join(DEVICES)} (or cuda:<index>)")
    if not (threads is None or threads == "auto" or (type(threads) is int and threads >= 1)):
        raise ConfigError("threads", threads, "must be auto, null or an integer >= 1")
    if type(threads) is int and threads > max_threads():  # libgomp would fail to allocate them (a traceback)
        raise ConfigError("threads", threads, f"must be at most {max_threads()} (8 per core of this machine, at least 256)")
    if not (resume is None or isinstance(resume, bool) or (isinstance(resume, str) and resume)):
        raise ConfigError("resume", resume, "must be null, true, false, or the path of a run directory or run file")
    if top["init_from"] == "":
        raise ConfigError("init_from", "", "must be the path of a run file or null")

    problem = _validate_problem(data.get("problem"))
    for size_key in ("train_size", "epoch_size"):
        size = problem.get(size_key)
        if isinstance(size, int) and top["batch_size"] > size:
            why = f"must not exceed problem.{size_key}={size} (no full batch would fit)"
            raise ConfigError("batch_size", top["batch_size"], why)
    check_optimizer(data.get("optimizer"), device)
    if needs_inverse_simulator(optimizer_class(data["optimizer"])):  # SIP
        if not problem_class(data["problem"]).has_inverse_simulator():
            name = data["optimizer"].get("name", data["optimizer"]["_target_"])
            raise ConfigError("optimizer", name, f"problem {problem['name']} has no inverse simulator")

    if device.startswith("cuda"):
        import torch

        if not torch.cuda.is_available():
            raise ConfigError("device", device, "CUDA is not available on this machine (use cpu or auto)")
    # init_from's file is read (and checked) once, by the plan: higbench.runner.plan.load_initial_weights


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


def constructor_args(cls: type) -> tuple[str, ...]:
    """Keyword arguments of an optimizer class (following ``**kwargs`` up to the class that takes them)."""
    import inspect

    names: list[str] = []
    for klass in cls.__mro__:
        params = list(inspect.signature(klass.__init__).parameters.values())[1:]
        if klass is not cls and [p.name for p in params] == ["params", "defaults"]:
            break  # a base optimizer's (torch's, pytorch-optimizer's): the subclass builds its defaults itself
        keywords = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
        names += [p.name for p in params if p.name not in ("params", *names) and p.kind in keywords]
        if not any(p.kind is p.VAR_KEYWORD for p in params) or klass is object:
            break
    return tuple(names)


def takes_any_keyword(cls: type) -> bool:
    """Whether the constructor itself accepts every keyword (``**kwargs``): a misspelt argument
    is then swallowed, never refused (pytorch-optimizer's SOAP and Shampoo)."""
    import inspect

    return any(p.kind is p.VAR_KEYWORD for p in inspect.signature(cls.__init__).parameters.values())


def optimizer_class(opt: Any) -> type:
    """The ``torch.optim.Optimizer`` subclass ``optimizer._target_`` names (never any other callable)."""
    import torch

    if not isinstance(opt, dict):
        raise ConfigError("optimizer", opt, "must be a mapping (pick one with optimizer=<name>)")
    target = opt.get("_target_")
    try:
        cls = locate(target)
    except ImportError as exc:
        if opt.get("extra"):  # a third-party optimizer: its YAML names the optional extra that installs it
            why = f'{target} comes with the {opt["extra"]} extra: pip install -e ".[{opt["extra"]}]"'
            raise ConfigError("optimizer", opt.get("name", target), why) from None
        raise ConfigError("optimizer._target_", target, f"cannot import this optimizer class ({type(exc).__name__})") from None
    except AttributeError as exc:
        raise ConfigError("optimizer._target_", target, f"cannot import this optimizer class ({type(exc).__name__})") from None
    if not (isinstance(cls, type) and issubclass(cls, torch.optim.Optimizer)):
        raise ConfigError("optimizer._target_", target, "is not a torch.optim.Optimizer subclass")
    return cls


def _check_number_types(cls: type, kwargs: dict) -> None:
    """An argument whose default is a number must be one (``kappa=abc``: one line, not a TypeError)."""
    import inspect

    defaults = {}
    for klass in reversed(cls.__mro__):
        if klass is not object:
            params = inspect.signature(klass.__init__).parameters.values()
            defaults.update({p.name: p.default for p in params if p.default is not inspect.Parameter.empty})
    for key, given in kwargs.items():
        default = defaults.get(key)
        number = isinstance(default, (int, float)) and not isinstance(default, bool)
        if number and (isinstance(given, (str, bool)) or given is None):
            raise ConfigError(f"optimizer.{key}", given, f"must be a number (the default is {default})")


def check_optimizer(opt: Any, device: str = "cpu") -> None:
    """Build the optimizer on a dummy parameter: its constructor checks its own arguments.

    When it refuses, each argument is left out in turn to find the one it refuses (a pair
    that conflicts, e.g. SGD's nesterov without momentum, names the one listed later).
    """
    import torch

    cls = optimizer_class(opt)
    kwargs = optimizer_kwargs(opt)
    if takes_any_keyword(cls):  # checked against its documented signature: a typo would train with the default
        known = constructor_args(cls)
        for key in kwargs:
            if key not in known:
                raise ConfigError(
                    f"optimizer.{key}", opt[key], f"not an argument of {opt['_target_']}; its arguments: {', '.join(known)}"
                )
    _check_number_types(cls, kwargs)

    trial_step = cls.__module__.startswith("torch.optim")  # ours (GN/HIG/LM) need a problem to step
    trial_device = device if device.startswith("cuda") and torch.cuda.is_available() else "cpu"  # capturable: CUDA only

    def refusal(args: dict) -> Exception | None:
        try:
            param = torch.nn.Parameter(torch.ones(2, device=trial_device))
            optimizer = cls([param], **args)
            if trial_step:  # some arguments fail only when used (L-BFGS history_size=0, Adam capturable)
                optimizer.step(lambda: _dummy_loss(optimizer, param))
        except Exception as exc:  # noqa: BLE001 - ValueError, TypeError, IndexError: whatever the class raises
            return exc
        return None

    exc = refusal(kwargs)
    if exc is None:
        return
    target = opt["_target_"]
    culprit = next((k for k in reversed(kwargs) if refusal({a: v for a, v in kwargs.items() if a != k}) is None), None)
    why = " ".join(str(exc).split()) or type(exc).__name__
    if culprit is None:
        raise ConfigError("optimizer", opt.get("name", target), f"{target} refuses its arguments: {why}")
    shown = opt[culprit]
    why = why.split(": ", 1)[1] if why.startswith(f"{culprit}=") and ": " in why else why  # "lr=-1: must be > 0"
    raise ConfigError(f"optimizer.{culprit}", shown, f"refused by {target}: {why}")


def _dummy_loss(optimizer, param):
    """The closure of ``check_optimizer``'s trial step: a quadratic on the dummy parameter."""
    import torch

    with torch.enable_grad():
        optimizer.zero_grad()
        loss = (param**2).sum()
        loss.backward()
    return loss


_HYDRA_REFERENCE = re.compile(r"\$\{hydra:([^}]+)\}")


def check_hydra_references(cfg: DictConfig) -> None:
    """Refuse ``${hydra:<key>}`` in the task config where this job's Hydra config has no such key.

    Hydra resolves a missing key to None (``threads='${hydra:launcher.cpus_per_task}'`` with
    a launcher that has no ``cpus_per_task`` would silently become ``threads=null``).
    """
    raw = OmegaConf.to_container(cfg, resolve=False)
    raw.pop("hydra", None)
    launcher = OmegaConf.select(cfg, "hydra.launcher._target_", default="?")

    def walk(node, prefix):
        if isinstance(node, dict):
            for k, v in node.items():
                walk(v, f"{prefix}{k}.")
        elif isinstance(node, list):
            for i, v in enumerate(node):
                walk(v, f"{prefix}{i}.")
        elif isinstance(node, str):
            for ref in _HYDRA_REFERENCE.findall(node):
                missing = object()
                found = OmegaConf.select(
                    cfg, f"hydra.{ref.strip()}", default=missing, throw_on_missing=False, throw_on_resolution_failure=False
                )
                if found is missing:
                    raise ConfigError(
                        prefix[:-1], node, f"hydra.{ref.strip()} does not exist in this job's Hydra config (launcher {launcher})"
                    )

    walk(raw, "")
