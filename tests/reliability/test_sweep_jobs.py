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


@pytest.mark.parametrize("batches", [[], ["hydra.sweeper.max_batch_size=1"]], ids=["one batch", "a batch per job"])
def test_one_job_refused_in_its_directory_fails_alone(tmp_path, monkeypatch, capsys, batches):
    """A link planted in one job's directory: that job is refused (one line), the other runs,
    and the sweep exits 1 saying how many failed; nothing is written through the link. In
    batches too: Hydra's basic sweeper stopped after the failed job's batch."""
    monkeypatch.chdir(tmp_path)
    sweep = tmp_path / "sweep"
    victim = tmp_path / "victim.h5"
    victim.write_bytes(b"someone's file")
    (sweep / "0").mkdir(parents=True)
    (sweep / "0" / "run.h5").symlink_to(victim)
    with pytest.raises(SystemExit) as info:
        _sweep(sweep, *batches)
    err = capsys.readouterr().err
    assert info.value.code == 1, err
    assert "symbolic link" in err and "1 of 2 sweep jobs failed" in err, err
    assert read_head(sweep / "1" / "run.h5").status == "completed"
    assert victim.read_bytes() == b"someone's file"


def test_the_job_list_sweeper_refuses_a_fifo(tmp_path):
    """Read in a thread of this process: had it blocked on the FIFO, opening the FIFO's other
    end lets it go, and the test fails."""
    import threading

    from hydra_plugins.higbench_joblist_sweeper.joblist_sweeper import read_jobs

    fifo = tmp_path / "jobs.json"
    os.mkfifo(fifo)
    outcome = {}

    def read():
        try:
            outcome["jobs"] = read_jobs(str(fifo))
        except Exception as exc:  # noqa: BLE001  (checked below)
            outcome["error"] = exc

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(timeout=30)
    if reader.is_alive():
        with open(fifo, "w"):  # the blocked open() returns, at end of file
            pass
        reader.join(timeout=30)
        pytest.fail("read_jobs blocked on a FIFO")
    error = outcome.get("error")
    assert isinstance(error, ValueError) and "not a regular file" in str(error), outcome


@pytest.mark.process
@pytest.mark.slow
def test_ctrl_c_in_a_joblib_sweep_loses_no_job(tmp_path):
    """SIGINT to a parallel sweep's process group, both jobs training and neither past its
    first checkpoint: the printed command completes both."""
    import shlex
    import signal
    import time

    from rel_helpers import table_rows

    sweep = tmp_path / "sweep"
    args = ["-m", "problem=toy", "optimizer=adam", "optimizer.lr=0.001,0.002", "budget.max_updates=400", "budget.seconds=null"]
    args += ["eval_unit=updates", "eval_every=20", "progress=false", "threads=1", "hydra.sweep.subdir=${hydra.job.num}"]
    args += ["hydra/launcher=joblib", "hydra.launcher.n_jobs=2", f"hydra.sweep.dir={sweep}"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "higbench.cli", *args],
        cwd=tmp_path,
        env=cli_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and not all(table_rows(sweep / str(n) / "run.h5") >= 2 for n in (0, 1)):
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.1)
    os.killpg(proc.pid, signal.SIGINT)
    _out, err = proc.communicate(timeout=120)
    lines = [line for line in err.splitlines() if line.startswith("complete the sweep with: ")]
    assert lines, err
    command = shlex.split(lines[-1].split(": ", 1)[1])
    assert command[0] == "higbench"
    _complete_sweep(tmp_path, sweep, command[1:], updates=400)


def test_the_job_list_sweeper_is_found_without_the_figures_launcher(higbench, tmp_path):
    """``higbench -m hydra/sweeper=joblist ...`` as docs/sweeps.md writes it, from any directory,
    with no PYTHONPATH (the figures' launcher sets one)."""
    jobs = tmp_path / "jobs.json"
    jobs.write_text('[["optimizer.lr=0.1"], ["optimizer.lr=0.2"]]')
    args = ["-m", "hydra/sweeper=joblist", f"hydra.sweeper.jobs_file={jobs}", "problem=toy", "optimizer=sgd"]
    args += ["budget.max_updates=2", "hydra.sweep.dir=sweep"]
    code, _, err = higbench(*args)
    assert code == 0, err
    assert len(list((tmp_path / "sweep").glob("*/run.h5"))) == 2


def test_a_worker_whose_sweep_parent_is_gone_stops_cleanly(tmp_path):
    """A launcher's worker trains for a parent pid; once that process is gone (the sweep's
    parent killed alone), the run stops as after SIGTERM: interrupted, checkpointed."""
    from rel_helpers import FAST, compose_here

    from higbench.runner.checkpoint import checkpoint_path
    from higbench.runner.plan import Plan
    from higbench.runner.train import train

    gone = os.getpid()  # a pid that is surely not this process's parent (its own)
    cfg = compose_here(["problem=toy", "optimizer=adam", "budget.max_updates=50", *FAST])
    plan = Plan.for_run(cfg, tmp_path / "run.h5").in_sweep(2, stop_with_parent=gone)
    summary = train(plan)
    assert summary.status == "interrupted" and "SIGTERM" in summary.reason, summary
    assert summary.steps == 0 and checkpoint_path(tmp_path / "run.h5").is_file()


