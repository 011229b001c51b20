"""How results are shown: each optimizer's name and colour, the Markdown table writer and the
number formatters. The one copy of each, for the figures, the claims, the results tables, a
run's progress lines, the benchmarks and the scripts (it imports nothing of higbench and sits
in the lowest layer, so every one of them may import it).

A new optimizer (conf/optimizer/<name>.yaml) gets its row in ``OPTIMIZERS``; a test checks that
every shipped optimizer config has one.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any, NamedTuple

import numpy as np


class Look(NamedTuple):
    """An optimizer as figures and tables show it."""

    name: str  # display name (legends, table columns, claim texts)
    color: str  # matplotlib colour of its lines


OPTIMIZERS: dict[str, Look] = {
    "adam": Look("Adam", "tab:blue"),
    "sgd": Look("SGD", "tab:gray"),
    "adagrad": Look("Adagrad", "tab:purple"),
    "adadelta": Look("Adadelta", "tab:brown"),
    "rmsprop": Look("RMSprop", "tab:orange"),
    "gn": Look("GN", "tab:red"),
    "hig": Look("HIG", "tab:green"),
    "lbfgs": Look("L-BFGS", "tab:pink"),
    "lm": Look("Levenberg-Marquardt", "tab:olive"),
    "adamw": Look("AdamW", "tab:cyan"),
    "muon": Look("Muon", "navy"),
    "soap": Look("SOAP", "darkgoldenrod"),
    "shampoo": Look("Shampoo", "teal"),
    "sip": Look("SIP", "crimson"),
}
# Views of the one table (name -> display name, name -> colour), for code that reads one of them.
OPTIMIZER_NAMES: dict[str, str] = {k: v.name for k, v in OPTIMIZERS.items()}
COLORS: dict[str, str] = {k: v.color for k, v in OPTIMIZERS.items()}


def optimizer_name(name: str) -> str:
    """The display name of an optimizer (``lbfgs`` -> ``L-BFGS``); an unknown one as it is."""
    return OPTIMIZER_NAMES.get(name, name)


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
