"""Hostile HDF5 structure (issue 39, item 5): depth, object count and declared bytes are
bounded before anything is read, so such a file is a ``corrupt`` row (the other runs are
still listed) or one line for ``init_from=``; weights in another byte order are read."""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from rel_helpers import FAST, compose_here, sha256, train_here
from test_front_door_security import refused

from higbench.runfile.reader import MAX_DEPTH, MAX_OBJECTS, UnreadableRunFile, load_weights, read_head


@pytest.fixture(scope="module")
def done(tmp_path_factory) -> Path:
    run = tmp_path_factory.mktemp("structure") / "done" / "run.h5"
    train_here(compose_here(["problem=toy", "optimizer=sgd", "budget.max_updates=3", *FAST]), run)
    return run


def _copy(done: Path, to: Path) -> Path:
    shutil.copytree(done.parent, to)
    return to / "run.h5"


def _nest(path: Path, depth: int) -> None:
    with h5py.File(path, "a") as f:
        g = f["logs"]
        for _ in range(depth):
            g = g.create_group("g")


def _many(path: Path, n: int) -> None:
    with h5py.File(path, "a") as f:
        g = f.create_group("extra")
        for i in range(n):
            g.create_group(str(i))


def _inflated(path: Path) -> None:
    """Every column the index reads becomes 16 MB of compressed zeros: each within the
    per-dataset bound (about 1,000x its bytes), together far more than the file."""
    with h5py.File(path, "a") as f:
        for group in ("curves", "updates"):
            for name in list(f[group]):
                del f[group][name]
                ds = f[group].create_dataset(name, shape=(2_000_000,), dtype="f8", compression="gzip", chunks=(500_000,))
                ds[:] = 0.0


def index_lines(tree: Path) -> list[str]:
    """``load_runs`` of the tree, one line per run: its folder, status and error (in this
    process: a C stack overflow in HDF5's visit, as once, ends the test session loudly)."""
    from higbench.results.index import load_runs

    runs = load_runs(tree)
    return [f"{row['path'].split('/')[-2]} {row['status']} | {row['error']}" for _, row in runs.sort_values("path").iterrows()]


@pytest.mark.parametrize("shape", ["10000 nested groups", "30000 groups", "inflated columns"])
def test_a_hostile_structure_is_a_corrupt_row_and_the_other_runs_are_listed(shape, done, tmp_path):
    tree = tmp_path / "tree"
    _copy(done, tree / "good")
    hostile = _copy(done, tree / "hostile")
    if shape == "10000 nested groups":
        _nest(hostile, 10_000)  # HDF5's recursive visit overflowed the C stack here (rc 139)
    elif shape == "30000 groups":
        _many(hostile, MAX_OBJECTS + 10_000)
    else:
        _inflated(hostile)
    lines = index_lines(tree)
    assert lines[0].startswith("good completed"), lines
    assert lines[1].startswith("hostile corrupt"), lines
    why = {"10000 nested groups": f"more than {MAX_DEPTH} levels", "30000 groups": "objects", "inflated columns": "declare"}
    assert why[shape] in lines[1], lines


def test_init_from_a_deeply_nested_file_is_one_line(done, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    hostile = _copy(done, tmp_path / "hostile")
    _nest(hostile, 10_000)
    digest = sha256(hostile)
    with pytest.raises(UnreadableRunFile, match="levels deep"):
        read_head(hostile)
    line = refused(["problem=toy", "optimizer=sgd", f"init_from={hostile}", *FAST, f"hydra.run.dir={tmp_path / 'new'}"], capsys)
    assert "init_from=" in line and "levels deep" in line, line
    assert sha256(hostile) == digest and not (tmp_path / "new").exists()


def test_big_endian_weights_start_a_run(done, tmp_path, monkeypatch):
    """Weights another tool stored big-endian are read in this machine's order (torch takes no other)."""
    monkeypatch.chdir(tmp_path)
    other = _copy(done, tmp_path / "other")
    with h5py.File(other, "a") as f:
        for name in list(f["weights"]):
            values = f["weights"][name][()]
            del f["weights"][name]
            f["weights"].create_dataset(name, data=values.astype(values.dtype.newbyteorder(">")))
    weights = load_weights(other)
    assert all(w.dtype.isnative for w in weights.values())
    np.testing.assert_array_equal(next(iter(weights.values())), next(iter(load_weights(done).values())))
    from higbench import cli

    cli.main(["problem=toy", "optimizer=sgd", f"init_from={other}", "budget.max_updates=2", *FAST, "hydra.run.dir=new"])
    assert read_head(tmp_path / "new" / "run.h5").status == "completed"
