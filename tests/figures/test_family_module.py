"""A new figure with its claim is one file: a module beside the paper's families in
``higbench/paper/`` that declares ``FIGURES`` is found by the registry's scan, and its figure and
claim reach every list the machinery keeps (``--list``, a build's selection and jobs, REPORT.md).
No training: the module is written to a scratch folder added to the package's search path, so
the checkout is not touched."""

from __future__ import annotations

import sys
import textwrap

import pytest

import higbench.paper
from higbench.claims import rules
from higbench.figures import registry
from higbench.figures.spec import Preset, expand

FAMILY = '''
"""Figure 14 (a scratch family): Adam on the toy problem, and one claim on it."""

from higbench.claims.rules import claim, final, require
from higbench.figures.plot import Curves, Series
from higbench.figures.spec import Budget, Figure, Sweep

FIGURES = [
    Figure(
        "fig14",
        "Toy problem: Adam alone",
        [Sweep("adam", {"problem": "toy", "optimizer": "adam"}, Budget(seconds={"paper": 20}), seeds=[0, 1, 2])],
        panels=[Curves("Adam", [Series("adam")])],
    )
]


@claim("new-1", "fig14", "below its start")
def adam_falls(datas):
    """Toy: Adam lowers the loss. Rule: the final loss below the initial one"""
    runs = datas["fig14"].runs("adam")
    require(runs, what="fig14 Adam")
    return "measured", final(runs) < 1.0, True
'''


@pytest.fixture
def scratch_family(tmp_path, monkeypatch):
    """``higbench/paper/scratch.py`` holding FAMILY, as if it were one more file of the package."""
    (tmp_path / "scratch.py").write_text(textwrap.dedent(FAMILY))
    monkeypatch.setattr(higbench.paper, "__path__", [*higbench.paper.__path__, str(tmp_path)])
    monkeypatch.setattr(rules, "CLAIMS", list(rules.CLAIMS))  # the scratch claim leaves with the test
    registry.families.cache_clear()
    yield tmp_path
    sys.modules.pop("higbench.paper.scratch", None)
    registry.families.cache_clear()


def test_a_family_module_is_one_file_the_registry_finds(scratch_family, tmp_path, capsys):
    from higbench.figures.__main__ import main
    from higbench.figures.report import write_report

    figures, claims = registry.figures(), registry.claims()
    assert "fig14" in figures and list(figures).index("fig14") == list(figures).index("fig13") + 1  # the paper's order
    before = list(claims)[list(claims).index("new-1") - 1]  # its family's place: after the ablation's (fig13)
    assert claims[before].measure.__module__ == "higbench.paper.ablation" and claims["new-1"].figures == ("fig14",)
    assert "higbench.paper.scratch" in {m.__name__ for m in registry.families()}
    assert [f.id for f in registry.select(["fig14"])] == ["fig14"]
    jobs = expand(figures["fig14"], Preset("quick", str(tmp_path)))
    assert [j.overrides["budget.seconds"] for j in jobs] == [20.0] * 3  # quick falls back to the paper's budget
    assert main(["--list"]) == 0 and "fig14    figure Toy problem: Adam alone" in capsys.readouterr().out
    out = tmp_path / "out"
    out.mkdir()
    report = write_report(out, list(figures)).read_text()
    assert "new-1: Toy: Adam lowers the loss" in report and "| fig14 | - | - | not drawn |" in report


def test_the_family_modules_are_the_registrys_and_only_theirs(scratch_family):
    """Every figure of the registry is declared by one family, and every family's figures are in it."""
    declared = [f.id for m in registry.families() for f in m.FIGURES]
    assert sorted(declared) == sorted(registry.figures())
    registry.families.cache_clear()
    sys.modules.pop("higbench.paper.scratch", None)
    higbench.paper.__path__ = higbench.paper.__path__[:-1]  # the scratch file gone: so is its figure
    assert "fig14" not in registry.figures() and "new-1" not in registry.claims()
