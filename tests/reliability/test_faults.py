"""Faults of the file system and of the run directory (issue 10): disk full, a checkpoint of
another run, a failure while closing, dead run dirs, sweeps run again into their directory,
a run file deleted or replaced under a live run, unusable output locations, and smaller ones.

Invariants checked throughout: a fault is one line on stderr (exit 1 for a run that had
started, 2 for input refused before anything was written); every row a run had flushed
before the fault is still readable afterwards; no completed run's file changes.

Disk full is a real file-system fault: a small tmpfs (needs root to mount; skipped
otherwise) filled by another file while the run writes, and the process's file-size limit
(RLIMIT_FSIZE, lowered with prlimit on a live run; works without root).
"""

from __future__ import annotations

import os
import resource
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import uuid
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir
from rel_helpers import (
    FAST,
    REPO,
    compose_here,
    files_under,
    run_cli,
    sha256,
    start_cli,
    stopped_run,
    table_rows,
    train_here,
    wait_for_rows,
)

from higbench import cli
from higbench.results.index import load_runs
from higbench.runfile.reader import load_run, load_updates
from higbench.runfile.writer import DiskFull, RunFileWriter
from higbench.runner import checkpoint
from higbench.runner.rundir import EMPTY_FILE_BYTES, RunDir

LONG_RUN = ["problem=toy", "optimizer=adam", "budget.seconds=30", "eval_unit=updates", "eval_every=10", *FAST]


