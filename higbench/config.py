"""Validation of a composed config: every key typed and range-checked, unknown keys refused.

The schema is explicit: one table for the top-level keys, one per problem and one for the
optimizer keys (plus, per optimizer class, the constructor arguments it accepts). Each row
is ``key: Check(predicate, requirement)``. ``validate(cfg)`` raises ``ConfigError`` naming
the key and the value for the first problem it finds; the CLI turns it into a one-line
error and exit code 2 before anything is written.

Adding a problem: add its table to ``PROBLEM_RULES`` below, or let the ``Problem`` class
declare it with the classmethod ``config_rules()`` returning ``{key: Check}`` (used for
problems that have no table here). Adding a top-level key: add a row to ``TOP_RULES``.

This module does not import torch (bad configs are refused in a fraction of a second);
only checks that need it (a CUDA device, an optimizer class outside the table) import it.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from numbers import Real
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

# Kept torch-free: these mirror higbench.optim.inversion.TRUNCATION_MODES,
# higbench.optim.hig.SOLVERS/JACOBIANS and higbench.problems.networks (tests check they agree).
TRUNCATION_MODES = ("relative", "absolute")
SOLVERS = ("auto", "gram", "svd")
JACOBIANS = ("structured", "naive")  # mirrors higbench.optim.hig.JACOBIANS
ACTIVATIONS = ("tanh", "relu")
INIT_SCHEMES = ("glorot", "torch")
DEVICES = ("cpu", "cuda", "auto")
DTYPES = ("float32", "float64")
EVAL_UNITS = ("seconds", "updates")
LOSS_REDUCTIONS = ("mean", "sum")  # mirrors higbench.problems.base.LOSS_REDUCTIONS


class ConfigError(ValueError):
    """A config value that cannot work; ``str()`` is the one-line message."""

    def __init__(self, key: str, value: Any, requirement: str):
        self.key, self.value, self.requirement = key, value, requirement
        super().__init__(f"{key}={show(value)}: {requirement}")


def show(value: Any) -> str:
    """A value as the user would type it on the command line."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return value if value and re.fullmatch(r"[\w./:+-]+", value) else repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(show(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ",".join(f"{k}:{show(v)}" for k, v in value.items()) + "}"
    return str(value)


# -- checks: a predicate and the sentence that says what the value must be ------------------


@dataclass(frozen=True)
class Check:
    ok: Callable[[Any], bool]
    requirement: str


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_real(v) -> bool:
    return isinstance(v, Real) and not isinstance(v, bool) and math.isfinite(v)


def _bounds_text(lo, hi, lo_open, hi_open) -> str:
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {lo}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {hi}"
    return "finite"


def _in_bounds(v, lo, hi, lo_open, hi_open) -> bool:
    if lo is not None and (v <= lo if lo_open else v < lo):
        return False
    if hi is not None and (v >= hi if hi_open else v > hi):
        return False
    return True


def _maybe_null(check: Check, optional: bool) -> Check:
    if not optional:
        return check
    return Check(lambda v: v is None or check.ok(v), check.requirement + " or null")


def real(lo=None, hi=None, *, lo_open=False, hi_open=False, optional=False) -> Check:
    text = f"must be a number {_bounds_text(lo, hi, lo_open, hi_open)}"
    return _maybe_null(Check(lambda v: _is_real(v) and _in_bounds(v, lo, hi, lo_open, hi_open), text), optional)


def positive(optional=False) -> Check:
    return real(0, lo_open=True, optional=optional)


def integer(lo=None, hi=None, *, optional=False) -> Check:
    text = f"must be an integer {_bounds_text(lo, hi, False, False)}"
    return _maybe_null(Check(lambda v: _is_int(v) and _in_bounds(v, lo, hi, False, False), text), optional)


def choice(options, *, optional=False) -> Check:
    options = tuple(options)
    return _maybe_null(Check(lambda v: isinstance(v, str) and v in options, f"must be one of {', '.join(options)}"), optional)


def boolean(*, optional=False) -> Check:
    return _maybe_null(Check(lambda v: isinstance(v, bool), "must be true or false"), optional)


def string(*, optional=False) -> Check:
    return _maybe_null(Check(lambda v: isinstance(v, str) and v != "", "must be a non-empty string"), optional)


def int_list(lo=1, *, min_len=1) -> Check:
    text = f"must be a list of at least {min_len} integer(s) >= {lo}"
    return Check(lambda v: isinstance(v, list) and len(v) >= min_len and all(_is_int(x) and x >= lo for x in v), text)


def real_list(length=None) -> Check:
    text = f"must be a list of {length} finite numbers" if length else "must be a list of finite numbers"
    return Check(lambda v: isinstance(v, list) and (length is None or len(v) == length) and all(_is_real(x) for x in v), text)


