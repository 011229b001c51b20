"""One card per optimizer and per problem (higbench.cards): shipping an optimizer is its YAML,
shipping a problem is its module and its YAML, and everything that lists them reads them.

Each shipping test works on a scratch copy of conf/ (``cards.conf_dir`` pointed at it, Hydra
given it through ``hydra.searchpath``): what a new file in the checkout's conf/ would do,
without touching it.
"""

from __future__ import annotations

import importlib.util
import itertools
import shutil
import textwrap
from pathlib import Path

import pytest
from matplotlib.colors import is_color_like

from higbench import cards, display
from higbench.config import optimizer_kwargs
from higbench.problems import base
from higbench.results.index import config_id, setting_config

ROOT = Path(__file__).resolve().parents[1]
_names = itertools.count()

NADAM = """\
    # NAdam (torch.optim.NAdam): Adam with Nesterov momentum. torch's defaults.
    card:
      display: NAdam
      color: tab:olive
      league: {league}
    name: nadam
    _target_: torch.optim.NAdam
    lr: 2.0e-3
    betas: [0.9, 0.999]
    eps: 1.0e-8
"""


@pytest.fixture
def scratch(tmp_path, monkeypatch):
    """A copy of conf/ that ``higbench.cards`` reads instead of the checkout's."""
    conf = tmp_path / "scratch" / "conf"
    shutil.copytree(cards.conf_dir(), conf)
    monkeypatch.setattr(cards, "conf_dir", lambda: conf)
    return conf


def league_without_search_space() -> list[str]:
    """League optimizers whose search space (conf/search/<name>.yaml) is missing."""
    return [name for name in cards.league_optimizers() if not (cards.conf_dir() / "search" / f"{name}.yaml").is_file()]


def test_every_league_optimizer_has_a_search_space():
    assert cards.league_optimizers(), "no card says the league runs it"
    assert league_without_search_space() == []


def test_the_league_runs_the_optimizers_whose_cards_say_so():
    from higbench.league import driver

    assert set(driver.DEFAULT_OPTIMIZERS) == set(cards.league_optimizers())


def test_every_shipped_optimizer_has_a_card():
    for name, card in cards.optimizer_cards().items():
        assert card.name == name and card.display and is_color_like(card.color) and card.help, card


@pytest.mark.parametrize("name", cards.problem_configs())
def test_every_shipped_problem_config_has_its_help_line(name):
    assert cards.problem_help().count(f"\n  {name} ") + cards.problem_help().startswith(f"  {name} ") == 1
    assert f"  {name:<13}\n" not in cards.problem_help() + "\n"  # not an empty line


def test_the_card_is_no_constructor_argument_and_no_part_of_a_run():
    node = {"name": "adam", "_target_": "torch.optim.Adam", "lr": 1e-3, "card": {"display": "Adam"}}
    assert optimizer_kwargs(node) == {"lr": 1e-3}
    run = {"seed": 0, "optimizer": node, "problem": {"name": "toy", "card": {"help": "a toy"}}}
    before_cards = {"seed": 0, "optimizer": optimizer_kwargs(node) | {"name": "adam", "_target_": "torch.optim.Adam"}}
    before_cards["problem"] = {"name": "toy"}  # a run file from before the cards
    assert config_id(run) == config_id(before_cards) and setting_config(run) == setting_config(before_cards)


def test_a_misspelt_card_key_is_refused(scratch):
    (scratch / "optimizer" / "bad.yaml").write_text("card: {colour: red}\nname: bad\n_target_: torch.optim.SGD\n")
    with pytest.raises(ValueError, match="colour"):
        cards.optimizer_cards()


def test_shipping_an_optimizer_is_one_yaml_file(scratch, higbench, tmp_path):
    before = set(p.relative_to(scratch) for p in scratch.rglob("*"))
    (scratch / "optimizer" / "nadam.yaml").write_text(textwrap.dedent(NADAM.format(league="false")))
    assert {p.relative_to(scratch) for p in scratch.rglob("*")} - before == {Path("optimizer/nadam.yaml")}

    # the help lists it, the display table shows it, the shared cases run over it
    code, out, err = higbench("--help", tiny=False)
    assert code == 0, err
    assert "  nadam      torch.optim.NAdam\n" in out
    assert display.optimizer_name("nadam") == "NAdam" and display.COLORS["nadam"] == "tab:olive"
    assert display.OPTIMIZERS["nadam"] == display.Look("NAdam", "tab:olive")
    assert "nadam" in load_cases().OPTIMIZERS
    assert "nadam" not in cards.league_optimizers()  # its card says the league does not run it

    # and it trains (Hydra finds it in the scratch copy)
    code, _, err = higbench(f"hydra.searchpath=[file://{scratch}]", "problem=toy", "optimizer=nadam", "threads=1")
    assert code == 0, err
    (run,) = (tmp_path / "outputs").rglob("run.h5")
    from higbench.results import load_run

    meta, _ = load_run(run)
    assert meta["status"] == "completed" and meta["optimizer"] == "nadam"


