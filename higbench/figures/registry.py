"""The one registry of the paper's figures, tables and claims: every module of ``higbench/paper/``
that declares ``FIGURES`` is a family (its settings, figures and claims side by side), found by
scanning the package, so a new family is one file there and no list names it.

The machinery never imports a family: the scan loads them by name (``PACKAGE``) when a figure
or a claim is asked for, as the import layers require (``higbench.paper`` sits above
``higbench.figures``). A family's claims are the ``@claim`` declarations of its module.
"""

from __future__ import annotations

import importlib
import pkgutil
import re
from functools import cache
from types import ModuleType

from higbench.claims import rules
from higbench.claims.rules import CAUSES, Claim, by_id  # noqa: F401 - CAUSES: the registry's vocabulary
from higbench.figures.spec import Figure

PACKAGE = "higbench.paper"


def _order(fid: str) -> tuple:
    """The paper's order: figures by number, then tables, then figures of this project (``ref_oscillator``)."""
    m = re.fullmatch(r"(fig|table)(\d+)([a-z]?)", fid)
    return (0 if m.group(1) == "fig" else 1, int(m.group(2)), m.group(3)) if m else (2, 0, fid)


@cache
def families() -> list[ModuleType]:
    """The family modules of ``PACKAGE``, in the paper's order of their first figure (toy,
    oscillator, Poisson, dipole, ablation, tables): the report's order of their claims."""
    package = importlib.import_module(PACKAGE)
    modules = [importlib.import_module(f"{PACKAGE}.{m.name}") for m in pkgutil.iter_modules(package.__path__)]
    found = [m for m in modules if getattr(m, "FIGURES", None)]
    return sorted(found, key=lambda m: min(_order(f.id) for f in m.FIGURES))


def figures() -> dict[str, Figure]:
    """Every figure and table, in the paper's order."""
    known = by_id([f for m in families() for f in m.FIGURES], "figure")
    return {k: known[k] for k in sorted(known, key=_order)}


def claims() -> dict[str, Claim]:
    """Every claim, in the report's order: family by family, each in its declaration order."""
    return by_id([c for m in families() for c in rules.CLAIMS if c.measure.__module__ == m.__name__], "claim")


def untested() -> list[tuple[str, str]]:
    """The paper's statements no claim tests, each with the reason (``higbench.paper.UNTESTED``)."""
    return importlib.import_module(PACKAGE).UNTESTED


def select(ids: list[str]) -> list[Figure]:
    """Figures by id ('all' for every one)."""
    known = figures()
    if not ids or "all" in ids:
        return list(known.values())
    unknown = [i for i in ids if i not in known]
    if unknown:
        raise KeyError(f"unknown figure id(s): {', '.join(unknown)}; known: {', '.join(known)}")
    return [known[i] for i in known if i in ids]
