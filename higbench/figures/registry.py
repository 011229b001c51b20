"""The one registry of the paper's figures and tables: each family module (toy, oscillator,
poisson, dipole, ablation, tables) declares ``FIGURES``. The claims the report judges on them
are ``higbench.claims.paper``'s (``claims()`` here lists them)."""

from __future__ import annotations

import importlib
import re
from functools import cache

from higbench.claims.paper import claims  # noqa: F401 - the claims on these figures
from higbench.claims.rules import CAUSES, by_id  # noqa: F401 - CAUSES: the registry's vocabulary
from higbench.figures.spec import Figure

FAMILIES = ("toy", "oscillator", "poisson", "dipole", "ablation", "tables")


def _order(fid: str) -> tuple:
    m = re.fullmatch(r"(fig|table)(\d+)([a-z]?)", fid)
    return (0 if m.group(1) == "fig" else 1, int(m.group(2)), m.group(3)) if m else (2, 0, fid)


@cache
def _families() -> list:
    return [importlib.import_module(f"higbench.figures.{name}") for name in FAMILIES]


def figures() -> dict[str, Figure]:
    """Every figure and table, in the paper's order."""
    known = by_id([f for m in _families() for f in m.FIGURES], "figure")
    return {k: known[k] for k in sorted(known, key=_order)}


def select(ids: list[str]) -> list[Figure]:
    """Figures by id ('all' for every one)."""
    known = figures()
    if not ids or "all" in ids:
        return list(known.values())
    unknown = [i for i in ids if i not in known]
    if unknown:
        raise KeyError(f"unknown figure id(s): {', '.join(unknown)}; known: {', '.join(known)}")
    return [known[i] for i in known if i in ids]
