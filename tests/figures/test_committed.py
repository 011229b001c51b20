"""A claim measured again from the committed results (``higbench.figures.committed``) gives what its
measurement gave on the run files: the plotted data are the runs' evaluations. No training."""

import json
from pathlib import Path

import pytest

from higbench.figures import registry
from higbench.figures.committed import CommittedFigure, parse_overrides, remeasure
from higbench.figures.report import sidecars

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results"
# Claims measured from the run files whose measurement this revision kept: the same text and verdict again.
UNCHANGED = ("toy-1", "toy-2", "osc-1", "osc-6", "poi-4", "poi-4a", "dip-5", "dip-6", "cnn-1", "dip-7", "dip-8", "cnn-2")
UNCHANGED += ("abl-1", "abl-4")


@pytest.mark.parametrize("cid", UNCHANGED)
def test_remeasured_from_the_plotted_data_as_from_the_run_files(cid):
    stored = {c["id"]: c for info in sidecars(RESULTS).values() for c in info.get("claims", [])}[cid]
    row = remeasure(RESULTS, registry.claims()[cid])
    assert row["measured"] == stored["measured"] and row["rule_verdict"] == stored["rule_verdict"], row["why"]


def test_overrides_read_as_hydra_reads_them():
    cfg = parse_overrides(["optimizer=hig", "optimizer.tau=1e-06", "batch_size=64", "problem.hidden=[64,128,64]"])
    assert cfg == {"optimizer.name": "hig", "optimizer.tau": 1e-6, "batch_size": 64, "problem.hidden": [64, 128, 64]}


def test_a_continued_run_finds_its_parent_and_starts_its_own_clock():
    fig7 = CommittedFigure.load(RESULTS, "fig7")
    after = fig7.runs("adam_after_hig_authors")[0]
    parent = [r for r in fig7.runs("hig_cont_authors") if r.path == after.cfg("init_from")]
    assert len(parent) == 1 and parent[0].cfg("optimizer.lr") == 0.02
    fig3c = CommittedFigure.load(RESULTS, "fig3c")
    assert 0.0 <= fig3c.runs("hig_cont")[0].curves["wall_time"].iloc[0] < 1.0  # drawn after its parent's 3,000 s


def test_update_counts_spread_over_the_run_where_only_time_is_plotted():
    info = json.loads((RESULTS / "fig2c.json").read_text())
    path = next(r["path"] for r in info["runs"] if r["sweep"] == "hig")
    run = next(r for r in CommittedFigure.load(RESULTS, "fig2c", {path: 1000}).runs("hig") if r.path == path)
    assert run.curves["step"].iloc[-1] == pytest.approx(1000) and run.curves["step"].is_monotonic_increasing
    assert "step" not in next(r for r in CommittedFigure.load(RESULTS, "fig2c").runs("hig") if r.path == path).curves


@pytest.mark.parametrize("fid", ["fig9", "fig13", "fig3c"])
def test_a_redrawn_figure_plots_the_points_it_plotted(fid, tmp_path):
    """Drawn again from its committed data by this revision's plotting code, a figure records the same points."""
    import numpy as np
    import pandas as pd

    from higbench.figures.committed import redraw

    for name in (f"{fid}.json", f"{fid}.csv"):
        (tmp_path / name).write_text((RESULTS / name).read_text())
    redraw(tmp_path, fid)
    before, after = pd.read_csv(RESULTS / f"{fid}.csv"), pd.read_csv(tmp_path / f"{fid}.csv")
    assert before[["panel", "series", "run"]].equals(after[["panel", "series", "run"]])
    assert np.allclose(before[["x", "y"]], after[["x", "y"]], rtol=1e-12, equal_nan=True)
    assert (tmp_path / f"{fid}.png").is_file()
    info = json.loads((tmp_path / f"{fid}.json").read_text())
    assert info["made"]["redrawn"] and info["claims"] == json.loads((RESULTS / f"{fid}.json").read_text())["claims"]
