"""Validation of a composed config: every error names the key and the value, before any work.

Hydra already rejects keys that do not exist (struct mode); this checks types and ranges.
Each rule is one row of ``RULES``: (key, predicate, what the value must be).
"""

from __future__ import annotations

import math
from numbers import Real
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from higbench.optim.inversion import TRUNCATION_MODES
from higbench.optim.hig import SOLVERS

DEVICES = ("cpu", "cuda", "auto")
DTYPES = ("float32", "float64")
EVAL_UNITS = ("seconds", "updates")


class ConfigError(ValueError):
    def __init__(self, key: str, value, requirement: str):
        self.key, self.value, self.requirement = key, value, requirement
        super().__init__(f"{key}={value!r}: {requirement}")


def _number(v) -> bool:
    return isinstance(v, Real) and not isinstance(v, bool) and math.isfinite(v)


def _positive(v) -> bool:
    return _number(v) and v > 0


def _positive_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v > 0


def _optional(pred):
    return lambda v: v is None or pred(v)


def _one_of(options):
    return lambda v: v in options


# (dotted key, predicate, requirement); keys absent from the config are skipped.
RULES = [
    ("seed", lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 0, "must be an integer >= 0"),
    ("batch_size", _positive_int, "must be an integer > 0"),
    ("budget.seconds", _optional(_positive), "must be > 0 (seconds of training clock) or null"),
    ("budget.max_updates", _optional(_positive_int), "must be an integer > 0 or null"),
    ("eval_every", _positive, "must be > 0"),
    ("eval_unit", _one_of(EVAL_UNITS), f"must be one of {EVAL_UNITS}"),
    ("device", _one_of(DEVICES), f"must be one of {DEVICES}"),
    ("dtype", _one_of(DTYPES), f"must be one of {DTYPES}"),
    ("threads", _optional(_positive_int), "must be an integer > 0 or null"),
    ("optimizer.lr", _positive, "must be a number > 0"),
    ("optimizer.tau", lambda v: _number(v) and v >= 0, "must be a number >= 0"),
    ("optimizer.kappa", lambda v: _number(v) and -1 <= v <= 1, "must lie in [-1, 1]"),
    ("optimizer.beta", lambda v: _number(v) and -1 <= v <= 1, "must lie in [-1, 1]"),
    ("optimizer.truncation", _one_of(TRUNCATION_MODES), f"must be one of {TRUNCATION_MODES}"),
    ("optimizer.solver", _one_of(SOLVERS), f"must be one of {SOLVERS}"),
    ("optimizer.precision", _one_of(DTYPES), f"must be one of {DTYPES}"),
    ("optimizer.momentum", lambda v: _number(v) and 0 <= v < 1, "must lie in [0, 1)"),
    ("optimizer.weight_decay", lambda v: _number(v) and v >= 0, "must be >= 0"),
    ("optimizer.eps", _positive, "must be > 0"),
    ("problem.gamma", _positive, "must be > 0"),
    ("problem.train_size", _positive_int, "must be an integer > 0"),
    ("problem.test_size", _positive_int, "must be an integer > 0"),
]


def _get(cfg: DictConfig, key: str):
    node = OmegaConf.select(cfg, key, throw_on_missing=False, default="__absent__")
    return node


def validate(cfg: DictConfig) -> None:
    """Raise ConfigError for the first bad value. Cheap: builds nothing, trains nothing."""
    for key, ok, requirement in RULES:
        value = _get(cfg, key)
        if isinstance(value, str) and value == "__absent__":
            continue
        if not ok(value):
            raise ConfigError(key, value, requirement)
    if cfg.budget.seconds is None and cfg.budget.max_updates is None:
        raise ConfigError("budget", "seconds=null, max_updates=null", "set at least one of budget.seconds, budget.max_updates")
    train_size = _get(cfg, "problem.train_size")
    if _positive_int(train_size) and cfg.batch_size > train_size:
        raise ConfigError("batch_size", cfg.batch_size, f"must not exceed problem.train_size={train_size}")
    betas = _get(cfg, "optimizer.betas")
    if not (isinstance(betas, str) and betas == "__absent__"):
        if len(betas) != 2 or not all(_number(b) and 0 <= b < 1 for b in betas):
            raise ConfigError("optimizer.betas", list(betas), "must be two numbers in [0, 1)")
    if cfg.device == "cuda":
        import torch

        if not torch.cuda.is_available():
            raise ConfigError("device", "cuda", "CUDA is not available on this machine (use cpu or auto)")
    init_from = cfg.get("init_from")
    if init_from:
        if not Path(init_from).is_file():
            raise ConfigError("init_from", init_from, "no such run file")
