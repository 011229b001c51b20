"""A fifth problem is one module plus one YAML file, and nothing under higbench/ changes.

The problem is the recipe's (docs/recipe.md): examples/heat/ (``heat_problem.py`` and
``conf/problem/heat.yaml``), outside the package.
The test suite registers it the way a user would: Hydra's search path for the YAML
(``hydra.searchpath``) and the module on the import path for its ``_target_`` (what
``PYTHONPATH`` does). It then goes through the console entry point (``higbench.cli.main``, in
this process): it trains with HIG and with Adam, and a bad value of one of its own keys is
refused like those of the built-in problems.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from higbench.results import load_run

HERE = Path(__file__).resolve().parents[1] / "examples" / "heat"


@pytest.fixture
def heat(higbench, monkeypatch):
    """``higbench problem=heat ...`` (the tiny run) with the test-only problem registered, from a fresh tmp dir."""
    monkeypatch.syspath_prepend(str(HERE))  # as PYTHONPATH=examples/heat

    def run(*args: str):
        return higbench(f"hydra.searchpath=[file://{HERE / 'conf'}]", "problem=heat", *args)

    yield run
    sys.modules.pop("heat_problem", None)  # imported by the runs: gone with the path, as with a process


def test_it_is_two_files_outside_higbench():
    assert sorted(str(p.relative_to(HERE)) for p in HERE.rglob("*") if p.is_file() and "__pycache__" not in p.parts) == [
        "conf/problem/heat.yaml",
        "heat_problem.py",
    ]
    import higbench

    package = Path(higbench.__file__).parent
    assert not any("heat" in p.name for p in package.rglob("*")), "the test problem leaked into higbench/"


@pytest.mark.parametrize("optimizer", ["hig", "adam", "sip"])  # sip: through its regularised inverse simulator
def test_the_custom_problem_trains_through_the_cli(heat, tmp_path, optimizer):
    code, out, err = heat(f"optimizer={optimizer}")
    assert code == 0, err
    # heat.yaml declares its targets (before it did not, and every job said "the problem sets no targets")
    assert "time to test loss 1e-02: " in out + err and "sets no targets" not in out + err
    (path,) = sorted((tmp_path / "outputs").rglob("run.h5"))
    meta, curves = load_run(path)
    assert meta["status"] == "completed" and meta["problem"] == "heat" and meta["optimizer"] == optimizer
    assert meta["config"]["problem"]["alpha"] == 0.2 and meta["config"]["batch_size"] == 16  # from heat.yaml
    assert list(curves["step"]) == [0, 1, 2, 3] and curves["test_loss"].notna().all()


@pytest.mark.parametrize(
    "override,message",
    [
        ("problem.alpha=0.7", "problem.alpha=0.7: must be a number in (0, 0.5]"),
        ("problem.points=two", "problem.points=two: Value 'two' of type 'str' could not be converted to Integer"),
        ("problem.hidden=[16,0]", "problem.hidden=[16,0]: each item must be an integer >= 1"),
        (
            "problem.gamma=1",
            "problem.gamma=1: unknown key; valid keys under problem: _target_, alpha, data_seed, held_out, hidden,",
        ),
        ("batch_size=512", "batch_size=512: must not exceed problem.train_size=256"),
    ],
)
def test_its_keys_are_validated_like_the_built_in_ones(heat, tmp_path, override, message):
    code, _, err = heat("optimizer=adam", override)
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"higbench: error: {message}"), err
    assert sorted(tmp_path.rglob("*")) == [], "a refused config wrote something"


def test_a_base_config_key_its_yaml_does_not_list_can_be_set(heat, tmp_path):
    """docs/configuration.md: every problem's base config holds ``init``; heat.yaml does not list it."""
    code, _, err = heat("optimizer=adam", "problem.init=torch")
    assert code == 0, err
    (path,) = sorted((tmp_path / "outputs").rglob("run.h5"))
    assert load_run(path)[0]["config"]["problem"]["init"] == "torch"


def test_a_multirun_checks_its_jobs_before_the_sweep_starts(heat, tmp_path):
    code, _, err = heat("-m", "optimizer=adam", "problem.alpha=0.1,0.9")
    assert code == 2 and "problem.alpha=0.9: must be a number in (0, 0.5]" in err, err
    assert sorted(tmp_path.rglob("*")) == []


def test_a_problem_module_off_the_path_names_pythonpath():
    """The recipe's trap: `--cfg job` finds the YAML, the run cannot import the module."""
    import pytest

    from higbench.config import ConfigError, problem_class

    with pytest.raises(ConfigError, match="'my_heat_problem' on PYTHONPATH"):
        problem_class({"_target_": "my_heat_problem.Heat"})
