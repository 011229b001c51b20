"""Claims as data: a claim of the paper, its rule, and the measurement its verdict is decided on;
with the helpers the measurements share (values read from runs, formatting)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from higbench.figures.data import RunData

REPRODUCED, PARTLY, NOT, NA = "reproduced", "partly", "not", "n/a"
CAUSES = {
    "budget": "too short a budget (the trend points the paper's way)",
    "deviation": "a deviation from the paper forced by cost",
    "unspecified": "a setting the paper does not give",
    "disagreement": "a genuine disagreement with the paper",
    "bug": "a bug (fixed or open)",
    "seeds": "too few seeds for a median",
    "open": "not yet examined with targeted runs",
}


class Missing(Exception):
    """The runs a claim needs are missing (verdict n/a)."""


@dataclass
class Claim:
    """A headline claim of the paper, checked against the runs of ``figures``.

    measure(datas) -> (measured text, full, partly): the values behind the rule, read from the
    runs (``datas``: the FigureData of each figure), and whether the rule holds fully and
    partly; full None means the rule cannot be applied (n/a, ``partly`` then says why). The
    verdict is "reproduced"/"partly"/"not". Budgets, seeds and causes: ``fidelity.py``.
    """

    id: str
    figures: tuple[str, ...]
    statement: str
    paper: str
    rule: str
    measure: Callable[[dict], tuple]
    min_seconds: float | None = None  # below this training budget per run: "n/a (budget)"
    min_seeds: int = 1  # fewer seeds per setting: at most "partly" (a seed search counts as settled)
    cause: tuple[str, str] | None = None  # root cause of a "not"/"partly" verdict: (category, evidence)

    def check(self, datas: dict) -> tuple[str, str, str]:
        """(measured, verdict, why)."""
        try:
            measured, full, partly = self.measure(datas)
        except Missing as m:
            return "-", NA, f"runs missing: {m}"
        if full is None:
            return measured, NA, f"rule: {self.rule}; {partly}"
        return measured, REPRODUCED if full else (PARTLY if partly else NOT), f"rule: {self.rule}"


CLAIMS: list[Claim] = []


def claim(cid: str, figures: str, paper: str):
    """Declare the decorated measurement a claim: its docstring is the statement, then "Rule: " the rule."""

    def declare(measure: Callable) -> Callable:
        statement, _, rule = " ".join(measure.__doc__.split()).partition(" Rule: ")
        CLAIMS.append(Claim(cid, tuple(figures.split()), statement.removesuffix("."), paper, rule, measure))
        return measure

    return declare


def need(*groups, what: str) -> None:
    if any(not g for g in groups):
        raise Missing(what)


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
    out = [float(c[-1]) if len(c) and np.isfinite(c[-1]) else math.inf for c in (_loss(r) for r in runs)]
    return median(out) if out else math.nan


def best(runs: list[RunData]) -> float:
    """Median over seeds of the lowest test loss reached."""
    out = [float(c.min()) if len(c) else math.inf for c in (_loss(r)[np.isfinite(_loss(r))] for r in runs)]
    return median(out) if out else math.nan


def _loss(r: RunData) -> np.ndarray:
    return r.curves["test_loss"].to_numpy(dtype=float)


def end_time(r: RunData) -> float:
    return float(r.curves["wall_time"].iloc[-1])


def loss_at(run: RunData, t: float, column: str = "test_loss", x: str = "wall_time") -> float:
    """Loss at training time t (log-linear interpolation between evaluations; last value after)."""
    xs, ys = run.curves[x].to_numpy(dtype=float), run.curves[column].to_numpy(dtype=float)
    return float(10 ** np.interp(t, xs, np.log10(np.maximum(ys, 1e-300)))) if len(xs) else math.nan


def crossing_time(a: RunData, b: RunData) -> float | None:
    """First evaluation time of ``a`` from which on ``a`` stays below ``b`` (interpolated); None if never."""
    ts, ys = a.curves["wall_time"].to_numpy(dtype=float), _loss(a)
    below = [y < loss_at(b, t) for t, y in zip(ts, ys) if t <= min(ts[-1], end_time(b))]
    if not below or not below[-1]:
        return None
    i = len(below) - 1
    while i > 0 and below[i - 1]:
        i -= 1
    return float(ts[i])


def budget_of(run: RunData) -> str:
    s = run.cfg("budget.seconds")
    return f"{s:g} s" if s is not None else f"{run.cfg('budget.max_updates')} updates"


def stable(r: RunData) -> bool:
    return r.status == "completed" and r.final_loss < r.initial_loss
