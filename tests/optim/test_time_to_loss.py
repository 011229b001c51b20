"""scripts/time_to_loss.py: the problem's targets read from a run's curves, table written (no training here)."""

import sys
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
import time_to_loss  # noqa: E402

sys.path.remove(str(ROOT / "scripts"))


def test_table_marks_unreached_targets_and_leaves_other_problems_targets_blank(tmp_path):
    row = {"problem": "oscillator", "optimizer": "hig", "batch_size": 128, "budget_s": 10.0, "status": "completed"}
    row |= {"updates": 7, "final_test_loss": 2e-4, "t_1e-02": 3.0, "t_1e-03": None}
    other = {**row, "problem": "poisson", "t_1e-02": None, "t_1e-03": None, "t_1e+01": 1.5}
    other.pop("t_1e-02"), other.pop("t_1e-03")
    time_to_loss.write([row, other], tmp_path, "note")
    text = (tmp_path / "time_to_loss.md").read_text()
    assert "| problem | optimizer | b | budget (s) | status | updates | to 1e+01 (s) | to 1e-02 (s) | to 1e-03 (s) |" in text
    assert "| oscillator | hig | 128 | 10 | completed | 7 |  | 3 | - | 0.0002 |" in text
    assert "| poisson | hig | 128 | 10 | completed | 7 | 1.5 |  |  | 0.0002 |" in text
    assert pd.read_csv(tmp_path / "time_to_loss.csv").loc[0, "t_1e-02"] == 3.0


def test_runs_are_jobs_of_the_one_launcher():
    (job,) = time_to_loss.jobs_of(["oscillator:gn:seed=7,problem.coupling=2"], 60.0, 2.0, ["threads=auto"])
    assert job.seed == 7 and job.overrides["problem.coupling"] == 2  # values as Hydra reads them
    assert job.override_list()[:4] == ["problem=oscillator", "optimizer=gn", "budget.seconds=60.0", "eval_every=2.0"]


def test_run_spec_carries_its_own_overrides():
    assert time_to_loss.parse_spec("oscillator:gn:seed=7,batch_size=64") == ("oscillator", "gn", ["seed=7", "batch_size=64"])
    assert time_to_loss.parse_spec("toy:hig") == ("toy", "hig", [])
    for bad in ("oscillator", ":hig", "oscillator:"):
        try:
            time_to_loss.parse_spec(bad)
        except ValueError as err:
            assert bad in str(err)
        else:
            raise AssertionError(f"{bad!r} accepted")


def test_levels_go_below_the_targets_as_far_as_a_run_went():
    targets = (1e-2, 1e-3, 1e-4, 3e-5)  # the oscillator's
    assert time_to_loss.levels(targets) == list(targets)
    assert time_to_loss.levels(targets, 1e-3) == list(targets)  # no run below the targets: nothing added
    assert time_to_loss.levels(targets, 6.1e-7) == pytest.approx([*targets, 1e-5, 1e-6])
    assert time_to_loss.levels(targets, 1e-6) == pytest.approx([*targets, 1e-5, 1e-6])  # reached exactly


def test_a_run_spec_keeps_list_values_whole():
    spec = "toy:hig:problem.hidden=[64,64],seed=7"
    assert time_to_loss.parse_spec(spec) == ("toy", "hig", ["problem.hidden=[64,64]", "seed=7"])
