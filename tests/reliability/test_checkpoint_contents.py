"""A checkpoint is checked whole before anything is written (issue 39, item 4): keys, types,
dtypes, shapes against the network its stored config builds, ranges, and the objects its
pickle may name. Each crafted checkpoint is refused with one line, exit 2, and the run
file's bytes (SHA-256) unchanged; the run can still be resumed from a good checkpoint."""

from __future__ import annotations

import io
import pickle
import shutil
import zipfile
from pathlib import Path

import pytest
import torch
from rel_helpers import FAST, sha256, stopped_run
from test_front_door_security import refused

from higbench import cli
from higbench.runfile.reader import read_head
from higbench.runner import checkpoint


@pytest.fixture(scope="module")
def stopped(tmp_path_factory) -> Path:
    """An interrupted Adam toy run with its checkpoint (made once, copied per case)."""
    run = tmp_path_factory.mktemp("stopped") / "run" / "run.h5"
    run.parent.mkdir()
    with pytest.MonkeyPatch.context() as m:
        stopped_run(run, m)
    return run.parent


def _tamper(state: dict, case: str) -> None:
    model, opt = state["model"], state["optimizer"]
    first = next(iter(model))
    if case == "complex weights":
        model[first] = model[first].to(torch.complex64)
    elif case == "wrong-shaped weights":
        model[first] = torch.zeros(3, 3)
    elif case == "a missing weight":
        del model[first]
    elif case == "negative step":
        state["step"] = -5
    elif case == "step as a string":
        state["step"] = "12"
    elif case == "missing step":
        del state["step"]
    elif case == "a position of 10**12":
        state["position"] = 10**12
    elif case == "rows as a list":
        state["rows"] = [1, 2]
    elif case == "rows with string counts":
        state["rows"] = {g: {n: str(c) for n, c in t.items()} for g, t in state["rows"].items()}
    elif case == "an optimizer state of the wrong shape":
        entry = next(iter(opt["state"].values()))
        entry["exp_avg"] = torch.zeros(5, 5)
    elif case == "a complex optimizer state":
        entry = next(iter(opt["state"].values()))
        entry["exp_avg"] = entry["exp_avg"].to(torch.complex64)
    elif case == "an optimizer hyper-parameter of another kind":
        opt["param_groups"][0]["lr"] = "fast"
    elif case == "an rng state of the wrong type":
        state["torch_rng"] = torch.zeros(3)
    elif case == "a shuffle state of the wrong size":
        state["shuffle_epoch_start"] = torch.zeros(10, dtype=torch.uint8)
    elif case == "a non-finite clock":
        state["wall_time"] = float("inf")
    elif case == "batch losses as a string":
        state["batch_losses"] = "x" * 10
    else:
        raise AssertionError(case)


CASES = [
    "complex weights",
    "wrong-shaped weights",
    "a missing weight",
    "negative step",
    "step as a string",
    "missing step",
    "a position of 10**12",
    "rows as a list",
    "rows with string counts",
    "an optimizer state of the wrong shape",
    "a complex optimizer state",
    "an optimizer hyper-parameter of another kind",
    "an rng state of the wrong type",
    "a shuffle state of the wrong size",
    "a non-finite clock",
    "batch losses as a string",
]


def _copy(stopped: Path, tmp_path: Path) -> Path:
    run_dir = tmp_path / "run"
    shutil.copytree(stopped, run_dir)
    return run_dir


