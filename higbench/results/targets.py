"""What a problem is judged at, and when a run got there: the one place both are decided.

A problem's config owns its test-loss targets (``problem.targets``) and its league budget
(``problem.league_seconds``); every reader takes them from here: the end-of-run summary, the
results index's ``time_to_<t>`` columns, ``--profile``, the league, ``scripts/time_to_loss.py``,
``scripts/performance_profile.py`` and ``higbench.bench.devices``.

    for_problem("oscillator")          # the shipped conf/problem/oscillator.yaml's targets
    for_problem(stored_config)         # a run's own (its config recorded them), else the shipped ones
    reach_index(test_loss, 1e-3)       # the time-to-target rule: index of the first evaluation <= target

The shipped configs are read with OmegaConf alone (no Hydra composition, no side effects);
a problem config that names another in its defaults (``dipole_cnn``: the dipole's) gets its base's.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np


def _conf_dir() -> Path:
    from higbench.config import config_dir  # the one rule for where conf/ lives (checkout or wheel)

    return Path(config_dir())


@cache
def shipped_problem(name: str) -> dict:
    """The ``problem`` node of conf/problem/<name>.yaml, its defaults' bases merged first;
    {} for a name with no shipped config (an out-of-tree problem)."""
    from omegaconf import OmegaConf

    path = _conf_dir() / "problem" / f"{name}.yaml"
    if not name or "/" in name or not path.is_file():
        return {}
    conf = OmegaConf.to_container(OmegaConf.load(path))
    merged: dict = {}
    for base in conf.get("defaults") or []:
        if isinstance(base, str) and base != "_self_":
            merged.update(shipped_problem(base))
    merged.update(conf.get("problem") or {})
    return merged


def _problem_node(source: str | Mapping | Any) -> tuple[str, Mapping]:
    """(problem name, the problem node the source carries) of a name, a run's config (with a
    ``problem`` key) or a problem node itself."""
    if isinstance(source, str):
        return source, {}
    node = source.get("problem", source) if hasattr(source, "get") else {}
    if not hasattr(node, "get"):  # a config whose ``problem`` is a plain string (old files)
        return str(node), {}
    return str(node.get("name") or ""), node


MAX_TARGETS = 32  # more levels than this in a stored config is not a problem's targets (a crafted file)


def _levels(values: Any) -> tuple[float, ...] | None:
    """Stored targets as floats; None for anything else (text, too many, not numbers)."""
    if values is None or isinstance(values, str) or not hasattr(values, "__len__") or len(values) > MAX_TARGETS:
        return None
    try:
        return tuple(float(v) for v in values)
    except (TypeError, ValueError):
        return None


def for_problem(source: str | Mapping | Any) -> tuple[float, ...]:
    """The test-loss targets of a problem, highest first as the config lists them: a stored
    config's own ``problem.targets``, else the shipped conf/problem/<name>.yaml's; () when
    neither has any (an out-of-tree problem that declares none)."""
    name, node = _problem_node(source)
    own = _levels(node.get("targets")) if node else None
    if own is not None:
        return own
    return _levels(shipped_problem(name).get("targets")) or ()


def league_seconds(source: str | Mapping | Any) -> float | None:
    """The problem's league budget (training-clock seconds per run), stored or shipped."""
    name, node = _problem_node(source)
    value = (node.get("league_seconds") if node else None) or shipped_problem(name).get("league_seconds")
    return float(value) if value else None


def of_runs(runs, by: str = "problem.name") -> dict[str, list[float]]:
    """Per group of an index table (``load_runs``; ``by``: a column, e.g. the league's ``task``):
    the targets its newest run recorded (``problem.targets``), else its problem's shipped ones.
    Groups with neither are absent."""
    if runs is None or not len(runs) or by not in runs:
        return {}
    if "started" in runs:
        runs = runs.sort_values("started", na_position="first", kind="stable")
    out: dict[str, list[float]] = {}
    for group, rows in runs.groupby(by, sort=True):
        stored = rows["problem.targets"].dropna() if "problem.targets" in rows else []
        levels = _levels(stored.iloc[-1]) if len(stored) else None
        if levels is None:
            levels = for_problem(str(rows["problem.name"].iloc[-1]) if "problem.name" in rows else str(group))
        if levels:
            out[str(group)] = list(levels)
    return out


# -- the time-to-target rule -----------------------------------------------------------------


def reach_index(losses: Sequence[float] | np.ndarray, target: float) -> int | None:
    """The one time-to-target rule: the index of the first evaluation whose loss is at or
    below ``target`` (None: never). Its training clock (``wall_time``) is the time to the
    target, its ``step`` the updates; NaN never counts as reached."""
    hit = np.flatnonzero(np.asarray(losses, dtype=float) <= target)
    return int(hit[0]) if len(hit) else None


def time_to(losses: Sequence[float] | np.ndarray, clock: Sequence[float] | np.ndarray, target: float) -> float:
    """Training clock at ``reach_index`` (inf when the target was never reached)."""
    i = reach_index(losses, target)
    return float(np.asarray(clock, dtype=float)[i]) if i is not None else float("inf")
