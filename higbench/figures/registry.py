"""The one registry of the paper's figures, tables and headline claims.

Each family module (toy, oscillator, poisson, dipole, ablation, tables) registers its
figures with ``register(Figure(...))`` and its claims with ``claim(Claim(...))``;
``figures()`` imports them all and returns the figures in the paper's order.
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable
from dataclasses import dataclass

from higbench.figures.spec import Figure

FAMILIES = ("toy", "oscillator", "poisson", "dipole", "ablation", "tables")

_FIGURES: dict[str, Figure] = {}
_CLAIMS: dict[str, Claim] = {}


@dataclass
class Claim:
    """A headline claim of the paper, checked against the runs of ``figures``.

    check(data) -> (measured, verdict, why) with ``data`` the FigureData of every figure
    in ``figures``; verdict is "reproduced", "partly" or "not" (decided by explicit rules
    in the check, on values read from the run files), "n/a" when the runs are missing.
    The claim is evaluated when its first figure is drawn and stored in that figure's
    sidecar; figures/REPORT.md collects them.
    """

    id: str
    figures: tuple[str, ...]
    statement: str
    paper: str
    check: Callable[[dict], tuple]
    # Below this training budget per run (seconds) the claim cannot show: "n/a (budget)".
    min_seconds: float | None = None
    # A comparison needs the median of this many seeds per setting to be "reproduced"
    # (fewer: at most "partly"); runs whose seed came from a seed search count as settled.
    min_seeds: int = 1
    # Root cause of a "not"/"partly" verdict, found with targeted runs: (category, evidence).
    # Categories: CAUSES. A check may return a 4th element (category, evidence) instead.
    cause: tuple[str, str] | None = None


CAUSES = {
    "budget": "too short a budget (the trend points the paper's way)",
    "deviation": "a deviation from the paper forced by cost",
    "unspecified": "a setting the paper does not give",
    "disagreement": "a genuine disagreement with the paper",
    "bug": "a bug (fixed or open)",
    "seeds": "too few seeds for a median",
    "open": "not yet examined with targeted runs",
}


def register(figure: Figure) -> Figure:
    if figure.id in _FIGURES:
        raise ValueError(f"figure {figure.id} registered twice")
    _FIGURES[figure.id] = figure
    return figure


def claim(c: Claim) -> Claim:
    if c.id in _CLAIMS:
        raise ValueError(f"claim {c.id} registered twice")
    _CLAIMS[c.id] = c
    return c


def _load() -> None:
    for name in FAMILIES:
        importlib.import_module(f"higbench.figures.{name}")


def _order(fid: str) -> tuple:
    m = re.fullmatch(r"(fig|table)(\d+)([a-z]?)", fid)
    if not m:
        return (2, 0, fid)
    return (0 if m.group(1) == "fig" else 1, int(m.group(2)), m.group(3))


def figures() -> dict[str, Figure]:
    """Every figure and table, in the paper's order."""
    _load()
    return {k: _FIGURES[k] for k in sorted(_FIGURES, key=_order)}


def claims() -> dict[str, Claim]:
    _load()
    from higbench.figures.fidelity import apply

    apply(_CLAIMS)  # minimum budgets, seeds and root causes (one table, with its evidence)
    return dict(_CLAIMS)


def select(ids: list[str]) -> list[Figure]:
    """Figures by id ('all' for every one); 'fig12' also selects nothing else."""
    known = figures()
    if not ids or "all" in ids:
        return list(known.values())
    unknown = [i for i in ids if i not in known]
    if unknown:
        raise KeyError(f"unknown figure id(s): {', '.join(unknown)}; known: {', '.join(known)}")
    return [known[i] for i in known if i in ids]
