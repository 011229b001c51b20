"""scripts/league_machines.py: runs split at a machine change, and one setting's speed on each side."""

import json
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
import league_machines  # noqa: E402

sys.path.remove(str(ROOT / "scripts"))

CHANGE = pd.Timestamp("2026-11-30T04:32:00+0000")


def run(overrides, started, steps, seconds=10.0, status="completed"):
    return {"problem.name": "dipole", "optimizer.name": overrides.split("optimizer=")[1].split()[0], "overrides": overrides,
            "started": started, "steps": steps, "train_time_s": seconds, "status": status, "env.git_revision": "abc"}  # fmt: skip


def test_a_setting_is_its_overrides_but_seed_budget_and_evaluation_interval():
    a = league_machines.setting_key("progress=false threads=1 problem=dipole optimizer=hig seed=0 budget.seconds=47.0 "
                                    "eval_every=0.47 optimizer.lr=1.0")  # fmt: skip
    b = league_machines.setting_key("optimizer.lr=1.0 problem=dipole optimizer=hig seed=3 budget.seconds=600 eval_every=6")
    assert a == b == "optimizer.lr=1.0 optimizer=hig problem=dipole"


def test_the_ratio_is_one_settings_median_rate_after_over_before():
    runs = pd.DataFrame([
        run("optimizer=hig optimizer.lr=1 seed=0", "2026-11-29T20:00:00+0000", 100),
        run("optimizer=hig optimizer.lr=1 seed=1", "2026-11-29T21:00:00+0000", 120),
        run("optimizer=hig optimizer.lr=1 seed=2 budget.seconds=600", "2026-11-30T05:00:00+0000", 2400, seconds=100.0),
        run("optimizer=hig optimizer.lr=2 seed=0", "2026-11-29T20:00:00+0000", 100),  # before only: not compared
        run("optimizer=adam seed=0", "2026-11-29T20:00:00+0000", 500),
        run("optimizer=adam seed=1", "2026-11-30T05:00:00+0000", 9, status="diverged"),  # not completed: not a rate
    ])  # fmt: skip
    rates = league_machines.rates_across_the_change(runs, CHANGE)
    assert list(rates["setting"]) == ["optimizer.lr=1 optimizer=hig"]
    row = rates.iloc[0]
    assert (row["before"], row["after"], row["ratio"]) == (11.0, 24.0, 24.0 / 11.0)
    assert (row["runs before"], row["runs after"]) == (2, 1)


def test_calibrations_are_read_from_the_manifests_once_each_with_their_side(tmp_path):
    early = {"when": "2026-11-29T20:00:00+0000", "matmul_50x256_s": 0.024, "svd_256_f64_s": 0.02}
    late = {"when": "2026-11-30T05:00:00+0000", "matmul_50x256_s": 0.016, "svd_256_f64_s": 0.012}
    (tmp_path / "manifests").mkdir()
    (tmp_path / "manifests" / "a.json").write_text(json.dumps({"calibration": [early, late]}))
    (tmp_path / "manifests" / "b.json").write_text(json.dumps({"calibration": [late]}))  # a sitting's start, copied again
    table = league_machines.calibrations(tmp_path, CHANGE)
    assert list(table["side"]) == ["before", "after"] and list(table["matmul_ms"]) == [24.0, 16.0]


def test_a_root_without_tables_or_a_bad_time_is_one_line_before_any_work(tmp_path, capsys):
    import pytest

    for argv, says in (([str(tmp_path), "--machine-change", "2026-11-30T04:32"], "no league tables there"),
                       ([str(tmp_path), "--machine-change", "yesterday"], "not an ISO time")):  # fmt: skip
        with pytest.raises(SystemExit) as stop:
            league_machines.main(argv)
        assert stop.value.code == 2 and says in capsys.readouterr().err
