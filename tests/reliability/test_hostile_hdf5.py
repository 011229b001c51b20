"""Run files with content no run file has, written by somebody else into a shared tree:
storage or links that leave the file, a YAML alias bomb as the stored config, weights that
are not arrays of real numbers. Every reader path refuses them (``init_from=``, ``resume=``,
``load_runs(curves=True)``, ``load_run``/``load_weights``) with one line or a ``corrupt`` row;
nothing of another file is ever returned, no run file changes.
"""

from __future__ import annotations

import os
import shutil
import textwrap
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from in_process import memory_cap
from rel_helpers import FAST, compose_here, sha256, stopped_run, train_here

from higbench import cli
from higbench.results.index import load_runs
from higbench.runfile.reader import UnreadableRunFile, load_run, load_weights

SECRET = np.arange(1, 11, dtype=np.float64) * 1111.0  # the other file's bytes, never to be seen


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    root = tmp_path_factory.mktemp("hostile")
    done = root / "done" / "run.h5"
    train_here(compose_here(["problem=toy", "optimizer=sgd", "budget.max_updates=3", *FAST]), done)
    with pytest.MonkeyPatch.context() as mp:
        stopped_run(root / "stopped" / "run.h5", mp, after=12)
    secret = root / "secret.bin"
    secret.write_bytes(np.tile(SECRET, 1000).tobytes())
    return root, done, root / "stopped"


def copy_run(src: Path, dst_dir: Path) -> Path:
    shutil.copytree(src.parent if src.suffix == ".h5" else src, dst_dir)
    return dst_dir / "run.h5"


def replace(f: h5py.File, name: str, make) -> None:
    """Replace dataset ``name`` by what ``make(group, leaf, shape, dtype)`` creates."""
    group, leaf = f[name].parent, name.rsplit("/", 1)[-1]
    shape, dtype = f[name].shape, f[name].dtype
    del f[name]
    make(group, leaf, shape, dtype)


def external_storage(secret: Path):
    def make(g, leaf, shape, dtype):
        g.create_dataset(leaf, shape=shape, dtype="f8", external=[(str(secret), 0, int(np.prod(shape)) * 8)])

    return make


def virtual(other: Path):
    def make(g, leaf, shape, dtype):
        layout = h5py.VirtualLayout(shape=shape, dtype="f8")
        layout[...] = h5py.VirtualSource(str(other), "curves/test_loss", shape=shape)
        g.create_virtual_dataset(leaf, layout)

    return make


def external_link(other: Path):
    def make(g, leaf, shape, dtype):
        g[leaf] = h5py.ExternalLink(str(other), f"{g.name}/{leaf}")

    return make


def soft_link(g, leaf, shape, dtype):
    g[leaf] = h5py.SoftLink(f"{g.name}/step" if "curves" in g.name else "/curves/step")


