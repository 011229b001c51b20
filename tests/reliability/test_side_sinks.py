"""A side sink that fails is turned off with one line and the run goes on (issue 39, item 8):
the run file is the record, TensorBoard a view of it."""

from __future__ import annotations

import errno

import pytest

from higbench import cli
from higbench.runfile.reader import read_head
from higbench.runner import tensorboard

RUN = ["problem=toy", "optimizer=adam", "budget.max_updates=6", "budget.seconds=null", "eval_unit=updates", "eval_every=2"]
RUN += ["progress=false", "threads=1", "tensorboard=true"]


def _turned_off(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("higbench: tensorboard turned off")]


def test_tensorboard_failing_mid_run_is_turned_off_and_the_run_completes(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    calls = {"n": 0}
    original = tensorboard.TensorBoardSink.flush

    def failing(self):
        calls["n"] += 1
        if calls["n"] == 2:
            raise OSError(errno.EFBIG, "File too large")
        original(self)

    monkeypatch.setattr(tensorboard.TensorBoardSink, "flush", failing)
    cli.main([*RUN, "hydra.run.dir=run"])
    lines = _turned_off(capsys.readouterr().err)
    assert len(lines) == 1 and "File too large" in lines[0], lines
    assert calls["n"] == 2  # never called again once off
    head = read_head(tmp_path / "run" / "run.h5")
    assert head.status == "completed" and head.n_updates == 6


def test_tensorboard_that_cannot_start_is_turned_off_and_the_run_completes(tmp_path, monkeypatch, capsys):
    """Its directory became a file between the checks and the start."""
    monkeypatch.chdir(tmp_path)

    def gone(run_dir):
        raise NotADirectoryError(errno.ENOTDIR, "Not a directory", str(run_dir / "tensorboard"))

    monkeypatch.setattr(tensorboard, "open_log_dir", gone)
    cli.main([*RUN, "hydra.run.dir=run"])
    lines = _turned_off(capsys.readouterr().err)
    assert len(lines) == 1 and "Not a directory" in lines[0], lines
    assert read_head(tmp_path / "run" / "run.h5").status == "completed"


def test_the_run_file_failing_still_stops_the_run(tmp_path, monkeypatch):
    """Only side sinks are turned off: a fault of the run file is the run's."""
    from higbench.runner.sinks import RunFileSink, Sinks

    class Broken(RunFileSink):
        def __init__(self):
            pass

        def on_eval(self, row):
            raise OSError(errno.EIO, "I/O error")

    with pytest.raises(OSError, match="I/O error"):
        Sinks(Broken()).on_eval({"step": 0})


@pytest.mark.parametrize("internal", ["RunFileSink", "ProgressSink"])
def test_an_internal_class_named_as_a_side_sink_is_turned_off_and_the_run_completes(internal, tmp_path, monkeypatch, capsys):
    """Before, the run's own sinks were told apart by their class: a side sink of class
    RunFileSink failed as if it were the run file, and the run died with a traceback and a
    failed file."""
    monkeypatch.chdir(tmp_path)
    run = [a for a in RUN if a != "tensorboard=true"]
    cli.main([*run, f"+sink.x._target_=higbench.runner.sinks.{internal}", "hydra.run.dir=run"])
    lines = [line for line in capsys.readouterr().err.splitlines() if "turned off" in line]
    assert len(lines) == 1 and lines[0].startswith(f"higbench: {internal} turned off"), lines
    head = read_head(tmp_path / "run" / "run.h5")
    assert head.status == "completed" and head.n_updates == 6