def test_a_league_optimizer_needs_its_search_space(scratch):
    (scratch / "optimizer" / "nadam.yaml").write_text(textwrap.dedent(NADAM.format(league="true")))
    assert "nadam" in cards.league_optimizers()
    assert league_without_search_space() == ["nadam"]  # the check above fails until it has one
    (scratch / "search" / "nadam.yaml").write_text("space:\n  optimizer.lr: {low: 1.0e-4, high: 1.0e-1}\n")
    assert league_without_search_space() == []


SQUARE = """\
    from dataclasses import dataclass

    import torch

    from higbench.problems.base import Batch, FixedDataConfig, FixedDataProblem
    from higbench.problems.networks import mlp


    class Square(FixedDataProblem):
        \"\"\"Fit u so that u**2 matches the target.\"\"\"

        @dataclass
        class Config(FixedDataConfig):
            pass

        def __init__(self, cfg, dtype, device, seed):
            super().__init__(cfg, dtype, device, seed)
            self.sample_datasets()

        def make_model(self):
            return mlp([1, 4, 1], "tanh")

        def physics(self, inputs, u):
            return u**2

        def loss(self, y, targets):
            return ((y - targets) ** 2).sum(-1)

        def _sample(self, n, gen):
            z = torch.rand(n, 1, generator=gen, dtype=self.dtype).to(self.device)
            return Batch(z, z, z)
"""


def load_cases():
    """tests/cases.py read afresh (its lists are taken when it is imported)."""
    spec = importlib.util.spec_from_file_location(f"cases_scratch_{next(_names)}", Path(__file__).parent / "cases.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_shipping_a_problem_is_a_module_and_a_yaml_file(scratch, higbench, tmp_path, monkeypatch):
    monkeypatch.setattr(base, "_REGISTRY", dict(base._REGISTRY))  # the new class leaves with the test
    name = f"square{next(_names)}"
    py = tmp_path / "py"
    py.mkdir()
    (py / f"{name}_problem.py").write_text(textwrap.dedent(SQUARE))
    monkeypatch.syspath_prepend(str(py))
    (scratch / "problem" / f"{name}.yaml").write_text(
        textwrap.dedent(f"""\
            # @package _global_
            problem:
              _target_: {name}_problem.Square
              name: {name}
              card: {{help: fit u so that u squared matches a target}}
              train_size: 64
              test_size: 16
              data_seed: 0
            batch_size: 8
            """)
    )
    assert name not in base._REGISTRY
    assert base.registry()[name].__module__ == f"{name}_problem"
    cases = load_cases()
    assert name in cases.PROBLEMS and name in cases.PROBLEM_CONFIGS and name in cases.FIXED_DATA_PROBLEMS

    code, out, err = higbench("--help", tiny=False)
    assert code == 0, err
    assert f"  {name:<13}fit u so that u squared matches a target\n" in out
    code, _, err = higbench(f"hydra.searchpath=[file://{scratch}]", f"problem={name}", "optimizer=adam", "threads=1")
    assert code == 0, err


def test_an_installed_package_ships_its_problem_through_the_entry_point_group(tmp_path, monkeypatch):
    import importlib.metadata

    monkeypatch.setattr(base, "_REGISTRY", dict(base._REGISTRY))
    name = f"installed{next(_names)}"
    (tmp_path / f"{name}_pkg.py").write_text(textwrap.dedent(SQUARE))
    monkeypatch.syspath_prepend(str(tmp_path))
    entry = importlib.metadata.EntryPoint(name, f"{name}_pkg:Square", base.ENTRY_POINT_GROUP)
    seen = []

    def entry_points(group):
        seen.append(group)
        return [entry] if group == base.ENTRY_POINT_GROUP else []

    monkeypatch.setattr(importlib.metadata, "entry_points", entry_points)
    problems = base.registry()
    assert seen == [base.ENTRY_POINT_GROUP] and problems[name].__module__ == f"{name}_pkg" and problems[name].name == name
