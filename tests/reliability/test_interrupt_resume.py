"""SIGINT / SIGTERM / SIGKILL in the middle of a run, then resume: nothing lost, nothing twice.

Three runs go at once and are stopped by a signal each once their files hold curve rows:
SIGINT and SIGKILL hit CLI subprocesses, SIGTERM hits a run trained in this process (the
same handler; it keeps the suite fast). SIGINT and SIGTERM must close the file cleanly
(status interrupted, checkpoint saved; the CLI exits 128+signal); SIGKILL leaves a file
that is readable up to its last flush and says ``running``. Then, again at once: the
SIGKILLed run (Adam: optimizer state, data order and RNG must all be restored) is resumed
through the CLI (``resume=true hydra.run.dir=...``) and compared update by update with an
uninterrupted reference run of the same config, trained here meanwhile; the SIGTERMed run
(HIG) is resumed here, from its stored config as the CLI does.
"""

from __future__ import annotations

import os
import signal
import threading
import time

import h5py
import numpy as np
import pytest
import torch
import yaml
from hydra.core.global_hydra import GlobalHydra
from omegaconf import OmegaConf
from rel_helpers import FAST, compose_here, start_cli, table_rows, train_here, wait_for_rows

from higbench import cli
from higbench.config import ConfigError, to_plain
from higbench.runfile.reader import load_run, load_updates, load_weights
from higbench.runfile.writer import RunFileWriter
from higbench.runner.checkpoint import checkpoint_path
from higbench.runner.stored import resume_config

pytestmark = pytest.mark.process  # SIGINT and SIGKILL to CLI processes, a resume through the CLI

VICTIM = ["problem=toy", "budget.seconds=30", "eval_unit=updates", "eval_every=5", "checkpoint_every=0.3", *FAST]
RUNS = {
    "sigint": (["optimizer=sgd"], signal.SIGINT),
    "sigterm": (["optimizer=hig"], signal.SIGTERM),
    "sigkill": (["optimizer=adam"], signal.SIGKILL),
}


def ckpt_state(run_file):
    return torch.load(checkpoint_path(run_file), map_location="cpu", weights_only=False)


def finish(proc, timeout=120):
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, err


def assert_continuous(run_file, last_step):
    """Curves and updates strictly increasing in step and time, every update exactly once."""
    meta, curves = load_run(run_file)
    assert meta["status"] == "completed", (meta["status"], meta["status_reason"])
    assert curves["step"].is_unique and curves["step"].is_monotonic_increasing, curves["step"].tolist()
    assert curves["wall_time"].is_monotonic_increasing and curves["wall_time"].is_unique
    assert curves["step"].iloc[-1] == last_step
    updates = load_updates(run_file)
    assert updates["step"].tolist() == list(range(1, last_step + 1)), "an update lost or written twice"
    assert updates["wall_time"].is_monotonic_increasing
    assert not checkpoint_path(run_file).exists(), "a finished run keeps no checkpoint"
    return meta, curves, updates


def sigterm_self_after_rows(n, monkeypatch):
    """Send SIGTERM to this process once the run trained here has written ``n`` curve rows.

    (A file being written cannot be opened a second time by the same process, so the rows
    are counted by wrapping the writer's append_row.)"""
    rows = {"curves": 0}
    real = RunFileWriter.append_row

    def counting(self, group, row):
        real(self, group, row)
        if group == "curves":
            rows["curves"] += 1
            if rows["curves"] == n:
                threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGTERM)).start()  # asynchronously, mid-loop

    monkeypatch.setattr(RunFileWriter, "append_row", counting)
    return rows


