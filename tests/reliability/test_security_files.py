"""Files in a run directory that somebody else wrote (issue: no file can make higbench run
code, overwrite another run or lose a finished one): crafted checkpoints, links planted
where the checkpoint's temporary file goes, a checkpoint or run file that is a link.

Every case checks that no code ran (a marker file an unpickled object would create), that
the run's bytes are unchanged (SHA-256) and that nothing was written outside the run dir.
"""

from __future__ import annotations

import os
import pickle
import shutil
from pathlib import Path

import pytest
import torch
from rel_helpers import compose_here, files_under, sha256, stopped_run, train_here

from higbench import cli
from higbench.errors import ConfigError
from higbench.runfile.reader import load_run


class RunsCode:
    """Unpickling this runs ``exec(source)`` (what a crafted checkpoint would do)."""

    def __init__(self, marker: Path):
        self.source = f"open({str(marker)!r}, 'w').write('ran')"

    def __reduce__(self):
        return (exec, (self.source,))


def one_error_line(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("higbench: error: "), err
    return lines[0]


@pytest.fixture(scope="module")
def stopped(tmp_path_factory):
    """One interrupted run with its checkpoint, copied fresh for each case."""
    root = tmp_path_factory.mktemp("stopped")
    with pytest.MonkeyPatch.context() as mp:
        stopped_run(root / "run" / "run.h5", mp)
    return root / "run"


def crafted(state: dict, marker: Path, kind: str, other: Path) -> Path | None:
    """Write a hostile ``run.h5.ckpt`` of ``kind`` beside ``other``'s run; returns a link target if any."""
    ckpt = other / "run.h5.ckpt"
    evil = RunsCode(marker)
    if kind == "entry":  # the real checkpoint, right run id, one more entry
        torch.save({**state, "note": evil}, ckpt)
    elif kind == "optimizer":  # hidden inside the optimizer's state
        torch.save({**state, "optimizer": {**state["optimizer"], "state": {0: {"exp_avg": evil}}}}, ckpt)
    elif kind == "top":
        torch.save(evil, ckpt)
    elif kind == "legacy":  # torch's pre-zip format
        torch.save({**state, "note": evil}, ckpt, _use_new_zipfile_serialization=False)
    elif kind == "pickle":  # a plain pickle under the checkpoint's name
        ckpt.write_bytes(pickle.dumps(evil))
    elif kind == "link":  # a link to a checkpoint elsewhere
        target = other.parent / f"elsewhere-{other.name}.ckpt"
        torch.save(state, target)
        ckpt.unlink()
        ckpt.symlink_to(target)
        return target
    return None


KINDS = ["entry", "optimizer", "top", "legacy", "pickle", "link"]


@pytest.mark.parametrize("kind", KINDS)
def test_crafted_checkpoint_runs_no_code_and_changes_nothing(stopped, tmp_path, monkeypatch, capsys, kind):
    run_dir = tmp_path / "run"
    shutil.copytree(stopped, run_dir)
    state = torch.load(run_dir / "run.h5.ckpt", weights_only=True)
    marker = tmp_path / "code-ran"
    target = crafted(state, marker, kind, run_dir)
    outside = tmp_path / "outside"
    outside.mkdir()
    before = {p: sha256(p) for p in [*run_dir.iterdir(), *([target] if target else [])] if p.is_file()}
    listing = files_under(run_dir)
    monkeypatch.chdir(outside)
    for value in (str(run_dir), str(run_dir / "run.h5")):
        with pytest.raises(SystemExit) as info:
            cli.main([f"resume={value}"])
        line = one_error_line(capsys.readouterr().err)
        assert info.value.code == 2, line
        assert "resume=" in line and "run.h5.ckpt" in line, line
    with pytest.raises(ConfigError):  # the in-job path (a sweep job) refuses too
        train_here(compose_here([]), run_dir / "run.h5", resume=True)
    assert not marker.exists(), "a crafted checkpoint ran code"
    assert {p: sha256(p) for p in before} == before and files_under(run_dir) == listing
    assert list(outside.iterdir()) == [], "something was written outside the run dir"
    assert load_run(run_dir / "run.h5")[0]["status"] == "interrupted"


def test_checkpoint_holds_only_tensors_and_containers(stopped):
    """What the runner saves loads with torch's restricted unpickler (nothing else is read)."""
    state = torch.load(stopped / "run.h5.ckpt", weights_only=True)
    assert {"run_id", "rows", "model", "optimizer", "torch_rng", "shuffle_epoch_start"} <= set(state)


def test_checkpoint_is_deserialised_once_per_resume(stopped, tmp_path, monkeypatch):
    """The front door checks the checkpoint and the job continues it: one unpickling."""
    run_dir = tmp_path / "run"
    shutil.copytree(stopped, run_dir)
    calls = []
    real = torch.load
    monkeypatch.setattr(torch, "load", lambda *a, **k: calls.append(k.get("weights_only")) or real(*a, **k))
    monkeypatch.chdir(tmp_path)
    cli.main([f"resume={run_dir}", "budget.max_updates=40", "threads=1", "progress=false"])
    assert calls == [True], calls
    assert load_run(run_dir / "run.h5")[0]["status"] == "completed"


# -- the checkpoint's temporary file ---------------------------------------------------------


def test_links_where_the_temporary_goes_are_never_followed(tmp_path, monkeypatch):
    """Links ``run.h5.ckpt.tmp*`` -> a file outside the run dir (this process's pid and a
    range of others): a run that saves checkpoints leaves the victim's bytes as they were."""
    victim = tmp_path / "victim.bin"
    victim.write_bytes(b"somebody's data\n")
    digest = sha256(victim)
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    names = [f"run.h5.ckpt.tmp{os.getpid()}", *(f"run.h5.ckpt.tmp{n}" for n in range(300, 340))]
    for name in names:
        (run_dir / name).symlink_to(victim)
    stopped_run(run_dir / "run.h5", monkeypatch, ["checkpoint_every=0"], after=12)  # a save per update, then one at the stop
    assert sha256(victim) == digest, "the checkpoint was written through a link"
    assert sorted(p.name for p in run_dir.iterdir()) == ["run.h5", "run.h5.ckpt"]
    assert torch.load(run_dir / "run.h5.ckpt", weights_only=True)["step"] > 0


def test_checkpoint_that_is_a_link_is_replaced_not_written_through(tmp_path, monkeypatch):
    victim = tmp_path / "victim.bin"
    victim.write_bytes(b"somebody's data\n")
    digest = sha256(victim)
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "run.h5.ckpt").symlink_to(victim)  # a new run moves a stray one aside; here train saves over it
    stopped_run(run_dir / "run.h5", monkeypatch, after=12)
    assert sha256(victim) == digest
    assert not (run_dir / "run.h5.ckpt").is_symlink()


def test_resume_refuses_a_run_file_that_is_a_link(tmp_path, monkeypatch, capsys):
    """``resume=E`` with ``E/run.h5 -> other/run.h5`` would continue the other run in E's name."""
    other = tmp_path / "other"
    stopped_run(other / "run.h5", monkeypatch)
    before = {p.name: sha256(p) for p in other.iterdir()}
    e = tmp_path / "e"
    e.mkdir()
    (e / "run.h5").symlink_to(other / "run.h5")
    shutil.copy(other / "run.h5.ckpt", e / "run.h5.ckpt")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        cli.main([f"resume={e}"])
    line = one_error_line(capsys.readouterr().err)
    assert info.value.code == 2 and "symbolic link" in line, line
    assert {p.name: sha256(p) for p in other.iterdir()} == before
    assert sorted(p.name for p in e.iterdir()) == ["run.h5", "run.h5.ckpt"]