def one_error_line(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("higbench: error: "), err
    return lines[0]


def curve_steps(path: Path) -> list[int]:
    return load_run(path)[1]["step"].tolist()


# -- 1. disk full mid-run --------------------------------------------------------------------


@pytest.fixture
def tmpfs(tmp_path):
    """A 8 MiB tmpfs (root only)."""
    mnt = tmp_path / "tmpfs"
    mnt.mkdir()
    if (
        os.geteuid() != 0
        or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=8m", "tmpfs", str(mnt)], capture_output=True).returncode
    ):
        pytest.skip("cannot mount a tmpfs here (needs root)")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def fill(directory: Path, leave: int) -> None:
    st = os.statvfs(directory)
    free = st.f_bavail * st.f_frsize
    fd = os.open(directory / f"filler-{uuid.uuid4().hex[:6]}", os.O_WRONLY | os.O_CREAT)
    try:
        os.write(fd, b"\0" * max(0, free - leave))
    except OSError:  # nothing left: as intended
        pass
    finally:
        os.close(fd)


def assert_stopped_by_disk(code: int, out: str, err: str, run_file: Path, rows_before: int):
    assert code == 1, (out, err)
    line = one_error_line(err)
    assert "no space left" in line, line
    assert "completed" not in out
    meta, curves = load_run(run_file)  # readable
    assert meta["status"] == "failed" and "DiskFull" in meta["status_reason"], meta["status_reason"]
    assert len(curves) >= rows_before, "a row flushed before the disk filled was lost"
    assert curves["step"].is_monotonic_increasing
    updates = load_updates(run_file)
    assert updates["step"].tolist() == list(range(1, len(updates) + 1))


def after_rows(monkeypatch, n: int, fault) -> dict:
    """``fault(writer)`` once, right after the flush that puts the run file's ``n``-th curve row
    on disk (the run going on): a fault of the file system between two writes of a run in this
    process. The returned dict gets ``rows``, the curve rows flushed when the fault came."""
    flush, seen = RunFileWriter.flush, {}

    def flush_then_fault(self):
        flush(self)
        rows = int(self.f["curves"]["step"].shape[0]) if "step" in self.f["curves"] else 0
        if "rows" not in seen and rows >= n:
            seen["rows"] = rows
            fault(self)

    monkeypatch.setattr(RunFileWriter, "flush", flush_then_fault)
    return seen


@pytest.mark.parametrize("leave", [300 * 1024, pytest.param(0, marks=pytest.mark.slow)], ids=["300KiB-left", "nothing-left"])
def test_disk_filled_by_another_file_stops_the_run_with_a_readable_file(tmpfs, leave, higbench, monkeypatch):
    seen = after_rows(monkeypatch, 4, lambda writer: fill(tmpfs, leave))
    code, out, err = higbench(*LONG_RUN, "checkpoint_every=0.3", f"hydra.run.dir={tmpfs}/run", tiny=False)
    assert_stopped_by_disk(code, out, err, tmpfs / "run" / "run.h5", seen["rows"])


def test_run_filling_the_disk_itself_stops_at_the_reserve(tmpfs):
    """The writer's own appends fill the disk: stopped before the write that would fail."""
    fill(tmpfs, 3 * 1024 * 1024)
    path = tmpfs / "run.h5"
    w = RunFileWriter(path, "a: 1\n", [], env={}, meta={})
    flushed = 0
    with pytest.raises(DiskFull):
        for i in range(10_000):
            w.append_rows("updates", {"step": np.arange(i * 4096, (i + 1) * 4096), "loss": np.ones(4096)})
            w.append_row("curves", {"step": i})
            w.flush()
            flushed = i + 1
    w.close("failed", "disk full", flushed)
    with h5py.File(path, "r") as f:
        assert f.attrs["status"] == "failed"
        assert f["curves/step"].shape[0] >= flushed and f["updates/step"].shape[0] >= flushed * 4096
        assert f["curves/step"][flushed - 1] == flushed - 1
    assert flushed > 10, "the disk filled at once: the test did not exercise appends"


@pytest.mark.process
@pytest.mark.slow
def test_file_size_limit_reached_mid_run(tmp_path):
    """RLIMIT_FSIZE lowered on a live run (no root needed): same outcome as a full disk."""
    proc = start_cli([*LONG_RUN, "checkpoint_every=null", f"hydra.run.dir={tmp_path}/run"], cwd=tmp_path)
    run_file = tmp_path / "run" / "run.h5"
    wait_for_rows(run_file, 4, proc)
    rows = table_rows(run_file)
    size = run_file.stat().st_size
    resource.prlimit(proc.pid, resource.RLIMIT_FSIZE, (size + 1024 * 1024 + 64 * 1024, resource.RLIM_INFINITY))
    out, err = proc.communicate(timeout=90)
    assert_stopped_by_disk(proc.returncode, out, err, run_file, rows)


# -- 2. a checkpoint of another run ----------------------------------------------------------


def test_checkpoint_of_another_run_is_refused(tmp_path, monkeypatch, capsys):
    a, b = tmp_path / "a" / "run.h5", tmp_path / "b" / "run.h5"
    stopped_run(a, monkeypatch)
    stopped_run(b, monkeypatch, ["optimizer.lr=0.01"], after=15)
    shutil.copy(checkpoint.checkpoint_path(a), checkpoint.checkpoint_path(b))  # the stray one
    before = {p: sha256(p) for p in (a, b, checkpoint.checkpoint_path(a), checkpoint.checkpoint_path(b))}
    monkeypatch.chdir(tmp_path)
    for value in (str(b.parent), str(b)):
        with pytest.raises(SystemExit) as info:
            cli.main([f"resume={value}"])
        assert info.value.code == 2
        assert "belongs to another run" in one_error_line(capsys.readouterr().err)
    assert {p: sha256(p) for p in before} == before
    # in-job check too (what a sweep job does): train refuses before reopening the file
    with pytest.raises(cli.ConfigError, match="belongs to another run"):
        train_here(compose_here([]), b, resume=True)
    assert {p: sha256(p) for p in before} == before


def test_checkpoint_without_run_id_or_with_more_rows_is_refused(tmp_path, monkeypatch, capsys):
    run = tmp_path / "r" / "run.h5"
    stopped_run(run, monkeypatch)
    ckpt = checkpoint.checkpoint_path(run)
    state = torch.load(ckpt, weights_only=False)
    monkeypatch.chdir(tmp_path)
    for case, change in (("legacy", lambda s: s.pop("run_id")), ("rows", lambda s: s["rows"]["curves"].update(step=999))):
        bad = dict(state, rows={g: dict(v) for g, v in state["rows"].items()})
        change(bad)
        torch.save(bad, ckpt)
        before = sha256(run)
        with pytest.raises(SystemExit) as info:
            cli.main([f"resume={run.parent}"])
        line = one_error_line(capsys.readouterr().err)
        assert info.value.code == 2, line
        assert ("another run" if case == "legacy" else "fewer rows") in line, line
        assert sha256(run) == before and load_run(run)[0]["status"] == "interrupted"


@pytest.mark.process
@pytest.mark.slow
def test_new_run_does_not_adopt_a_stray_checkpoint(tmp_path, monkeypatch):
    a = tmp_path / "a" / "run.h5"
    stopped_run(a, monkeypatch)
    target = tmp_path / "new"
    target.mkdir()
    shutil.copy(checkpoint.checkpoint_path(a), target / "run.h5.ckpt")
    stray = sha256(target / "run.h5.ckpt")
    r = run_cli(["problem=toy", "optimizer=sgd", "budget.max_updates=20", *FAST, f"hydra.run.dir={target}"], cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "moved to run.h5.ckpt.stray-" in r.stderr
    kept = list(target.glob("run.h5.ckpt.stray-*"))
    assert len(kept) == 1 and sha256(kept[0]) == stray, "the stray checkpoint was lost or changed"
    with h5py.File(target / "run.h5", "r") as f:
        assert f.attrs["run_id"] != torch.load(kept[0], weights_only=False)["run_id"]
    assert load_updates(target / "run.h5")["step"].tolist() == list(range(1, 21)), "it continued another run"


# -- 3. failure while closing ----------------------------------------------------------------


@pytest.mark.parametrize("where", ["write_weights", "set_attrs", "disk_full_at_end"])
def test_failure_while_closing_leaves_status_failed(tmp_path, monkeypatch, where):
    def boom(self, *args, **kwargs):
        if where == "disk_full_at_end":
            raise DiskFull("no space left (injected at the end of the run)")
        raise RuntimeError(f"injected failure in {where}")

    monkeypatch.setattr(RunFileWriter, "set_attrs" if where == "set_attrs" else "write_weights", boom)
    path = tmp_path / "run.h5"
    with pytest.raises((RuntimeError, DiskFull)):
        train_here(
            compose_here(["problem=toy", "optimizer=sgd", "budget.max_updates=30", "eval_unit=updates", "eval_every=10", *FAST]),
            path,
        )
    meta, curves = load_run(path)
    assert meta["status"] == "failed" and ("injected" in meta["status_reason"]), meta
    assert curves["step"].tolist() == [0, 10, 20, 30], "rows written before the failure were lost"


def test_failure_while_stopping_on_a_signal_leaves_status_failed(tmp_path, monkeypatch):
    monkeypatch.setattr(checkpoint, "save", lambda *a, **k: (_ for _ in ()).throw(DiskFull("no space left (injected)")))
    with pytest.raises(DiskFull):
        stopped_run(tmp_path / "run.h5", monkeypatch)
    meta, curves = load_run(tmp_path / "run.h5")
    assert meta["status"] == "failed" and len(curves) >= 5


# -- 4. dead run dirs ------------------------------------------------------------------------


def _killed_at_creation(run_dir: Path, config_yaml: str | None = None) -> Path:
    """A run dir as left by a run killed while creating run.h5: a 96-byte header, Hydra's files."""
    run_dir.mkdir(parents=True)
    probe = run_dir / "probe.h5"
    RunFileWriter(probe, "a: 1\n", [], env={}, meta={}).close()
    (run_dir / "run.h5").write_bytes(probe.read_bytes()[:96])
    probe.unlink()
    (run_dir / ".hydra").mkdir()
    if config_yaml is not None:
        (run_dir / ".hydra" / "config.yaml").write_text(config_yaml)
    return run_dir / "run.h5"


@pytest.mark.process
@pytest.mark.slow
def test_dir_of_a_run_killed_at_creation_can_be_started_again(tmp_path):
    from omegaconf import OmegaConf

    stub = _killed_at_creation(tmp_path / "new", None)
    args = ["problem=toy", "optimizer=sgd", "budget.max_updates=10", *FAST]
    r = run_cli([*args, f"hydra.run.dir={stub.parent}"], cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "recorded nothing" in r.stderr and "moved to run.h5.empty-" in r.stderr, r.stderr
    assert load_run(stub)[0]["status"] == "completed"
    assert len(list(stub.parent.glob("run.h5.empty-*"))) == 1  # moved aside, not deleted
    # resume= of such a dir: started again from the config Hydra saved for it
    cfg = OmegaConf.to_yaml(compose_here(args))
    stub2 = _killed_at_creation(tmp_path / "resumed", cfg)
    r = run_cli([f"resume={stub2.parent}", *FAST], cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "recorded nothing" in r.stderr
    meta, curves = load_run(stub2)
    assert meta["status"] == "completed" and meta["config"]["optimizer"]["name"] == "sgd"


def test_a_sweep_job_killed_at_creation_starts_again_from_its_own_config_and_its_init_from(tmp_path):
    """resume=true on a sweep whose job died creating its file: the job's config is the one
    composed now (its init_from the user's, from a config file or the command line), not a
    stored one, so its init_from is opened as given, never refused as a stored config's path."""
    from omegaconf import OmegaConf

    from higbench.runner.plan import make_plan

    donor = tmp_path / "donor" / "run.h5"
    train_here(compose_here(["problem=toy", "optimizer=sgd", "budget.max_updates=3", *FAST]), donor)
    task = compose_here(["problem=toy", "optimizer=sgd", "budget.max_updates=3", "resume=true", *FAST])
    task = OmegaConf.to_container(task, resolve=True) | {"init_from": str(donor)}  # as a config file sets it
    stub = _killed_at_creation(tmp_path / "sweep" / "0")
    plan = make_plan(task, stub.parent, ["resume=true"], multirun=True)
    assert plan.policy == "restart" and plan.initial_weights is not None


@pytest.mark.process
@pytest.mark.slow
def test_killed_before_first_checkpoint(tmp_path):
    """Updates recorded, no checkpoint: resume says why (not 'set checkpoint_every'); a run with no update restarts."""
    proc = start_cli([*LONG_RUN, "checkpoint_every=1000", f"hydra.run.dir={tmp_path}/run"], cwd=tmp_path)
    run_file = tmp_path / "run" / "run.h5"
    wait_for_rows(run_file, 3, proc)
    proc.kill()
    proc.communicate()
    before = sha256(run_file)
    r = run_cli([f"resume={run_file.parent}"], cwd=tmp_path)
    line = one_error_line(r.stderr)
    assert r.returncode == 2 and "before its first checkpoint" in line and "1000" in line, line
    assert "set checkpoint_every" not in line
    r = run_cli([*LONG_RUN, f"hydra.run.dir={run_file.parent}"], cwd=tmp_path)  # a new run there: refused
    assert r.returncode == 2 and "already holds a run file" in one_error_line(r.stderr)
    assert sha256(run_file) == before
    # a run that stopped before its first update (status running, no update, no checkpoint)
    empty_dir = tmp_path / "empty"
    w = RunFileWriter(empty_dir / "run.h5", "a: 1\n", [], env={}, meta={})
    w.append_row("curves", {"step": 0, "test_loss": 1.0})
    w.f.close()  # killed: status stays running
    assert RunDir(empty_dir / "run.h5").recorded_nothing()


@pytest.mark.process
@pytest.mark.slow
def test_large_unreadable_file_is_never_taken_over(tmp_path):
    d = tmp_path / "garbage"
    d.mkdir()
    (d / "run.h5").write_bytes(b"x" * (EMPTY_FILE_BYTES + 1))
    before = sha256(d / "run.h5")
    r = run_cli(["problem=toy", "optimizer=sgd", "budget.max_updates=5", *FAST, f"hydra.run.dir={d}"], cwd=tmp_path)
    assert r.returncode == 2 and "already holds a run file" in one_error_line(r.stderr)
    assert sha256(d / "run.h5") == before and files_under(d) == ["run.h5"]


# -- 5. sweeps run again into their directory ------------------------------------------------

SWEEP = ["-m", "problem=toy", "optimizer=adam", "optimizer.lr=0.001,0.002,0.003", "eval_unit=updates", "eval_every=20", *FAST]


def _sweep_state(sweep: Path) -> dict[str, str]:
    """Digests of every file of the sweep except what a re-run may add (new .hydra/rerun-*, multirun-rerun-*)."""
    return {
        str(p.relative_to(sweep)): sha256(p)
        for p in sorted(sweep.rglob("*"))
        if p.is_file() and "rerun-" not in str(p.relative_to(sweep)) and not p.name.endswith(".log")
    }


@pytest.mark.process
@pytest.mark.slow
def test_completed_sweep_run_again_changes_nothing(tmp_path):
    sweep = tmp_path / "sweep"
    r = run_cli([*SWEEP, "budget.max_updates=40", f"hydra.sweep.dir={sweep}"], cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    before = _sweep_state(sweep)
    assert sum(k.endswith("run.h5") for k in before) == 3
    for extra in ([], ["resume=true"]):
        r = run_cli([*SWEEP, "budget.max_updates=40", f"hydra.sweep.dir={sweep}", *extra], cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        assert r.stderr.count("kept as it is") == 3, r.stderr
        assert _sweep_state(sweep) == before, "an existing run's files changed"


@pytest.mark.process
@pytest.mark.slow
def test_interrupted_sweep_is_completed_in_place(tmp_path):
    """Sweep stopped by SIGINT in its second job: one command resumes it, runs the third, keeps the first."""
    sweep = tmp_path / "sweep"
    args = [*SWEEP, "budget.seconds=2", "checkpoint_every=0.2", f"hydra.sweep.dir={sweep}"]
    proc = start_cli(args, cwd=tmp_path)
    deadline = 120
    second = None
    import time

    t0 = time.monotonic()
    while second is None and time.monotonic() - t0 < deadline:
        found = sorted(sweep.glob("1_*/run.h5"))
        second = found[0] if found and table_rows(found[0]) >= 3 else None
        time.sleep(0.05)
    assert second is not None
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGINT, err
    hint = [ln for ln in err.splitlines() if ln.startswith("resume with: ")]
    assert hint and shlex.split(hint[0][len("resume with: ") :])[1] == f"resume={second.parent}", hint
    first = sorted(sweep.glob("0_*/run.h5"))[0]
    assert load_run(second)[0]["status"] == "interrupted"
    rows_before = table_rows(second)
    kept = {p: sha256(p) for p in [first, *first.parent.joinpath(".hydra").glob("*.yaml"), sweep / "multirun.yaml"]}
    hydra_second = {p: sha256(p) for p in second.parent.joinpath(".hydra").glob("*.yaml")}
    r = run_cli([*args, "resume=true"], cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert {p: sha256(p) for p in kept} == kept, "the completed job's files changed"
    assert {p: sha256(p) for p in hydra_second} == hydra_second, "the resumed job's .hydra/ was rewritten"
    runs = sorted(sweep.glob("*/run.h5"))
    assert len(runs) == 3 and all(load_run(p)[0]["status"] == "completed" for p in runs)
    meta, curves = load_run(second)
    assert len(meta["resumes"]) == 1 and len(curves) >= rows_before
    assert load_updates(second)["step"].tolist() == list(range(1, meta["steps"] + 1))


# -- 6. run file deleted or replaced under a live run ----------------------------------------


@pytest.mark.parametrize("how", ["deleted", "replaced", "dir-renamed"])
def test_run_file_deleted_or_replaced_while_running(tmp_path, how, higbench, monkeypatch):
    run_file = tmp_path / "run" / "run.h5"
    replacement = {}

    def fault(writer):
        if how == "deleted":
            run_file.unlink()
        elif how == "dir-renamed":
            os.rename(run_file.parent, tmp_path / "moved")
        else:
            other = tmp_path / "other.h5"
            shutil.copy(run_file, other)
            os.replace(other, run_file)
            replacement["sha"] = sha256(run_file)

    after_rows(monkeypatch, 3, fault)
    code, out, err = higbench(*LONG_RUN, "checkpoint_every=null", f"hydra.run.dir={tmp_path}/run", tiny=False)
    assert code == 1, (out, err)
    line = one_error_line(err)
    assert f"was {'replaced by another file' if how == 'replaced' else 'deleted'}" in line, line
    assert "completed" not in out and "run file:" not in out
    if how == "dir-renamed":  # the file went with its directory: readable, failed, rows kept
        meta, curves = load_run(tmp_path / "moved" / "run.h5")
        assert meta["status"] == "failed" and len(curves) >= 3
    elif how == "deleted":
        assert not run_file.exists()
        assert (run_file.parent / ".hydra" / "config.yaml").is_file(), "the run's other files went with it"
    else:
        assert sha256(run_file) == replacement["sha"], "the run wrote into the file that replaced its own"


# -- 7. unusable output locations ------------------------------------------------------------


def _refused(argv, tmp_path, monkeypatch, capsys, key):
    work = tmp_path / "work"
    work.mkdir(exist_ok=True)
    monkeypatch.chdir(work)
    before = files_under(tmp_path)
    monkeypatch.setattr(cli, "_run_job", lambda cfg: pytest.fail(f"{argv} reached the job"))
    with pytest.raises(SystemExit) as info:
        cli.main([*argv, "budget.max_updates=5"])
    line = one_error_line(capsys.readouterr().err)
    assert info.value.code == 2, line
    assert line.startswith(f"higbench: error: {key}="), line
    assert files_under(tmp_path) == before, "a refused output location got files"
    return line


def test_output_dir_is_a_file(tmp_path, monkeypatch, capsys):
    (tmp_path / "afile").write_text("x")
    assert "not a directory" in _refused([f"hydra.run.dir={tmp_path}/afile/run"], tmp_path, monkeypatch, capsys, "hydra.run.dir")
    line = _refused(["-m", "seed=0,1", f"hydra.sweep.dir={tmp_path}/afile"], tmp_path, monkeypatch, capsys, "hydra.sweep.dir")
    assert "not a directory" in line


def test_output_name_too_long(tmp_path, monkeypatch, capsys):
    line = _refused([f"hydra.run.dir={tmp_path}/{'x' * 300}"], tmp_path, monkeypatch, capsys, "hydra.run.dir")
    assert "longer than the file system allows" in line


def test_output_dir_read_only(tmp_path, monkeypatch, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    if os.geteuid() == 0:
        if subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(ro)], capture_output=True).returncode:
            pytest.skip("cannot mount a read-only tmpfs")
        try:
            line = _refused([f"hydra.run.dir={ro}/run"], tmp_path, monkeypatch, capsys, "hydra.run.dir")
        finally:
            subprocess.run(["umount", "-l", str(ro)], capture_output=True)
        assert "read-only file system" in line
    else:
        ro.chmod(0o555)
        line = _refused([f"hydra.run.dir={ro}/run"], tmp_path, monkeypatch, capsys, "hydra.run.dir")
        assert "not writable" in line


def test_output_disk_full_at_start(tmpfs, tmp_path, monkeypatch, capsys):
    fill(tmpfs, 512 * 1024)
    line = _refused([f"hydra.run.dir={tmpfs}/run"], tmp_path, monkeypatch, capsys, "hydra.run.dir")
    assert "KiB free" in line
    assert not (tmpfs / "run").exists()


@pytest.mark.process
@pytest.mark.slow
def test_output_disk_full_at_start_by_file_size_limit(tmp_path):
    """No root needed: RLIMIT_FSIZE of the CLI process below what a run needs."""
    limit = 512 * 1024
    r = subprocess.run(
        [sys.executable, "-m", "higbench.cli", "budget.max_updates=5", f"hydra.run.dir={tmp_path}/run", *FAST],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit)),
        timeout=120,
    )
    assert r.returncode == 2 and "KiB free" in one_error_line(r.stderr), r.stderr
    assert not (tmp_path / "run").exists()


def test_dangling_symlink_named_run_file(tmp_path, monkeypatch, capsys):
    d = tmp_path / "run"
    d.mkdir()
    (d / "run.h5").symlink_to(tmp_path / "nowhere" / "x.h5")
    line = _refused([f"hydra.run.dir={d}"], tmp_path, monkeypatch, capsys, "hydra.run.dir")
    assert "dangling symbolic link" in line
    assert not (tmp_path / "nowhere").exists()


def test_run_file_symlink_to_an_existing_run_and_run_dir_a_dangling_link(tmp_path, monkeypatch, capsys):
    src = tmp_path / "src.h5"
    src.write_bytes(b"a run file")
    (tmp_path / "y").mkdir()
    (tmp_path / "y" / "run.h5").symlink_to(src)
    line = _refused([f"hydra.run.dir={tmp_path}/y"], tmp_path, monkeypatch, capsys, "hydra.run.dir")
    assert "is a symbolic link" in line and src.read_bytes() == b"a run file"
    (tmp_path / "z").symlink_to(tmp_path / "nowhere")
    line = _refused([f"hydra.run.dir={tmp_path}/z"], tmp_path, monkeypatch, capsys, "hydra.run.dir")
    assert "dangling symbolic link" in line and not (tmp_path / "nowhere").exists()


def test_threads_from_a_missing_launcher_key(tmp_path, monkeypatch, capsys):
    line = _refused(["threads=${hydra:launcher.cpus_per_task}"], tmp_path, monkeypatch, capsys, "threads")
    assert "hydra.launcher.cpus_per_task does not exist" in line
    line = _refused(["threads=${oc.env:HIGBENCH_NO_SUCH_VARIABLE}"], tmp_path, monkeypatch, capsys, "threads")
    assert "cannot be resolved" in line


def test_threads_from_a_launcher_that_has_the_key():
    cfg = None
    with initialize_config_dir(config_dir=cli.config_dir(), version_base="1.3"):
        cfg = compose(
            "config", overrides=["hydra/launcher=slurm", "threads=${hydra:launcher.cpus_per_task}"], return_hydra_config=True
        )
    cli.check_hydra_references(cfg)  # exists: accepted (resolved in the job)


# -- 8. smaller ones -------------------------------------------------------------------------


def test_init_from_non_finite_weights_is_refused(tmp_path, monkeypatch, capsys):
    src = tmp_path / "src" / "run.h5"
    train_here(compose_here(["problem=toy", "optimizer=sgd", "budget.max_updates=3", *FAST]), src)
    with h5py.File(src, "r+") as f:
        f["weights/0.weight"][0, 0] = np.nan
    line = _refused(["problem=toy", "optimizer=sgd", f"init_from={src}"], tmp_path, monkeypatch, capsys, "init_from")
    assert "NaN or inf" in line


def test_stale_checkpoint_temporaries_are_removed(tmp_path, monkeypatch):
    run = tmp_path / "r" / "run.h5"
    run.parent.mkdir()
    stale = run.parent / "run.h5.ckpt.tmp99999999"
    stale.write_bytes(b"half a checkpoint")
    stopped_run(run, monkeypatch)  # its checkpoint save cleans up
    assert not stale.exists() and [p.name for p in run.parent.glob("run.h5.ckpt*")] == ["run.h5.ckpt"]


def test_load_updates_of_a_run_without_updates(tmp_path):
    w = RunFileWriter(tmp_path / "run.h5", "a: 1\n", [], env={}, meta={})
    w.append_row("curves", {"step": 0, "test_loss": 1.0})
    w.close("interrupted")
    df = load_updates(tmp_path / "run.h5")
    assert len(df) == 0 and "step" in df and "update_s" in df


def test_index_notes_ragged_curve_columns(tmp_path):
    w = RunFileWriter(tmp_path / "run.h5", "problem: {name: toy}\n", [], env={}, meta={})
    w.append_rows("curves", {"step": [0, 10, 20], "wall_time": [0.0, 1.0, 2.0], "test_loss": [1.0, 0.5, 0.25]})
    w.append_rows("curves", {"step": [30]})  # the writer stopped between columns
    w.close("running")
    row = load_runs(tmp_path).iloc[0]
    assert row["final_test_loss"] == 0.25  # the last row every column holds (step 20), not step 30's
    assert "differ in length" in row["error"] and "step (4)" in row["error"]


def test_fifo_in_runs_tree_does_not_hang_the_figures_index(tmp_path):
    from higbench.jobs import run_index
    from higbench.results.index import one_per_config

    src = tmp_path / "a" / "run.h5"
    train_here(compose_here(["problem=toy", "optimizer=sgd", "budget.max_updates=3", *FAST]), src)
    os.mkfifo(tmp_path / "pipe.h5")
    result = {}
    t = threading.Thread(target=lambda: result.setdefault("index", run_index(tmp_path)), daemon=True)
    t.start()
    t.join(30)
    assert "index" in result, "the figures index hung on a FIFO"
    runs = one_per_config(load_runs(tmp_path))  # the index the figures read
    assert runs["path"].tolist() == [str(src)]
    assert result["index"][runs["config_id"].iloc[0]][0] == src.resolve()
