"""Small helpers for the claim checks: values read from runs, verdict rules, formatting."""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from higbench.figures.data import RunData

REPRODUCED, PARTLY, NOT, NA = "reproduced", "partly", "not", "n/a"


def verdict(full: bool, partly: bool) -> str:
    return REPRODUCED if full else (PARTLY if partly else NOT)


def e(v: float) -> str:
    """1.234e-05 -> '1.2e-5'."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return str(v)
    m, x = f"{v:.1e}".split("e")
    return f"{m}e{int(x)}"


def median(values: Iterable[float]) -> float:
    vals = [v for v in values if v is not None and not math.isnan(v)]
    return float(np.median(vals)) if vals else math.nan


def final(runs: list[RunData]) -> float:
    """Median over seeds of the final test loss (diverged runs: their last finite value or inf)."""
    out = []
    for r in runs:
        c = r.curves["test_loss"].to_numpy(dtype=float)
        out.append(float(c[-1]) if len(c) and np.isfinite(c[-1]) else math.inf)
    return median(out) if out else math.nan


def best(runs: list[RunData]) -> float:
    """Median over seeds of the lowest test loss reached."""
    out = []
    for r in runs:
        c = r.curves["test_loss"].to_numpy(dtype=float)
        c = c[np.isfinite(c)]
        out.append(float(c.min()) if len(c) else math.inf)
    return median(out) if out else math.nan


def loss_at(run: RunData, t: float, column: str = "test_loss", x: str = "wall_time") -> float:
    """Loss at training time t (log-linear interpolation between evaluations; last value after)."""
    c = run.curves
    xs, ys = c[x].to_numpy(dtype=float), c[column].to_numpy(dtype=float)
    if len(xs) == 0:
        return math.nan
    return float(10 ** np.interp(t, xs, np.log10(np.maximum(ys, 1e-300))))


def crossing_time(a: RunData, b: RunData) -> float | None:
    """First evaluation time of ``a`` from which on ``a`` stays below ``b`` (interpolated); None if never."""
    c = a.curves
    ts, ys = c["wall_time"].to_numpy(dtype=float), c["test_loss"].to_numpy(dtype=float)
    t_end = min(ts[-1], b.curves["wall_time"].iloc[-1])
    below = [y < loss_at(b, t) for t, y in zip(ts, ys) if t <= t_end]
    if not below or not below[-1]:
        return None
    i = len(below) - 1
    while i > 0 and below[i - 1]:
        i -= 1
    return float(ts[i])


def budget_of(run: RunData) -> str:
    s = run.cfg("budget.seconds")
    if s is not None:
        return f"{s:g} s"
    return f"{run.cfg('budget.max_updates')} updates"


def missing_runs(*groups: list[RunData]) -> bool:
    return any(len(g) == 0 for g in groups)


def na(what: str) -> tuple[str, str, str]:
    return "-", NA, f"runs missing: {what}"