def _device_ok(v) -> bool:
    return isinstance(v, str) and (v in DEVICES or re.fullmatch(r"cuda:\d+", v) is not None)


def _resume_ok(v) -> bool:
    return v is None or isinstance(v, bool) or (isinstance(v, str) and v != "")


# -- the schema ----------------------------------------------------------------------------

# Top-level keys (dotted). Required keys must be present; the others may be absent.
TOP_RULES: dict[str, Check] = {
    "seed": integer(0, 2**63 - 1),
    "batch_size": integer(1),
    "budget.seconds": positive(optional=True),
    "budget.max_updates": integer(1, optional=True),
    "eval_every": positive(),
    "eval_unit": choice(EVAL_UNITS),
    "device": Check(_device_ok, f"must be one of {', '.join(DEVICES)} (or cuda:<index>)"),
    "dtype": choice(DTYPES),
    "threads": Check(lambda v: v is None or v == "auto" or (_is_int(v) and v >= 1), "must be auto, null or an integer >= 1"),
    "init_from": string(optional=True),
    "progress": boolean(),
    "checkpoint_every": positive(optional=True),
    "resume": Check(_resume_ok, "must be null, true, false, or the path of a run directory or run file"),
    "memory_limit_mb": positive(optional=True),
}
REQUIRED_TOP = ("seed", "batch_size", "budget.seconds", "budget.max_updates", "eval_every", "device", "dtype")
SECTIONS = ("problem", "optimizer")

# Keys shared by the problems (a problem table picks the ones it uses).
_DATA = {
    "train_size": integer(1),
    "test_size": integer(1),
    "data_seed": integer(0),
    "init": choice(INIT_SCHEMES),
    "loss_reduction": choice(LOSS_REDUCTIONS),
}

# problem.solver of the time-stepping problems: the compiled loop with its adjoint, or plain torch.
PHYSICS_SOLVERS = ("fast", "reference")

PROBLEM_RULES: dict[str, dict[str, Check]] = {
    "toy": {
        **_DATA,
        "gamma": positive(),
        "hidden": integer(1),
        "probe_x": real(),
    },
    "oscillator": {
        **_DATA,
        "dt": positive(),
        "steps": integer(1),
        "coupling": real(),
        "control": real_list(2),
        "hidden": int_list(1, min_len=0),
        "activation": choice(ACTIVATIONS),
        "solver": choice(PHYSICS_SOLVERS),
    },
    "poisson": {
        **{k: v for k, v in _DATA.items() if k != "train_size"},
        "grid": integer(2),
        "modes": integer(1),
        "epoch_size": integer(1),
        "hidden": int_list(1, min_len=0),
        "activation": choice(ACTIVATIONS),
    },
    "dipole": {
        **_DATA,
        "model": choice(("mlp", "cnn")),
        "dt": positive(),
        "steps": integer(1),
        "hidden": int_list(1, min_len=0),
        "cnn_channels": integer(1),
        "cnn_layers": integer(1, 6),  # 6 valid convolutions of kernel 3 take 14 points to 2
        "activation": choice(ACTIVATIONS),
        "solver": choice(PHYSICS_SOLVERS),
    },
}

# Every optimizer key higbench knows, with its check.
OPTIMIZER_RULES: dict[str, Check] = {
    "name": string(),
    "_target_": string(),
    "lr": positive(),
    "tau": real(0),
    "kappa": real(-1, 1),
    "beta": real(-1, 1),
    "truncation": choice(TRUNCATION_MODES),
    "solver": choice(SOLVERS),
    "precision": choice(DTYPES),
    "jacobian": choice(JACOBIANS),
    "momentum": real(0, 1, hi_open=True),
    "dampening": real(0, 1),
    "weight_decay": real(0),
    "eps": positive(),
    "betas": Check(
        lambda v: isinstance(v, list) and len(v) == 2 and all(_is_real(b) and 0 <= b < 1 for b in v),
        "must be two numbers in [0, 1)",
    ),
    "rho": real(0, 1),
    "alpha": real(0, 1, hi_open=True),
    "initial_accumulator_value": real(0),
    "lr_decay": real(0),
    "nesterov": boolean(),
    "amsgrad": boolean(),
    "centered": boolean(),
    "maximize": boolean(),
    "capturable": boolean(),
    "differentiable": boolean(),
    "decoupled_weight_decay": boolean(),
    "foreach": boolean(optional=True),
    "fused": boolean(optional=True),
}
OPTIMIZER_META = ("name", "_target_", "kind")

