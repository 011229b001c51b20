"""How results are shown: each optimizer's name and colour, the Markdown table writer and the
number formatters. The one copy of each, for the figures, the claims, the results tables, a
run's progress lines, the benchmarks and the scripts (it imports only ``higbench.cards``, below
it, and sits in the lowest layer but one, so every one of them may import it).

An optimizer's name and colour are on its card (``card.display``, ``card.color`` in
conf/optimizer/<name>.yaml; ``higbench.cards``): ``OPTIMIZERS`` and its views are read from
the cards when first asked for; a test checks that every shipped optimizer has both.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any, NamedTuple

import numpy as np

from higbench import cards


class Look(NamedTuple):
    """An optimizer as figures and tables show it."""

    name: str  # display name (legends, table columns, claim texts)
    color: str | None  # matplotlib colour of its lines (None: matplotlib's colour cycle)


def optimizer_looks() -> dict[str, Look]:
    """Every shipped optimizer's look, from its card."""
    return {name: Look(card.display, card.color) for name, card in cards.optimizer_cards().items()}


def __getattr__(attr: str) -> Any:
    """``OPTIMIZERS`` (name -> Look) and its views (name -> display name, name -> colour), read
    from the cards when first imported (PEP 562), not when a run imports ``fmt``."""
    looks = optimizer_looks()
    views = {
        "OPTIMIZERS": looks,
        "OPTIMIZER_NAMES": {k: v.name for k, v in looks.items()},
        "COLORS": {k: v.color for k, v in looks.items()},
    }
    if attr not in views:
        raise AttributeError(f"module {__name__!r} has no attribute {attr!r}")
    return views[attr]


def optimizer_name(name: str) -> str:
    """The display name of an optimizer (``lbfgs`` -> ``L-BFGS``); an unknown one as it is."""
    card = cards.optimizer_cards().get(name)
    return card.display if card else name


# -- tables and numbers ----------------------------------------------------------------------


def md_table(header: Iterable[Any], rows: Iterable[Iterable[Any]]) -> list[str]:
    """The lines of a GitHub Markdown table (cells as ``str``; format numbers with ``fmt`` first)."""
    header = list(header)
    lines = ["| " + " | ".join(map(str, r)) + " |" for r in [header, *rows]]
    return [lines[0], "|" + "---|" * len(header), *lines[1:]]


def _missing(x: Any) -> bool:
    return x is None or (isinstance(x, float) and math.isnan(x))


def fmt(x: Any, digits: int = 3, *, exponent: bool = False, grouped: bool = False) -> str:
    """A number in a table or a progress line: None and NaN as ``-``; a float to ``digits``
    significant digits (``0.000123``, ``2.64e+03``), with ``grouped`` 1000 and more as a whole
    number with separators (``12,345``: timings in milliseconds), with ``exponent`` in
    exponent form with ``digits`` decimals (``1.234e-05``); anything else (ints, text) as ``str``."""
    if isinstance(x, np.floating) or (exponent and isinstance(x, int | np.integer) and not isinstance(x, bool)):
        x = float(x)
    if _missing(x):
        return "-"
    if isinstance(x, float):
        if exponent:
            return f"{x:.{digits}e}"
        return f"{x:,.0f}" if grouped and abs(x) >= 1000 else f"{x:.{digits}g}"
    return str(x)


def sci(v: Any, digits: int = 1) -> str:
    """A loss in compact exponent form: 1.234e-05 -> '1.2e-5' (``digits`` decimals)."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return str(v)
    m, x = f"{v:.{digits}e}".split("e")
    return f"{m}e{int(x)}"


def num(v: Any) -> str:
    """A hyper-parameter in a label: 0.0003 -> 3e-4, 1.0 -> 1, 128 -> 128, 0.25 -> 0.25."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return str(v)
    if isinstance(v, int) or (float(v).is_integer() and abs(v) < 1e5):
        return str(int(v))
    if 1e-2 <= abs(v) < 1e3:
        return f"{v:g}"
    return sci(v, 0)


# A run that had less than this share of its cores (its CPU seconds over wall seconds times its
# threads, the run file's env/cpu_share) ran on a busy machine: its update count and its loss
# at the end of the budget are not what an idle machine gives. The one threshold of the
# closing lines of runs, sweeps and figure builds and of the results tables' marker.
BUSY_SHARE = 0.7


def busy_load(load_at_finish: Any) -> float | None:
    """The 1-minute load from a run file's ``load_at_finish`` ("12.1 11.0 9.8"); None without one."""
    try:
        return float(str(load_at_finish).split()[0])
    except (ValueError, IndexError):
        return None


def busy_note(share: Any, load: Any = None, what: str = "this run") -> str | None:
    """``this run had 0.33 of a core (load 12): ...`` when ``share`` is under BUSY_SHARE, else None.

    share: CPU share (per thread) of one run, or the least of several; load: the 1-minute load
    average (a number, or the run file's "1m 5m 15m" text)."""
    try:
        share = float(share)
    except (TypeError, ValueError):
        return None
    if not math.isfinite(share) or share >= BUSY_SHARE:
        return None
    load = load if isinstance(load, int | float) else busy_load(load)
    at = f" (load {load:.0f})" if load is not None and math.isfinite(load) else ""
    return f"{what} had {share:.2f} of a core{at}: its update count and loss are not what an idle machine gives"


def busy_summary(uses: Iterable[tuple[Any, Any]], noun: str = "runs") -> str | None:
    """For work of many runs (a sweep, a figure build): ``2 of 6 runs had under 0.7 of a core
    (least 0.33, load up to 12): ...`` when some did, else None. ``uses``: (cpu_share, load)
    per run, load as a number or a run file's "1m 5m 15m" text; runs without a share are left out."""
    known = []
    for share, load in uses:
        try:
            share = float(share)
        except (TypeError, ValueError):
            continue
        if math.isfinite(share):
            known.append((share, load if isinstance(load, int | float) else busy_load(load)))
    busy = [(s, x) for s, x in known if s < BUSY_SHARE]
    if not busy:
        return None
    loads = [x for _, x in busy if x is not None and math.isfinite(x)]
    at = f", load up to {max(loads):.0f}" if loads else ""
    least = min(s for s, _ in busy)
    return (
        f"{len(busy)} of {len(known)} {noun} had under {BUSY_SHARE} of a core (least {least:.2f}{at}):"
        " their update counts and losses are not what an idle machine gives"
    )
