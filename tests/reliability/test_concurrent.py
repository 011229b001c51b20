"""Concurrent runs into one outputs root, a diverging one among them, and two runs racing
for the same run directory: distinct files, nothing overwritten, the index sees it all."""

from __future__ import annotations

import math

import pytest
from rel_helpers import FAST, start_cli

from higbench.runfile.reader import load_run

pytestmark = pytest.mark.process  # concurrent CLI processes racing for a directory

SHORT = ["budget.seconds=1", "eval_every=0.25", "checkpoint_every=0.5", *FAST]


def test_concurrent_runs_into_one_root(tmp_path):
    same = tmp_path / "outputs" / "same"
    procs = {
        # a run that diverges, in the default run directory
        # (outputs/runs/<date>/<time with microseconds>_<problem>_<optimizer>): exit code 0
        "diverging": start_cli([*SHORT, "optimizer=sgd", "optimizer.lr=1e12"], cwd=tmp_path),
        # two runs racing for one directory of the same root: one wins, the other refuses
        "race1": start_cli([*SHORT, "optimizer=hig", f"hydra.run.dir={same}"], cwd=tmp_path),
        "race2": start_cli([*SHORT, "optimizer=adam", f"hydra.run.dir={same}"], cwd=tmp_path),
    }
    try:
        results = {name: (p.wait(timeout=150), *p.communicate()) for name, p in procs.items()}
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.kill()

    assert results["diverging"][0] == 0, results["diverging"]
    assert results["diverging"][1].startswith("diverged:"), results["diverging"]
    codes = sorted(results[n][0] for n in ("race1", "race2"))
    assert codes == [0, 2], results
    loser = next(results[n] for n in ("race1", "race2") if results[n][0] == 2)
    assert "hydra.run.dir=" in loser[2] and ("refusing to overwrite" in loser[2] or "already exists" in loser[2]), loser[2]

    files = sorted((tmp_path / "outputs").rglob("run.h5"))
    assert len(files) == 2 and len({f.parent for f in files}) == 2, files
    statuses = {}
    for f in files:
        meta, curves = load_run(f)
        statuses[f] = meta["status"]
        assert len(curves) >= 2 and curves["step"].is_unique
        assert not f.with_name("run.h5.ckpt").exists()
    assert sorted(statuses.values()) == ["completed", "diverged"]
    assert statuses[same / "run.h5"] == "completed"
    winner = next(n for n in ("race1", "race2") if results[n][0] == 0)
    assert load_run(same / "run.h5")[0]["optimizer"] == {"race1": "hig", "race2": "adam"}[winner], (
        "the winner's file was overwritten"
    )
    meta, curves = load_run(next(f for f, s in statuses.items() if s == "diverged"))
    assert "non-finite" in meta["status_reason"] and not math.isfinite(curves["test_loss"].iloc[-1])

    index = pytest.importorskip("higbench.results.index")
    runs = index.load_runs(tmp_path / "outputs")
    assert sorted(runs["status"]) == ["completed", "diverged"]
    best = index.best_runs(runs, by="problem.name")  # a diverged run is never the best
    assert list(best["status"]) == ["completed"]