_JP = ("lr", "kappa", "beta", "tau", "truncation", "solver", "precision", "jacobian")
# Constructor arguments (besides params) of the optimizer classes in conf/optimizer/.
# A class not listed here is inspected (its signature) instead.
OPTIMIZER_ARGS: dict[str, tuple[str, ...]] = {
    "torch.optim.SGD": (
        "lr",
        "momentum",
        "dampening",
        "weight_decay",
        "nesterov",
        "maximize",
        "foreach",
        "differentiable",
        "fused",
    ),
    "torch.optim.Adam": (
        "lr",
        "betas",
        "eps",
        "weight_decay",
        "amsgrad",
        "foreach",
        "maximize",
        "capturable",
        "differentiable",
        "fused",
        "decoupled_weight_decay",
    ),
    "torch.optim.Adagrad": (
        "lr",
        "lr_decay",
        "weight_decay",
        "initial_accumulator_value",
        "eps",
        "foreach",
        "maximize",
        "differentiable",
        "fused",
    ),
    "torch.optim.Adadelta": ("lr", "rho", "eps", "weight_decay", "foreach", "capturable", "maximize", "differentiable"),
    "torch.optim.RMSprop": (
        "lr",
        "alpha",
        "eps",
        "weight_decay",
        "momentum",
        "centered",
        "capturable",
        "foreach",
        "maximize",
        "differentiable",
    ),
    "higbench.optim.JacobianPower": _JP,
    "higbench.optim.HIG": _JP,
    "higbench.optim.GaussNewton": _JP,
    "higbench.optim.hig.JacobianPower": _JP,
    "higbench.optim.hig.HIG": _JP,
    "higbench.optim.hig.GaussNewton": _JP,
}
JACOBIAN_POWER_TARGETS = tuple(k for k, v in OPTIMIZER_ARGS.items() if v is _JP)


def optimizer_args(target: str, keys=()) -> tuple[str, ...]:
    """Constructor keyword arguments of an optimizer class.

    From the table when it covers ``keys`` (no torch import), else from the class's
    signature (an argument added to a class before its row here is still accepted).
    """
    if target in OPTIMIZER_ARGS and all(k in OPTIMIZER_ARGS[target] or k in OPTIMIZER_META for k in keys):
        return OPTIMIZER_ARGS[target]
    import inspect

    from hydra.utils import get_class

    try:
        cls = get_class(target)
    except Exception as exc:  # noqa: BLE001 - ImportError, AttributeError, ValueError from Hydra
        raise ConfigError("optimizer._target_", target, f"cannot import this optimizer class ({type(exc).__name__})") from None
    names: list[str] = []
    for klass in cls.__mro__:  # follow **kwargs up to the class that takes them
        params = list(inspect.signature(klass.__init__).parameters.values())[1:]
        names += [
            p.name for p in params if p.name not in ("params", *names) and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        ]
        if not any(p.kind is p.VAR_KEYWORD for p in params) or klass is object:
            break
    return tuple(names)


def problem_rules(name: str) -> dict[str, Check] | None:
    """The table of a problem: ours, else the problem class's ``config_rules()``; None if unknown."""
    if name in PROBLEM_RULES:
        return PROBLEM_RULES[name]
    from higbench.problems.base import registry  # imports torch: only for problems without a table

    cls = registry().get(name)
    if cls is None:
        return None
    rules = getattr(cls, "config_rules", None)
    return dict(rules()) if callable(rules) else {}


def known_problems() -> list[str]:
    try:
        from higbench.problems.base import registry

        return sorted(set(PROBLEM_RULES) | set(registry()))
    except Exception:  # noqa: BLE001
        return sorted(PROBLEM_RULES)


# -- validation ----------------------------------------------------------------------------

_ABSENT = object()


def _lookup(data: dict, dotted: str):
    node = data
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            return _ABSENT
        node = node[part]
    return node


def _unknown(key: str, value, valid) -> ConfigError:
    return ConfigError(key, value, f"unknown key; valid keys: {', '.join(sorted(valid))}")


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
        raw = OmegaConf.to_container(cfg, resolve=False)  # the value as written, unresolved
        for part in str(key).split("."):
            raw = raw.get(part, "?") if isinstance(raw, dict) else "?"
        message = " ".join(str(exc.msg if hasattr(exc, "msg") else exc).split())
        raise ConfigError(str(key), raw if key != "?" else "?", f"cannot be resolved ({message})") from None
    assert isinstance(data, dict)
    data.pop("hydra", None)
    return data


def _check(key: str, value, check: Check) -> None:
    if not check.ok(value):
        raise ConfigError(key, value, check.requirement)


def _check_section(section: str, values: dict, rules: dict[str, Check], valid: tuple[str, ...] | None) -> None:
    """Type/range check every key of a section; refuse keys outside ``valid``."""
    for key, value in values.items():
        full = f"{section}.{key}"
        if valid is not None and key not in valid:
            raise _unknown(full, value, valid)
        if key in rules:
            _check(full, value, rules[key])


