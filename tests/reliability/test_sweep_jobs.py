"""Sweeps lose no job (issue 39, item 6): a job stopped before its first checkpoint (a parallel
sweep's worker hard-killed by Ctrl-C) is run again by the sweep's resume command, a job
refused in its own directory fails alone, and the job-list sweeper never blocks on a FIFO."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import h5py
import pytest
from rel_helpers import cli_env

from higbench import cli
from higbench.runfile.reader import read_head

JOBS = ["problem=toy", "optimizer=adam", "optimizer.lr=0.001,0.002", "budget.max_updates=3", "budget.seconds=null"]
JOBS += ["eval_unit=updates", "eval_every=1", "progress=false", "threads=1", "hydra.sweep.subdir=${hydra.job.num}"]


def _sweep(sweep: Path, *extra: str) -> None:
    cli.main(["-m", *JOBS, f"hydra.sweep.dir={sweep}", *extra])


def test_a_job_killed_before_its_first_checkpoint_is_run_again_by_the_sweeps_resume(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    sweep = tmp_path / "sweep"
    _sweep(sweep)
    killed = sweep / "1" / "run.h5"
    with h5py.File(killed, "a") as f:  # as a worker hard-killed mid-run leaves it: running, no checkpoint
        f.attrs["status"] = "running"
        del f["weights"]
    kept = sweep / "0" / "run.h5"
    before = kept.read_bytes()
    capsys.readouterr()
    _sweep(sweep, "resume=true")
    err = capsys.readouterr().err
    assert "before its first checkpoint; moved to run.h5.stopped-" in err, err
    assert read_head(killed).status == "completed"
    assert [p.name for p in killed.parent.glob("run.h5.stopped-*")], "the stopped file is kept aside"
    assert kept.read_bytes() == before and "kept as it is" in err


def test_one_job_refused_in_its_directory_fails_alone(tmp_path, monkeypatch, capsys):
    """A link planted in one job's directory: that job is refused (one line), the other runs,
    and the sweep exits 1 saying how many failed; nothing is written through the link."""
    monkeypatch.chdir(tmp_path)
    sweep = tmp_path / "sweep"
    victim = tmp_path / "victim.h5"
    victim.write_bytes(b"someone's file")
    (sweep / "0").mkdir(parents=True)
    (sweep / "0" / "run.h5").symlink_to(victim)
    with pytest.raises(SystemExit) as info:
        _sweep(sweep)
    err = capsys.readouterr().err
    assert info.value.code == 1, err
    assert "symbolic link" in err and "1 of 2 sweep jobs failed" in err, err
    assert read_head(sweep / "1" / "run.h5").status == "completed"
    assert victim.read_bytes() == b"someone's file"


def test_the_job_list_sweeper_refuses_a_fifo(tmp_path):
    fifo = tmp_path / "jobs.json"
    os.mkfifo(fifo)
    code = "import sys; from hydra_plugins.higbench_joblist_sweeper.joblist_sweeper import read_jobs; read_jobs(sys.argv[1])"
    try:
        proc = subprocess.run([sys.executable, "-c", code, str(fifo)], capture_output=True, text=True, timeout=60, env=cli_env())
    except subprocess.TimeoutExpired:
        pytest.fail("read_jobs blocked on a FIFO")
    assert proc.returncode == 1 and "not a regular file" in proc.stderr, proc.stderr
