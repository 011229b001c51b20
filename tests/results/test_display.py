"""One display table (every shipped optimizer's name and colour), one Markdown table writer and
one number formatter (higbench.display), and no copies of them elsewhere."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import is_color_like, to_rgba

from higbench import display

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("name", sorted(p.stem for p in (ROOT / "conf" / "optimizer").glob("*.yaml")))
def test_every_shipped_optimizer_has_a_name_and_a_colour(name):
    look = display.OPTIMIZERS[name]
    assert look.name and is_color_like(look.color)
    assert display.optimizer_name(name) == look.name == display.OPTIMIZER_NAMES[name]
    assert display.COLORS[name] == look.color


def test_names_and_colours_tell_the_optimizers_apart():
    looks = display.OPTIMIZERS.values()
    assert len({lk.name for lk in looks}) == len(looks)
    assert len({to_rgba(lk.color) for lk in looks}) == len(looks)
    assert display.optimizer_name("my_own") == "my_own"  # an out-of-tree optimizer as it is named


def test_markdown_table():
    assert display.md_table(["a", "b"], [[1, "x"], ("2", None)]) == ["| a | b |", "|---|---|", "| 1 | x |", "| 2 | None |"]
    assert display.md_table(["only"], []) == ["| only |", "|---|"]


@pytest.mark.parametrize(
    "value,kwargs,text",
    [
        (None, {}, "-"),
        (math.nan, {}, "-"),
        (np.float32("nan"), {"exponent": True}, "-"),
        (0.000123456, {}, "0.000123"),
        (2640.4, {}, "2.64e+03"),
        (12345.6, {"grouped": True}, "12,346"),  # 1000 and more: whole, with separators
        (0.5, {"digits": 2}, "0.5"),
        (7, {}, "7"),
        ("hig", {}, "hig"),
        (1.23456e-5, {"exponent": True}, "1.235e-05"),
        (np.float32(0.5), {"digits": 2, "exponent": True}, "5.00e-01"),
        (1, {"exponent": True}, "1.000e+00"),
    ],
)
def test_one_number_formatter(value, kwargs, text):
    assert display.fmt(value, **kwargs) == text


def test_compact_numbers_for_losses_and_labels():
    assert display.sci(1.234e-05) == "1.2e-5" and display.sci(math.inf) == "inf" and display.sci(None) == "None"
    assert [display.num(v) for v in (3e-4, 1.0, 128, 0.25, True, 1e-10)] == ["3e-4", "1", "128", "0.25", "True", "1e-10"]


# A copy of the table, the writer or a formatter anywhere but higbench/display.py
COPIES = re.compile(
    r"^\s*(COLORS|OPTIMIZER_NAMES|OPTIMIZERS)\s*[:=][^=\n]*\{"  # a dict of names or colours
    r"|---\||\| --- \|"  # a Markdown table's separator row
    r"|^def (fmt|_fmt|num|sci|_num|md_table|markdown_table)\(",  # a number formatter or table writer
    re.M,
)


def test_no_other_module_holds_the_display_table_a_table_writer_or_a_formatter():
    found = []
    for path in sorted([*(ROOT / "higbench").rglob("*.py"), *(ROOT / "scripts").glob("*.py")]):
        if path == ROOT / "higbench" / "display.py":
            continue
        for m in COPIES.finditer(path.read_text()):
            found.append(f"{path.relative_to(ROOT)}: {m.group(0).strip()}")
    assert not found, found