def one_error_line(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("higbench: error: "), err
    return lines[0]


def refused(args, cwd, monkeypatch, capsys, key) -> str:
    monkeypatch.chdir(cwd)
    monkeypatch.setattr(cli, "_run_job", lambda cfg: pytest.fail("reached the job"))
    with pytest.raises(SystemExit) as info:
        cli.main(list(args))
    line = one_error_line(capsys.readouterr().err)
    assert info.value.code == 2 and f"{key}=" in line, line
    assert list(Path(cwd).iterdir()) == [], "something was written"
    return line


KINDS = ["external", "virtual", "external_link", "soft_link"]


def hostile(kind: str, root: Path):
    other_run = root / "done" / "run.h5"
    return {
        "external": external_storage(root / "secret.bin"),
        "virtual": virtual(other_run),
        "external_link": external_link(other_run),
        "soft_link": soft_link,
    }[kind]


@pytest.mark.parametrize("kind", KINDS)
def test_init_from_refuses_weights_from_elsewhere(sources, tmp_path, monkeypatch, capsys, kind):
    root, done, _ = sources
    src = copy_run(done, tmp_path / "src")
    with h5py.File(src, "r+") as f:
        replace(f, "weights/0.weight", hostile(kind, root))
    before = sha256(src)
    work = tmp_path / "work"
    work.mkdir()
    line = refused(["problem=toy", "optimizer=sgd", f"init_from={src}"], work, monkeypatch, capsys, "init_from")
    assert "0.weight" in line, line
    with pytest.raises(UnreadableRunFile):
        load_weights(src)
    assert sha256(src) == before


@pytest.mark.parametrize("kind", KINDS)
def test_index_and_loaders_never_return_another_files_bytes(sources, tmp_path, kind):
    root, done, _ = sources
    tree = tmp_path / "tree"
    bad = copy_run(done, tree / "bad")
    copy_run(done, tree / "good")
    with h5py.File(bad, "r+") as f:
        replace(f, "curves/test_loss", hostile(kind, root))
    runs, curves = load_runs(tree, curves=True)
    status = dict(zip(runs["path"].map(lambda p: Path(p).parent.name), runs["status"]))
    assert status == {"bad": "corrupt", "good": "completed"}, runs[["path", "status", "error"]]
    assert "test_loss" in runs.set_index(runs["path"].map(lambda p: Path(p).parent.name)).loc["bad", "error"]
    assert set(curves["path"].map(lambda p: Path(p).parent.name)) == {"good"}
    assert not np.isin(SECRET, curves["test_loss"].to_numpy()).any()
    with pytest.raises(UnreadableRunFile):
        load_run(bad)


@pytest.mark.parametrize("kind", KINDS)
def test_resume_refuses_a_file_with_storage_elsewhere(sources, tmp_path, monkeypatch, capsys, kind):
    root, _, stopped = sources
    run = copy_run(stopped, tmp_path / "run")
    with h5py.File(run, "r+") as f:
        replace(f, "curves/test_loss", hostile(kind, root))
    before = {p.name: sha256(p) for p in run.parent.iterdir()}
    other = {p: sha256(p) for p in (root / "done" / "run.h5", root / "secret.bin")}
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        cli.main([f"resume={run.parent}"])
    line = one_error_line(capsys.readouterr().err)
    assert info.value.code == 2 and "resume=" in line and "test_loss" in line, line
    assert {p.name: sha256(p) for p in run.parent.iterdir()} == before
    assert {p: sha256(p) for p in other} == other


# -- the stored config -----------------------------------------------------------------------

BOMB = textwrap.dedent(
    """\
    a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]
    b: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]
    c: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]
    d: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]
    e: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d]
    f: &f [*e,*e,*e,*e,*e,*e,*e,*e,*e]
    g: &g [*f,*f,*f,*f,*f,*f,*f,*f,*f]
    h: &h [*g,*g,*g,*g,*g,*g,*g,*g,*g]
    i: &i [*h,*h,*h,*h,*h,*h,*h,*h,*h]
    """
)


def test_parse_config_bounds_aliases_and_size():
    from higbench.runfile.reader import parse_config

    assert parse_config("a: &x [1, 2]\nb: *x\n") == {"a": [1, 2], "b": [1, 2]}  # modest aliases are YAML
    for text in (BOMB, "x: " + "y" * (1 << 20), "- 1\n", "a: &a [*a]\n"):
        with pytest.raises(UnreadableRunFile):
            parse_config(text)


def test_alias_bomb_in_the_stored_config_is_a_corrupt_row_at_once(sources, tmp_path):
    """Under a memory cap: before, this took tens of seconds and GBs."""
    root, done, _ = sources
    tree = tmp_path / "tree"
    bad = copy_run(done, tree / "bomb")
    copy_run(done, tree / "good")
    with h5py.File(bad, "r+") as f:
        f.attrs["config"] = f.attrs["config"] + "\n" + BOMB
    t = time.perf_counter()
    with memory_cap():
        runs = load_runs(tree)
    seconds = time.perf_counter() - t
    status = dict(zip([p.split("/")[-2] for p in runs["path"]], runs["status"]))
    assert (status["bomb"], status["good"]) == ("corrupt", "completed") and seconds < 5, (status, seconds)
    with pytest.raises(UnreadableRunFile, match="aliases"):
        load_run(bad)


def test_resume_refuses_an_alias_bomb_config(sources, tmp_path, monkeypatch, capsys):
    """Through the CLI, under a memory cap (before: GBs, minutes)."""
    root, _, stopped = sources
    run = copy_run(stopped, tmp_path / "run")
    with h5py.File(run, "r+") as f:
        f.attrs["config"] = f.attrs["config"] + "\n" + BOMB
    before = sha256(run)
    monkeypatch.chdir(tmp_path)
    t = time.perf_counter()
    with memory_cap(), pytest.raises(SystemExit) as info:
        cli.main([f"resume={run.parent}"])
    line = one_error_line(capsys.readouterr().err)
    assert info.value.code == 2 and "resume=" in line and "aliases" in line, line
    assert time.perf_counter() - t < 60 and sha256(run) == before


# -- weights that are not arrays of real numbers ---------------------------------------------


def as_strings(g, leaf, shape, dtype):
    g.create_dataset(leaf, data=np.array([b"0.5"] * int(np.prod(shape))).reshape(shape))


def as_group(g, leaf, shape, dtype):
    g.create_group(leaf).create_dataset("x", data=np.zeros(shape))


def as_complex(g, leaf, shape, dtype):
    g.create_dataset(leaf, data=np.full(shape, 0.5 + 2j))


def as_huge(g, leaf, shape, dtype):
    g.create_dataset(leaf, shape=(200_000, 200_000), dtype="f8")  # unallocated: 320 GB of fill values


@pytest.mark.parametrize(
    "make, why",
    [(as_strings, "strings"), (as_group, "a group"), (as_complex, "complex"), (as_huge, "declares")],
    ids=["strings", "group", "complex", "unallocated-200000x200000"],
)
def test_init_from_refuses_weights_that_are_not_real_arrays(sources, tmp_path, monkeypatch, capsys, make, why):
    _, done, _ = sources
    src = copy_run(done, tmp_path / "src")
    with h5py.File(src, "r+") as f:
        replace(f, "weights/0.weight", make)
    work = tmp_path / "work"
    work.mkdir()
    t = time.perf_counter()
    line = refused(["problem=toy", "optimizer=sgd", f"init_from={src}"], work, monkeypatch, capsys, "init_from")
    assert why in line and "0.weight" in line, line
    assert time.perf_counter() - t < 30


def test_init_from_refuses_a_diverged_run_with_finite_weights(sources, tmp_path, monkeypatch, capsys):
    _, done, _ = sources
    src = copy_run(done, tmp_path / "src")
    with h5py.File(src, "r+") as f:
        f.attrs["status"] = "diverged"
        f["weights/0.weight"][...] = 1e30  # finite, huge
    work = tmp_path / "work"
    work.mkdir()
    line = refused(["problem=toy", "optimizer=sgd", f"init_from={src}"], work, monkeypatch, capsys, "init_from")
    assert "diverged" in line, line


def test_unreadable_directory_is_a_row_like_an_unreadable_file(sources, tmp_path, monkeypatch):
    _, done, _ = sources
    tree = tmp_path / "tree"
    copy_run(done, tree / "good")
    copy_run(done, tree / "hidden" / "run")
    real = os.scandir

    def scandir(path="."):  # as for a directory without read permission (root reads every one)
        if Path(path) == tree / "hidden":
            raise PermissionError(13, "Permission denied", str(path))
        return real(path)

    monkeypatch.setattr(os, "scandir", scandir)
    runs = load_runs(tree)
    rows = dict(zip(runs["path"], runs["status"]))
    assert rows == {str(tree / "good" / "run.h5"): "completed", str(tree / "hidden"): "corrupt"}, runs[["path", "status"]]
    assert "cannot be read" in runs.set_index("path").loc[str(tree / "hidden"), "error"]