@pytest.mark.parametrize("case", CASES)
def test_a_checkpoint_that_does_not_fit_is_refused_with_the_run_file_unchanged(case, stopped, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    run_dir = _copy(stopped, tmp_path)
    ckpt = checkpoint.checkpoint_path(run_dir / "run.h5")
    state = torch.load(ckpt, weights_only=True)
    _tamper(state, case)
    torch.save(state, ckpt)
    digest = sha256(run_dir / "run.h5")
    line = refused([f"resume={run_dir}", "progress=false", "threads=1"], capsys)
    assert "resume=" in line and "checkpoint" in line, line
    assert sha256(run_dir / "run.h5") == digest
    assert read_head(run_dir / "run.h5").status == "interrupted"


def _with_extra_object(ckpt: Path, payload: bytes) -> None:
    """Replace the archive's pickle by ``payload`` (the tensors' records stay)."""
    original = ckpt.read_bytes()
    with zipfile.ZipFile(io.BytesIO(original)) as src:
        records = [(r, src.read(r)) for r in src.infolist()]
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_STORED) as dst:
        for record, data in records:
            dst.writestr(record, payload if record.filename.endswith("data.pkl") else data)
    ckpt.write_bytes(out.getvalue())


class _Expands:
    """Unpickles as ``bytearray(n)``: a builtin torch's restricted unpickler allows."""

    def __init__(self, n: int):
        self.n = n

    def __reduce__(self):
        return (bytearray, (self.n,))


def test_a_checkpoint_pickle_naming_an_allowed_builtin_is_refused_before_unpickling(stopped, tmp_path, monkeypatch, capsys):
    """133 bytes of pickle made a 1.5 GB bytearray on resume; here a small one: it is refused
    by the names its pickle holds, so its size never matters."""
    monkeypatch.chdir(tmp_path)
    run_dir = _copy(stopped, tmp_path)
    ckpt = checkpoint.checkpoint_path(run_dir / "run.h5")
    bomb = pickle.dumps({"format": 1, "extra": _Expands(1000)}, protocol=2)
    _with_extra_object(ckpt, bomb)
    digest = sha256(run_dir / "run.h5")
    line = refused([f"resume={run_dir}", "progress=false", "threads=1"], capsys)
    assert "bytearray" in line, line
    assert sha256(run_dir / "run.h5") == digest


@pytest.mark.parametrize("tensor", ["meta", "sparse"])
def test_meta_and_sparse_tensors_are_refused_by_name(tensor, stopped, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    run_dir = _copy(stopped, tmp_path)
    ckpt = checkpoint.checkpoint_path(run_dir / "run.h5")
    state = torch.load(ckpt, weights_only=True)
    first = next(iter(state["model"]))
    shape = state["model"][first].shape
    if tensor == "meta":
        state["model"][first] = torch.empty(shape, device="meta")
    else:
        indices = torch.tensor([[0], [10**6]])  # out of range on purpose
        state["model"][first] = torch.sparse_coo_tensor(indices, torch.tensor([1.0]), shape, check_invariants=False)
    torch.save(state, ckpt)
    digest = sha256(run_dir / "run.h5")
    line = refused([f"resume={run_dir}", "progress=false", "threads=1"], capsys)
    assert "refusing to load it" in line, line
    assert sha256(run_dir / "run.h5") == digest


def test_a_good_checkpoint_still_resumes(stopped, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    run_dir = _copy(stopped, tmp_path)
    cli.main([f"resume={run_dir}", "progress=false", "threads=1"])
    assert read_head(run_dir / "run.h5").status == "completed"


SHIPPED = sorted(p.stem for p in (Path(cli.config_dir()) / "optimizer").glob("*.yaml"))
FAST_LAYOUTS = ("muon", "soap")  # checkpoints in layouts other than torch's per-parameter state


@pytest.mark.parametrize("optimizer", [o if o in FAST_LAYOUTS else pytest.param(o, marks=pytest.mark.slow) for o in SHIPPED])
def test_every_shipped_optimizers_checkpoint_passes_the_check(optimizer, tmp_path, monkeypatch):
    """The check refuses what does not fit, never a real checkpoint of a shipped optimizer."""
    from rel_helpers import compose_here, train_here

    run = tmp_path / "run.h5"
    stopped_run(run, monkeypatch, overrides=[f"optimizer={optimizer}"], after=9)
    cfg = compose_here(
        ["problem=toy", f"optimizer={optimizer}", "budget.max_updates=12", "eval_unit=updates", "eval_every=5", *FAST]
    )
    assert train_here(cfg, run, resume=True).status == "completed"
