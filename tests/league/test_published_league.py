"""The published CPU league (docs/results/league/cpu/) re-scores from its committed tables alone,
byte for byte: what the docs quote is what the tables say."""

from __future__ import annotations

import shutil
from pathlib import Path

from higbench.league import driver

PUBLISHED = Path(__file__).resolve().parents[2] / "docs" / "results" / "league" / "cpu"


def test_the_published_league_re_scores_byte_for_byte_from_its_tables(tmp_path):
    copy = tmp_path / "cpu"
    shutil.copytree(PUBLISHED, copy)
    (copy / "league.txt").unlink()
    driver.report([copy], copy, {"protocol": {}}, [1000, 1001])
    assert (copy / "league.txt").read_bytes() == (PUBLISHED / "league.txt").read_bytes()


def test_the_published_targets_come_from_five_reruns_of_each_reference():
    runs, curves = driver.tables.read([PUBLISHED])
    found = driver.found_targets(runs, curves)
    assert len(found) and (found["reruns"] == 5).all()
    assert all(set(m) == {"adam", "adamw"} for m in found["medians"])
    assert (found["budget_s"] > 0).all() and (found["target"] > 0).all()
