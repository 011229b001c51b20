"""The runs root as the ledger of its jobs (higbench/jobs/ledger.py, worker.py) and the
launch around it: claims, dead workers, two drivers on one root, final records, submitit
arrays, progress.

The ledger's decisions are tested in this process on hand-made claim files (a dead pid, a
stale heartbeat, a live claim held by another process); one test (slow) kills a driver and
its worker with SIGKILL, synchronised on the files they write, and runs two drivers at once.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest
from cases import TINY_RUN

from higbench import jobs as runs
from higbench.jobs import Job, Launcher, LauncherError, parse_overrides, resolve, run_missing
from higbench.jobs.ledger import MAX_FAILURES, STALE_S, Ledger, LedgerError, process_started, this_host
from higbench.jobs.worker import run_claimed

ID = "0123456789abcdef"
NO_SUCH_PID = 2**22 + 1  # above Linux's largest pid_max: no process has it


def hand_made_claim(root: Path, identity: str, host: str, pid: int, pid_started: float, age_s: float = 0.0) -> Path:
    """A claim file as a worker writes it, its heartbeat ``age_s`` seconds ago."""
    ledger = Ledger(root)
    ledger.ensure_dir()
    path = ledger.dir / f"{identity}.claim"
    path.write_text(json.dumps({"host": host, "pid": pid, "pid_started": pid_started, "started": time.time(), "run": ""}))
    then = time.time() - age_s
    os.utime(path, (then, then))
    return path


def live_other_process(root: Path, identity: str) -> Path:
    """A claim held by another live process of this host (this test's parent)."""
    return hand_made_claim(root, identity, this_host(), os.getppid(), process_started(os.getppid()))


# -- claims -------------------------------------------------------------------------------------
def test_a_claim_is_exclusive_and_released(tmp_path):
    ledger = Ledger(tmp_path)
    with ledger.held(ID, "r/run.h5") as claim:
        assert claim is not None and claim.pid == os.getpid() and claim.host == this_host()
        assert ledger.try_claim(ID) is None  # the holder is alive: nobody else gets it
        assert ledger.live_holder(ID).pid == os.getpid()
    assert ledger.holder(ID) is None  # released at the end


def test_a_dead_workers_claim_is_broken_and_the_job_taken(tmp_path):
    """On this host: the pid is gone, or it is another process than the one that claimed."""
    ledger = Ledger(tmp_path)
    for pid, started in ((NO_SUCH_PID, 1.0), (os.getpid(), 12345.0)):  # gone; reused by another process
        hand_made_claim(tmp_path, ID, this_host(), pid, started)
        assert ledger.live_holder(ID) is None
        fd, claim = ledger.try_claim(ID)
        assert claim.pid == os.getpid()
        ledger.release(fd, claim)
    assert sorted(p.name for p in ledger.dir.iterdir()) == []  # the dead claims were removed, not left aside


def test_another_hosts_claim_lives_until_its_heartbeat_is_stale(tmp_path):
    ledger = Ledger(tmp_path)
    hand_made_claim(tmp_path, ID, "another-host", os.getpid(), 1.0, age_s=STALE_S / 2)
    assert ledger.try_claim(ID) is None  # its heartbeat is recent: its worker runs the job
    hand_made_claim(tmp_path, ID, "another-host", os.getpid(), 1.0, age_s=STALE_S + 1)
    got = ledger.try_claim(ID)
    assert got is not None and got[1].host == this_host()


def test_a_live_claim_of_another_process_is_left_alone(tmp_path):
    ledger = Ledger(tmp_path)
    path = live_other_process(tmp_path, ID)
    before = path.read_bytes()
    assert ledger.try_claim(ID) is None and path.read_bytes() == before


def test_a_link_planted_as_a_claim_or_as_the_ledger_is_never_followed(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("keep")
    root = tmp_path / "root"
    ledger = Ledger(root)
    ledger.ensure_dir()
    (ledger.dir / f"{ID}.claim").symlink_to(victim)
    with pytest.raises(LedgerError, match="not a regular file"):
        ledger.try_claim(ID)
    other = tmp_path / "other"
    other.mkdir()
    (other / "ledger").symlink_to(tmp_path / "elsewhere", target_is_directory=True)
    with pytest.raises(LedgerError, match="not a directory"):
        Ledger(other).ensure_dir()
    assert victim.read_text() == "keep" and not (tmp_path / "elsewhere").exists()


# -- records: what is final -----------------------------------------------------------------------
def test_a_memory_refusal_is_final_and_repeated_failures_are(tmp_path):
    ledger = Ledger(tmp_path)
    ledger.write_record(ID, "refused", None, "batch_size=512: ... but 10 MB is available")
    assert ledger.final(ID)["status"] == "refused"
    other = "fedcba9876543210"
    for attempt in range(1, MAX_FAILURES + 1):
        assert ledger.final(other) is None
        ledger.write_record(other, "failed", "x/run.h5", "boom")
        assert ledger.record(other)["failures"] == attempt
    assert ledger.final(other) is not None
    ledger.write_record(other, "interrupted", "x/run.h5")  # a run that got further: counting starts again
    assert ledger.final(other) is None


def test_the_worker_skips_a_held_job_and_records_a_memory_refusal(tmp_path):
    from higbench.errors import ConfigError, MemoryRefusal

    called = []
    live_other_process(tmp_path, ID)
    assert run_claimed(lambda cfg: called.append(cfg), {}, tmp_path, ID, tmp_path / "a" / "run.h5") is None
    assert called == []  # another worker runs it

    def refused(cfg, error=MemoryRefusal):
        try:
            raise error("batch_size", 512, "the HIG step needs about 9 GB but 10 MB is available; fits: 8")
        except ConfigError as exc:
            raise RuntimeError("job failed") from exc  # as the CLI hands it on (JobFailed)

    # a user's value whose message happens to speak of memory is a failure, not a refusal for good
    with pytest.raises(RuntimeError):
        run_claimed(lambda cfg: refused(cfg, ConfigError), {}, tmp_path, "00000000feedbeef", tmp_path / "c" / "run.h5")
    assert Ledger(tmp_path).final("00000000feedbeef") is None

    other = "fedcba9876543210"
    with pytest.raises(RuntimeError):
        run_claimed(refused, {}, tmp_path, other, tmp_path / "b" / "run.h5")
    assert Ledger(tmp_path).final(other)["status"] == "refused"
    assert run_claimed(lambda cfg: called.append(cfg), {}, tmp_path, other, tmp_path / "b" / "run.h5") is None
    assert called == [] and Ledger(tmp_path).holder(other) is None


# -- two drivers on one root (issue 51, break 7) ---------------------------------------------------
def toy_jobs(n: int, *extra: str) -> list[Job]:
    base = parse_overrides(["problem=toy", "optimizer=adam", *TINY_RUN, *extra])
    return [Job("league", "s", {**base, "seed": s}, seed=s) for s in range(n)]


def test_a_job_another_driver_runs_is_waited_for_not_run_twice(tmp_path, monkeypatch):
    """Driver B meets a job whose claim a live worker of driver A holds: B launches nothing for
    it, waits until A's worker has finished it, and returns it done: one run for the job.
    Before the ledger, B launched it again (two leagues into one root ran every job twice)."""
    import subprocess

    from higbench import cli

    (job,) = toy_jobs(1)
    resolve([job], {})
    claim = live_other_process(tmp_path, job.identity)
    multiruns = []
    real_run = subprocess.run

    def run(cmd, *args, **kwargs):
        if list(cmd[1:3]) == ["-m", "higbench.cli"]:
            multiruns.append(cmd)
            raise AssertionError("driver B launched a job driver A runs")
        return real_run(cmd, *args, **kwargs)

    def worker_a_finishes(seconds):  # B waits: meanwhile A's worker completes the run and releases its claim
        if claim.exists():
            cli.main([*job.override_list(), f"hydra.run.dir={tmp_path / 'a'}"])
            claim.unlink()

    monkeypatch.setattr(runs, "run_to_end", run)
    monkeypatch.setattr(runs, "pause", worker_a_finishes)
    left = run_missing([job], tmp_path, log=lambda text: None)
    assert left == [] and multiruns == []
    assert job.done and job.path == (tmp_path / "a" / "run.h5").resolve()
    assert len(list(tmp_path.rglob("run.h5"))) == 1


def test_workers_of_one_launch_claim_each_job_and_skip_one_held_elsewhere(higbench, tmp_path):
    """The job list as two drivers' multiruns meet it: job 0 is held by a live worker of the other
    driver (skipped, its claim untouched), job 1 runs and is recorded, job 2 is refused by the
    memory guard and recorded as refused (final: not launched again)."""
    ids = [f"{i:016x}" for i in (1, 2, 3)]
    held = live_other_process(tmp_path, ids[0])
    sweep = tmp_path / "sweep"
    tiny = ["problem=toy", *TINY_RUN]
    entries = [
        {"overrides": [*tiny, "optimizer=adam"], "claim": ids[0], "run": str(sweep / "0" / "run.h5")},
        {"overrides": [*tiny, "optimizer=adam", "seed=1"], "claim": ids[1], "run": str(sweep / "1" / "run.h5")},
        {"overrides": [*tiny, "optimizer=hig", "memory_limit_mb=0.001"], "claim": ids[2], "run": str(sweep / "2" / "run.h5")},
    ]
    jobs_file = tmp_path / "jobs.json"
    jobs_file.write_text(json.dumps({"ledger": str(tmp_path), "jobs": entries}))
    args = [f"hydra.sweeper.jobs_file={jobs_file}", f"hydra.sweep.dir={sweep}", "hydra.sweep.subdir=${hydra.job.num}"]
    code, _, err = higbench("-m", "hydra/sweeper=joblist", *args, tiny=False)
    assert code == 1 and "1 of 3 sweep jobs failed" in err, err[-2000:]  # the refusal
    assert sorted(p.parent.name for p in sweep.rglob("run.h5")) == ["1"]
    ledger = Ledger(tmp_path)
    assert ledger.record(ids[0]) == {} and held.exists()
    assert ledger.record(ids[1])["status"] == "completed" and ledger.holder(ids[1]) is None
    assert ledger.final(ids[2])["status"] == "refused" and "memory_limit_mb" in ledger.final(ids[2])["reason"]


# -- launcher settings and submitit arrays ---------------------------------------------------------
def test_a_bad_launcher_setting_is_one_line_before_anything_runs(tmp_path):
    with pytest.raises(LauncherError, match=r"^hydra.launcher.partiton=gpu: not a setting of the submitit_slurm launcher"):
        run_missing(toy_jobs(1), tmp_path, launcher="submitit_slurm", launcher_overrides=["partiton=gpu"])
    with pytest.raises(LauncherError, match="KEY=VALUE"):
        run_missing(toy_jobs(1), tmp_path, launcher="submitit_local", launcher_overrides=["gpus_per_node"])
    with pytest.raises(LauncherError, match="hydra.launcher.partition=gpu: not a setting of the submitit_local"):
        Launcher("submitit_local", ("hydra.launcher.partition=gpu",))
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_a_round_goes_to_slurm_as_one_job_array(tmp_path, monkeypatch):
    """The sbatch script submitit writes for a round of three jobs, without a cluster: its
    partition, time, GPUs and one array line (at most two tasks at once); each task runs the
    launch's job-list multirun narrowed to its job."""
    import submitit
    from submitit.core import utils as submitit_utils

    from higbench.jobs import arrays

    submitted = []

    def sbatch(self):  # submitit's call of `sbatch <file>`: the file's text kept, a job id answered
        submitted.append(Path(self.command[-1]).read_text())
        return "Submitted batch job 4242"

    monkeypatch.setattr(submitit_utils.CommandFunction, "__call__", sbatch)
    monkeypatch.setattr(submitit.SlurmExecutor, "affinity", classmethod(lambda cls: 2))  # no srun here
    launcher = runs.as_launcher("submitit_slurm", ["partition=gpu", "timeout_min=90", "gpus_per_node=1", "array_parallelism=2"])
    ex = arrays.executor(launcher.name, tmp_path / "submitit", launcher.settings())
    commands = [runs.multirun_command(tmp_path / "jobs.json", tmp_path, [f"hydra.sweeper.only={i}"], str(i)) for i in range(3)]
    tasks = arrays.submit_array(ex, commands)
    assert len(submitted) == 1 and [t.job_id for t in tasks] == ["4242_0", "4242_1", "4242_2"]
    script = submitted[0]
    for line in ("#SBATCH --partition=gpu", "#SBATCH --time=90", "#SBATCH --gpus-per-node=1", "#SBATCH --array=0-2%2"):
        assert line in script, script
    assert launcher.workers(3, 1) == 2


# -- progress --------------------------------------------------------------------------------------
def test_progress_counts_the_ledgers_records_and_is_quiet_under_progress_false(tmp_path, capsys):
    ledger = Ledger(tmp_path)
    jobs = toy_jobs(2, "budget.seconds=60", "budget.max_updates=null", "progress=true")
    for i, j in enumerate(jobs):
        j.identity = f"{i + 10:016x}"
    with runs.watching(jobs, ledger, workers=1):
        ledger.write_record(jobs[0].identity, "completed", "a/run.h5")
        ledger.write_record(jobs[1].identity, "failed", "b/run.h5", "boom")
    err = capsys.readouterr().err
    assert "[jobs] 0 of 2 runs done, about 2 min left" in err and "[jobs] 2 of 2 runs done (1 failed)" in err
    assert err.count("2 of 2 runs done") == 1  # a line when something ends, not one per look
    quiet = toy_jobs(2, "progress=false")
    for i, j in enumerate(quiet):
        j.identity = f"{i + 20:016x}"
    with runs.watching(quiet, ledger, workers=1):
        ledger.write_record(quiet[0].identity, "completed", "a/run.h5")
    assert capsys.readouterr().err == ""


# -- faults: kill -9 of a driver and its worker, then two drivers at once ---------------------------
DRIVER = """
import sys
from higbench.jobs import Job, parse_overrides, run_missing
base = parse_overrides(sys.argv[2:])
jobs = [Job("league", "s", {**base, "seed": s}, seed=s) for s in range(2)]
left = run_missing(jobs, sys.argv[1], log=lambda text: print(text, file=sys.stderr, flush=True))
sys.exit(1 if left else 0)
"""


def wait_for_file(root: Path, pattern: str, proc, limit_s: float = 300) -> Path:
    """The first file under ``root`` matching ``pattern`` (the test waits for it, not for a time)."""
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        if found := sorted(root.rglob(pattern)):
            return found[0]
        if proc.poll() is not None:
            pytest.fail(f"the driver ended (exit {proc.returncode}) before {pattern} appeared: {proc.stderr.read()[-3000:]}")
        time.sleep(0.05)
    pytest.fail(f"no {pattern} under {root} after {limit_s} s")


@pytest.mark.slow
@pytest.mark.process
def test_a_killed_driver_and_worker_then_two_drivers_at_once_run_each_job_once(tmp_path):
    """kill -9 of a driver with its worker mid-run (once the worker's claim and the run's first
    checkpoint exist), then the same command twice at once: both end with every job done; each
    job has exactly one completed run, and the killed one resumed from its checkpoint."""
    import signal
    import subprocess
    import sys

    from cli_runner import cli_env

    from higbench.results.index import load_runs

    root = tmp_path / "root"
    settings = ["problem=toy", "optimizer=adam", "budget.seconds=3", "budget.max_updates=null", "eval_unit=updates",
                "eval_every=20", "checkpoint_every=0.1", "threads=1", "progress=false"]  # fmt: skip
    command = [sys.executable, "-c", DRIVER, str(root), *settings]

    def start():
        return subprocess.Popen(command, env=cli_env(), stderr=subprocess.PIPE, text=True, start_new_session=True)

    first = start()
    wait_for_file(root, "ledger/*.claim", first)
    checkpoint = wait_for_file(root, "run.h5.ckpt", first)
    os.killpg(first.pid, signal.SIGKILL)  # the driver, its multirun and the worker in the middle of a run
    first.wait()
    again = [start(), start()]
    outs = [p.communicate(timeout=600)[1] for p in again]
    assert [p.returncode for p in again] == [0, 0], outs
    runs_ = load_runs(root, figure_runs=True)
    done = runs_[runs_["status"] == "completed"]
    assert len(done) == 2 and done["config_id"].nunique() == 2, runs_[["path", "status", "config_id"]]
    resumed = done[done["path"].map(lambda p: Path(p).resolve()) == checkpoint.with_name("run.h5").resolve()]
    assert len(resumed) == 1 and int(resumed["resumes"].iloc[0]) >= 1  # the killed run continued in place
    assert not list((root / "ledger").glob("*.claim"))  # every claim released