def freeze_with_rows_beyond_its_checkpoint(proc, run_file, tries: int = 50) -> None:
    """Leave ``proc`` stopped (SIGSTOP) at a moment when its run file holds curve rows beyond
    its last checkpoint's, judged from the files while it is stopped, so no checkpoint can land
    between the check and the kill (under load one did: the kill then found none beyond it).
    A checkpoint is replaced atomically, so reading it while the writer is stopped is safe."""
    for _ in range(tries):
        t_end = time.monotonic() + 60
        while not checkpoint_path(run_file).exists() and time.monotonic() < t_end and proc.poll() is None:
            time.sleep(0.05)
        assert checkpoint_path(run_file).exists(), "no checkpoint was written"
        wait_for_rows(run_file, ckpt_state(run_file)["rows"]["curves"]["step"] + 3, proc, timeout=60)
        proc.send_signal(signal.SIGSTOP)
        if table_rows(run_file) > ckpt_state(run_file)["rows"]["curves"]["step"]:
            return
        proc.send_signal(signal.SIGCONT)  # a checkpoint caught up meanwhile: wait for rows beyond it
    pytest.fail(f"{run_file}: never caught with rows beyond its checkpoint in {tries} tries")


@pytest.fixture(scope="module")
def stopped(tmp_path_factory):
    """The three victims, each stopped by its signal mid-run."""
    root = tmp_path_factory.mktemp("signals")
    procs = {
        name: start_cli([*VICTIM, *RUNS[name][0], f"hydra.run.dir={root / name}"], cwd=root) for name in ("sigint", "sigkill")
    }
    seen, results = {}, {}
    try:
        # SIGTERM, in this process: the handler turns it into a clean stop
        run_file = root / "sigterm" / "run.h5"
        handler = signal.getsignal(signal.SIGTERM)
        with pytest.MonkeyPatch.context() as mp:
            sigterm_self_after_rows(4, mp)
            summary = train_here(compose_here([*VICTIM, *RUNS["sigterm"][0]]), run_file)
        seen["sigterm"] = 4
        results["sigterm"] = summary
        results["handler_restored"] = signal.getsignal(signal.SIGTERM) == handler
        for name in ("sigint", "sigkill"):
            run_file = root / name / "run.h5"
            wait_for_rows(run_file, 4, procs[name], timeout=90)
            if name == "sigkill":  # kill after a checkpoint, with rows written after it (resume must cut them)
                freeze_with_rows_beyond_its_checkpoint(procs[name], run_file)
            if name == "sigkill":  # resuming a run that is still going is refused
                try:
                    cli.precheck([f"resume={root / name}"])
                    results["resume_live"] = "accepted"
                except ConfigError as exc:
                    results["resume_live"] = str(exc)
                finally:
                    GlobalHydra.instance().clear()
            seen[name] = table_rows(run_file)
            procs[name].send_signal(RUNS[name][1])
        results.update({name: finish(p) for name, p in procs.items()})
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.kill()
    return root, seen, results


@pytest.mark.parametrize("name", ["sigint", "sigterm"])
def test_sigint_sigterm_close_the_file_cleanly(stopped, name):
    root, seen, results = stopped
    sig = RUNS[name][1]
    if name == "sigterm":
        summary = results[name]
        assert summary.status == "interrupted" and summary.reason == "SIGTERM", summary
        assert results["handler_restored"], "train() must put the previous SIGTERM handler back"
    else:
        rc, out, err = results[name]
        assert rc == 128 + sig, (rc, out, err)
        assert out.startswith("interrupted:") and f"resume with: higbench resume={root / name}" in err, (out, err)
    run_file = root / name / "run.h5"
    meta, curves = load_run(run_file)
    assert meta["status"] == "interrupted" and sig.name in meta["status_reason"], meta
    assert meta["finished"] and meta["steps"] == meta["status_step"] > 0
    assert len(curves) >= seen[name], "rows seen before the signal were lost"
    assert curves["step"].is_unique and curves["step"].is_monotonic_increasing
    assert len(load_weights(run_file)) == 4
    if name == "sigint":  # the summary's final test loss is the file's last evaluation, and says its step
        assert f"final test loss {curves['test_loss'].iloc[-1]:.4e}" in out, out
        last = int(curves["step"].iloc[-1])
        assert last == meta["steps"] or f"(last evaluated at step {last})" in out, out
    state = ckpt_state(run_file)  # a clean stop saves a checkpoint at the very step it stopped
    assert state["step"] == meta["steps"]
    assert load_updates(run_file)["step"].tolist() == list(range(1, meta["steps"] + 1))