def validate(cfg: DictConfig | dict) -> None:
    """Raise ConfigError for the first bad key or value. Builds nothing, writes nothing."""
    data = to_plain(cfg)

    # top level: unknown keys, then every rule
    top_valid = {k.split(".")[0] for k in TOP_RULES} | set(SECTIONS)
    for key, value in data.items():
        if key not in top_valid:
            raise _unknown(key, value, top_valid)
    budget = data.get("budget")
    if not isinstance(budget, dict):
        raise ConfigError("budget", budget, "must be a mapping with keys seconds, max_updates")
    for key, value in budget.items():
        if key not in ("seconds", "max_updates"):
            raise _unknown(f"budget.{key}", value, ("seconds", "max_updates"))
    for key, check in TOP_RULES.items():
        value = _lookup(data, key)
        if value is _ABSENT:
            if key in REQUIRED_TOP:
                raise ConfigError(key, "<missing>", "is required")
            continue
        _check(key, value, check)
    if budget.get("seconds") is None and budget.get("max_updates") is None:
        raise ConfigError("budget", "{seconds:null,max_updates:null}", "set at least one of budget.seconds, budget.max_updates")

    _validate_optimizer(data)
    _validate_problem(data)

    if str(data["device"]).startswith("cuda"):
        import torch

        if not torch.cuda.is_available():
            raise ConfigError("device", data["device"], "CUDA is not available on this machine (use cpu or auto)")
    if data.get("init_from"):
        check_init_from_file(data["init_from"], data["problem"]["name"])


def _validate_optimizer(data: dict) -> None:
    opt = data.get("optimizer")
    if not isinstance(opt, dict):
        raise ConfigError("optimizer", opt, "must be a mapping (pick one with optimizer=<name>)")
    target = opt.get("_target_")
    _check("optimizer._target_", target, OPTIMIZER_RULES["_target_"])
    args = optimizer_args(target, tuple(opt))
    _check_section("optimizer", opt, OPTIMIZER_RULES, (*OPTIMIZER_META, *args))
    if "lr" in args and "lr" not in opt:
        raise ConfigError("optimizer.lr", "<missing>", "is required")
    if opt.get("truncation", "relative") == "relative" and _is_real(opt.get("tau")) and opt["tau"] > 1:
        raise ConfigError(
            "optimizer.tau", opt["tau"], "must lie in [0, 1] with truncation=relative (tau > 1 drops every singular value)"
        )
    if opt.get("nesterov") and (not opt.get("momentum") or opt.get("dampening", 0) != 0):
        raise ConfigError("optimizer.nesterov", True, "needs optimizer.momentum > 0 and optimizer.dampening = 0")


def _validate_problem(data: dict) -> None:
    prob = data.get("problem")
    if not isinstance(prob, dict):
        raise ConfigError("problem", prob, "must be a mapping (pick one with problem=<name>)")
    name = prob.get("name")
    _check("problem.name", name, string())
    rules = problem_rules(name)
    if rules is None:
        raise ConfigError("problem.name", name, f"unknown problem; valid: {', '.join(known_problems())}")
    # A problem class that declares no rules gets its keys type-checked only where known.
    _check_section("problem", prob, rules, ("name", *rules) if rules else None)
    for key in rules:
        if key not in prob:
            raise ConfigError(f"problem.{key}", "<missing>", f"is required by problem {name}")
    batch = data["batch_size"]
    for size_key in ("train_size", "epoch_size"):
        size = prob.get(size_key)
        if _is_int(size) and batch > size:
            raise ConfigError("batch_size", batch, f"must not exceed problem.{size_key}={size} (no full batch would fit)")


def check_init_from_file(path: str, problem_name: str) -> None:
    """``init_from``: an existing, readable run file of the same problem with final weights.

    The shapes of the weights against this config's network are checked later, once the
    network is built (``higbench.runner.train.preflight``), still before anything is written.
    """
    from higbench.runfile.reader import UnreadableRunFile, read_head, run_file_path

    p = run_file_path(path)
    if not p.is_file():
        raise ConfigError("init_from", path, "no such run file")
    try:
        head = read_head(p)
    except UnreadableRunFile as exc:
        raise ConfigError("init_from", path, str(exc).split(": ", 1)[-1]) from None
    if not head.has_weights:
        raise ConfigError("init_from", path, "run file holds no final weights (run still going, or killed)")
    if head.problem and head.problem != problem_name:
        raise ConfigError("init_from", path, f"run is of problem {head.problem}, not {problem_name}")


def init_from_path(path: str) -> Path:
    from higbench.runfile.reader import run_file_path

    return run_file_path(path)


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