@pytest.mark.slow
def test_sigterm_to_a_joblib_sweeps_parent_alone_leaves_no_worker_training(tmp_path):
    """``kill <parent pid>`` (a scheduler's SIGTERM to the sweep's process only): its joblib
    workers stop their runs cleanly instead of training on orphaned, and the sweep's resume
    completes both jobs."""
    import signal
    import time

    import psutil
    from rel_helpers import table_rows

    sweep = tmp_path / "sweep"
    args = ["-m", "problem=toy", "optimizer=adam", "optimizer.lr=0.001,0.002", "budget.max_updates=100000", "budget.seconds=null"]
    args += ["eval_unit=updates", "eval_every=20", "progress=false", "threads=1", "hydra.sweep.subdir=${hydra.job.num}"]
    args += ["hydra/launcher=joblib", "hydra.launcher.n_jobs=2", f"hydra.sweep.dir={sweep}"]
    log = (tmp_path / "sweep.log").open("w")  # not a pipe: a lingering worker would hold it open
    proc = subprocess.Popen([sys.executable, "-m", "higbench.cli", *args], cwd=tmp_path, env=cli_env(), stdout=log, stderr=log)
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and not all(table_rows(sweep / str(n) / "run.h5") >= 2 for n in (0, 1)):
        assert proc.poll() is None, (tmp_path / "sweep.log").read_text()
        time.sleep(0.1)
    workers = [p for p in psutil.Process(proc.pid).children(recursive=True) if "loky" in " ".join(p.cmdline()).lower()]
    proc.send_signal(signal.SIGTERM)  # the parent alone, not its process group
    proc.wait(timeout=60)
    _gone, alive = psutil.wait_procs(workers, timeout=60)
    assert not alive, f"workers still running after their sweep's parent was killed: {alive}"
    for n in (0, 1):
        assert read_head(sweep / str(n) / "run.h5").status == "interrupted", n
    _complete_sweep(tmp_path, sweep, [*args, "budget.max_updates=200", "resume=true"], updates=200)


@pytest.mark.slow
def test_a_sweep_a_driver_launched_stops_when_the_driver_is_gone(tmp_path):
    """The league's driver killed alone (a scheduler's SIGTERM, SIGKILL): the sweep it launched
    (basic launcher, jobs in one process) stops its run cleanly instead of going on through its
    jobs list with no driver to read them; it went on, orphaned, before."""
    import time

    import psutil
    from rel_helpers import table_rows

    sweep = tmp_path / "sweep"
    args = ["-m", "problem=toy", "optimizer=adam", "optimizer.lr=0.001,0.002", "budget.max_updates=100000", "budget.seconds=null"]
    args += ["eval_unit=updates", "eval_every=20", "progress=false", "threads=1", "hydra.sweep.subdir=${hydra.job.num}"]
    args += [f"hydra.sweep.dir={sweep}"]
    driver = (f"import os, subprocess, sys, time\nfrom higbench.jobs import _checkout_env\n"
              f"p = subprocess.Popen([sys.executable, '-m', 'higbench.cli', *{args!r}], env=_checkout_env(),\n"
              f"                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)\n"
              f"print(p.pid, flush=True)\ntime.sleep(3600)\n")  # fmt: skip
    proc = subprocess.Popen([sys.executable, "-c", driver], cwd=tmp_path, env=cli_env(), stdout=subprocess.PIPE, text=True)
    sweep_proc = psutil.Process(int(proc.stdout.readline()))
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and table_rows(sweep / "0" / "run.h5") < 2:
        assert sweep_proc.is_running() and proc.poll() is None
        time.sleep(0.1)
    proc.kill()  # the driver alone
    proc.wait(timeout=10)
    _gone, alive = psutil.wait_procs([sweep_proc], timeout=60)
    assert not alive, "the sweep went on after its driver was killed"
    assert read_head(sweep / "0" / "run.h5").status == "interrupted"
    assert not (sweep / "1" / "run.h5").exists()  # the next job never started


def _complete_sweep(tmp_path: Path, sweep: Path, argv: list[str], updates: int) -> None:
    """Run ``higbench argv`` (the sweep's completing command) as a process: exit 0, and both jobs
    completed with at least ``updates`` updates."""
    done = subprocess.run(
        [sys.executable, "-m", "higbench.cli", *argv], cwd=tmp_path, env=cli_env(), capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-3000:]
    for n in (0, 1):
        head = read_head(sweep / str(n) / "run.h5")
        assert head.status == "completed" and head.n_updates >= updates, (n, head.status, done.stderr[-2000:])
