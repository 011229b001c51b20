"""scripts/time_to_loss.py: thresholds read from a run's curves, table written (no training here)."""

import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
import time_to_loss  # noqa: E402

sys.path.remove(str(ROOT / "scripts"))


def test_time_to_first_evaluation_at_or_below():
    curves = pd.DataFrame({"wall_time": [0.0, 5.0, 10.0, 15.0], "test_loss": [1.0, 2e-3, 1e-3, 5e-6]})
    assert time_to_loss.time_to(curves, 1e-3) == 10.0  # at or below
    assert time_to_loss.time_to(curves, 1e-5) == 15.0
    assert time_to_loss.time_to(curves, 1e-7) is None  # not reached


def test_table_marks_unreached_thresholds(tmp_path):
    row = {"problem": "oscillator", "optimizer": "hig", "batch_size": 128, "budget_s": 10.0, "status": "completed"}
    row |= {"updates": 7, "final_test_loss": 2e-4}
    row |= {f"t_{t:.0e}": (3.0 if t >= 1e-3 else None) for t in time_to_loss.THRESHOLDS}
    time_to_loss.write([row], tmp_path, "note")
    text = (tmp_path / "time_to_loss.md").read_text()
    assert "| oscillator | hig | 128 | 10 | completed | 7 | 3 | - | - | - | - | 0.0002 |" in text
    assert pd.read_csv(tmp_path / "time_to_loss.csv").loc[0, "t_1e-03"] == 3.0


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
