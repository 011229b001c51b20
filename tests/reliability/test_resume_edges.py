"""Resume at the edges: nothing left to do."""

from __future__ import annotations

import math

import pytest
import torch
from omegaconf import OmegaConf
from rel_helpers import compose_here, stopped_run, train_here

from higbench.config import to_plain
from higbench.runfile.reader import load_run, load_updates
from higbench.runner.checkpoint import checkpoint_path, resume_config


def resume_here(run_file, extra):
    overrides = [f"resume={run_file.parent}", *extra]
    stored = load_run(run_file)[0]["config"]
    merged = resume_config(stored, to_plain(compose_here(overrides)), overrides)
    return train_here(OmegaConf.create(merged), run_file, overrides=overrides, resume=True)


@pytest.mark.parametrize("budget", ["budget.seconds=0.001", "budget.max_updates=STEP"])
def test_resume_with_the_budget_spent_completes_with_the_last_test_loss(tmp_path, monkeypatch, budget):
    """Stopped right after an evaluation, resumed with nothing left to do: ``completed`` with
    the last recorded test loss (it was ``diverged``, "non-finite test loss", checkpoint gone)."""
    run = tmp_path / "run" / "run.h5"
    stopped_run(run, monkeypatch, after=13)
    state = torch.load(checkpoint_path(run), weights_only=True)
    assert state["step"] == state["last_eval_step"] > 0, "the stop must land just after an evaluation"
    _, curves = load_run(run)
    summary = resume_here(run, [budget.replace("STEP", str(state["step"]))])
    meta, after = load_run(run)
    assert summary.status == meta["status"] == "completed", (summary, meta["status_reason"])
    assert math.isfinite(summary.final_test_loss) and summary.final_test_loss == curves["test_loss"].iloc[-1]
    assert after["step"].tolist() == curves["step"].tolist(), "no second row for the same step"
    assert load_updates(run)["step"].tolist() == list(range(1, state["step"] + 1))
    assert meta["steps"] == state["step"]
