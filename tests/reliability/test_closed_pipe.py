"""`make run | head -3`: a reader that leaves early stops the output, never the training."""

from __future__ import annotations

import subprocess

import pytest
from cli_runner import CLI, cli_env

from higbench.results import load_runs

pytestmark = pytest.mark.process  # the pipe is the point


def test_training_goes_on_when_its_output_pipe_closes(tmp_path):
    args = ["problem=toy", "optimizer=hig", "budget.max_updates=300", "budget.seconds=null", "eval_unit=updates",
            "eval_every=10", "threads=1", "checkpoint_every=null", f"hydra.run.dir={tmp_path}/run"]  # fmt: skip
    proc = subprocess.Popen([*CLI, *args], cwd=tmp_path, env=cli_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    first = proc.stdout.readline()  # the start line: then the reader is gone, as after `| head -1`
    proc.stdout.close()
    assert proc.wait(timeout=180) == 0
    assert b"starting" in first
    runs = load_runs(tmp_path / "run")
    assert runs["status"].tolist() == ["completed"], runs[["status", "error"]].to_string()
    assert int(runs["steps"].iloc[0]) == 300