def test_sigkill_leaves_a_readable_running_file(stopped):
    root, seen, results = stopped
    rc, _, _ = results["sigkill"]
    assert rc == -signal.SIGKILL
    run_file = root / "sigkill" / "run.h5"
    meta, curves = load_run(run_file)  # readable without any repair
    assert meta["status"] == "running" and "finished" not in meta
    assert len(curves) >= seen["sigkill"], "rows flushed before the kill were lost"
    assert curves["step"].is_monotonic_increasing
    state = ckpt_state(run_file)
    assert len(curves) > state["rows"]["curves"]["step"], "the kill should land after rows beyond the checkpoint"
    assert "open in another process" in results["resume_live"], results["resume_live"]
    index = pytest.importorskip("higbench.results.index")
    runs = index.load_runs(root)
    status = {p.split("/")[-2]: s for p, s in zip(runs["path"], runs["status"])}
    assert status == {"sigint": "interrupted", "sigterm": "interrupted", "sigkill": "running"}


@pytest.fixture(scope="module")
def resumed(stopped):
    root, _, _ = stopped
    k_state = ckpt_state(root / "sigkill" / "run.h5")
    k_last = k_state["step"] + 30
    t_state = ckpt_state(root / "sigterm" / "run.h5")
    t_last = t_state["step"] + 15
    # through the CLI, with more updates than the budget allowed so far (budget keys may change)
    proc = start_cli(["resume=true", f"hydra.run.dir={root / 'sigkill'}", f"budget.max_updates={k_last}", *FAST], cwd=root)
    try:
        # meanwhile, here: the same experiment never interrupted, and the SIGTERMed run resumed
        train_here(compose_here([*VICTIM, *RUNS["sigkill"][0], f"budget.max_updates={k_last}"]), root / "reference" / "run.h5")
        sigterm_file = root / "sigterm" / "run.h5"
        overrides = [f"resume={root / 'sigterm'}", f"budget.max_updates={t_last}"]
        with h5py.File(sigterm_file, "r") as f:
            stored = yaml.safe_load(f.attrs["config"])
        merged = resume_config(stored, to_plain(compose_here(overrides)), overrides)
        train_here(OmegaConf.create(merged), sigterm_file, overrides=overrides, resume=True)
        results = {"sigkill": finish(proc)}
    finally:
        if proc.poll() is None:
            proc.kill()
    return root, results, {"sigkill": (k_state, k_last), "sigterm": (t_state, t_last)}


def test_resume_after_sigkill_continues_the_run_exactly(resumed):
    root, results, states = resumed
    assert results["sigkill"][0] == 0, results["sigkill"]
    state, last = states["sigkill"]
    meta, curves, updates = assert_continuous(root / "sigkill" / "run.h5", last)
    assert [r["from_step"] for r in meta["resumes"]] == [state["step"]]
    # the resumed part starts where the checkpoint was, on its clock
    after = curves[curves["step"] > state["step"]]
    assert len(after) > 0 and after["wall_time"].iloc[0] > state["wall_time"]
    assert updates[updates["step"] > state["step"]]["wall_time"].iloc[0] >= state["wall_time"]
    # weights, Adam moments, data order and RNG restored: the same losses as never stopped
    _, ref_curves, ref_updates = assert_continuous(root / "reference" / "run.h5", last)
    np.testing.assert_allclose(updates["loss"].to_numpy(), ref_updates["loss"].to_numpy(), rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(curves["test_loss"].iloc[-1], ref_curves["test_loss"].iloc[-1], rtol=1e-4)
    # the original Hydra files of the run are kept; the resume's go to .hydra/resume-*
    assert (root / "sigkill" / ".hydra" / "config.yaml").read_text().count("resume: null") == 1
    assert len(list((root / "sigkill" / ".hydra").glob("resume-*/config.yaml"))) == 1


def test_resume_after_sigterm(resumed):
    root, _, states = resumed
    state, last = states["sigterm"]
    meta, curves, _ = assert_continuous(root / "sigterm" / "run.h5", last)
    assert meta["resumes"][0]["from_step"] == state["step"]
    assert meta["config"]["budget"]["max_updates"] == last and meta["config"]["optimizer"]["name"] == "hig"
