"""Edges of a run's storage: a resume with nothing left to do, no free inode for the run file."""

from __future__ import annotations

import math

import pytest
import torch
from omegaconf import OmegaConf
from rel_helpers import compose_here, stopped_run, train_here

from higbench.config import to_plain
from higbench.runfile.reader import load_run, load_updates
from higbench.runner.checkpoint import checkpoint_path
from higbench.runner.stored import resume_config


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
    stopped_run(run, monkeypatch, after=11)  # the 11th loop turn starts at step 10, just after its evaluation
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


def test_no_free_inodes_at_file_creation_is_one_line_and_leaves_nothing(tmp_path, monkeypatch, capsys):
    """Creating the run file fails with ENOSPC (inodes exhausted: free bytes remain, so the
    free-space check passes): one line, exit 1, no Hydra files or log left behind."""
    import errno

    import h5py

    from higbench import cli
    from higbench.runfile import writer

    real = h5py.File

    def no_inode(path, mode="r", **kwargs):
        if mode == "w-":
            raise OSError(errno.ENOSPC, f"Unable to synchronously create file (errno = {errno.ENOSPC}, No space left)")
        return real(path, mode, **kwargs)

    monkeypatch.setattr(writer.h5py, "File", no_inode)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    with pytest.raises(SystemExit) as info:
        cli.main(["problem=toy", "optimizer=sgd", "budget.max_updates=3", "threads=1", "progress=false", "hydra.run.dir=run"])
    lines = [ln for ln in capsys.readouterr().err.strip().splitlines() if ln.strip()]
    assert info.value.code == 1 and len(lines) == 1 and "No space left" in lines[0], lines
    assert list(work.iterdir()) == [], [str(p) for p in work.rglob("*")]


def test_stop_signal_just_after_the_file_is_closed_exits_as_the_file_says(higbench, tmp_path, monkeypatch):
    """SIGTERM while the CLI reports a run whose file is closed ``completed``: exit 0, not 143."""
    import os
    import signal

    from higbench.results import end_of_run

    real = end_of_run.summary_lines

    def late(*a):
        os.kill(os.getpid(), signal.SIGTERM)
        return real(*a)

    monkeypatch.setattr(end_of_run, "summary_lines", late)
    reached = []  # in a process of its own, a SIGTERM nobody ignores would end it (here: pytest)
    signal.signal(signal.SIGTERM, lambda signum, frame: reached.append(signum))  # put back after the test
    code, _, err = higbench("problem=toy", "optimizer=sgd", "budget.max_updates=5", "hydra.run.dir=run")
    meta, _ = load_run(tmp_path / "run" / "run.h5")
    assert meta["status"] == "completed"
    assert code == 0 and reached == [], (code, reached, err[-2000:])
