"""Two sweeps started at the same moment into the same outputs/ never share a run file."""

from __future__ import annotations

from pathlib import Path

import pytest
from cases import TINY_RUN
from cli_runner import cli_env, start_cli

from higbench.results import load_runs

SWEEP = ["-m", "optimizer=adam", "optimizer.lr=0.01,0.1", "problem=toy", *TINY_RUN]


def start_together(cwd, *argvs):
    procs = [start_cli(argv, cwd, env=cli_env(launcher_threads=True)) for argv in argvs]
    return [(p, *p.communicate(timeout=300)) for p in procs]


@pytest.mark.process  # two processes at once: each claims its directories
def test_concurrent_sweeps_get_their_own_directories(tmp_path):
    """Same command twice, at once, with the default sweep directory of conf/config.yaml
    (outputs/sweeps/<date>/<time with microseconds>, relative to the working directory)."""
    for proc, _out, err in start_together(tmp_path, SWEEP, SWEEP):
        assert proc.returncode == 0, err[-3000:]
    runs = load_runs(tmp_path / "outputs")
    assert len(runs) == 4 and runs["path"].is_unique
    assert set(runs["status"]) == {"completed"}, runs[["path", "status", "error"]]
    sweep_dirs = {p.rsplit("/", 2)[0] for p in runs["path"]}
    assert len(sweep_dirs) == 2  # one per sweep, each with both jobs and its multirun.yaml
    for d in sweep_dirs:
        assert sorted(p.rsplit("/", 2)[1].split("_")[0] for p in runs["path"] if p.startswith(d + "/")) == ["0", "1"]
        assert Path(d, "multirun.yaml").is_file()
    assert sorted(runs["optimizer.lr"]) == [0.01, 0.01, 0.1, 0.1]


@pytest.mark.process
@pytest.mark.slow
def test_forced_same_sweep_dir_never_overwrites(tmp_path):
    """Even when both sweeps are told the same directory, a run file has one writer: each job's
    directory is claimed by one sweep, and the other sweep's copy of that job fails alone
    (refused, nothing overwritten), so the jobs may split between the two sweeps and both
    report the jobs they lost. Every job runs exactly once."""
    same = [*SWEEP, f"hydra.sweep.dir={tmp_path / 'same'}"]
    results = start_together(tmp_path, same, same)
    losers = [err for p, _, err in results if p.returncode != 0]
    assert losers, [(p.returncode, err[-500:]) for p, _, err in results]  # two jobs, four attempts: two refused
    for err in losers:
        assert "refusing to overwrite" in err or "already holds a run file" in err, err[-1000:]
    runs = load_runs(tmp_path / "same")
    assert len(runs) == 2 and set(runs["status"]) == {"completed"}
