"""Crash-safe files: writers killed mid-write, truncated and garbage files in an outputs
tree, a corrupt checkpoint. Readers never crash; what was flushed is never lost."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir
from rel_helpers import FAST, REPO, cli_env

from higbench import cli
from higbench.runfile.reader import load_run, load_updates
from higbench.runner.checkpoint import checkpoint_path
from higbench.runner.plan import Plan
from higbench.runner.train import train

# A writer that appends and flushes as the runner does at each evaluation (a burst of
# appends, one flush, then "training" for a while), and prints how many rows each flush
# made durable; it is killed at some moment of its loop, during a burst or between.
# (HDF5 without SWMR has no atomic flush: a kill inside a flush that allocates new file
# space can leave the newest chunk unreadable. Measured with a writer that does nothing but
# append and flush: 1 of 150 kills. See higbench/runfile/writer.py.)
WRITER = """
import sys, time, numpy as np
from higbench.runfile.writer import RunFileWriter
w = RunFileWriter(sys.argv[1], "problem: {name: toy}\\n", [], env={"host": "x"}, meta={"problem": "toy", "optimizer": "adam"})
i = 0
while True:
    w.append_row("curves", {"step": i, "epoch": 0, "wall_time": 0.01 * i, "train_loss": 1.0, "test_loss": 1.0 / (i + 1)})
    w.append_row("logs", {"neuron_mean": np.full(7, float(i))})
    w.append_rows("updates", {"step": np.arange(3 * i, 3 * i + 3), "loss": np.ones(3)})
    w.flush()
    print(i + 1, flush=True)
    i += 1
    time.sleep(0.01)
"""


def _train_small(path, *overrides):
    threads = torch.get_num_threads()
    try:
        with initialize_config_dir(config_dir=cli.config_dir(), version_base="1.3"):
            cfg = compose(
                "config",
                overrides=[
                    "budget.max_updates=12",
                    "eval_unit=updates",
                    "eval_every=4",
                    "checkpoint_every=null",
                    *FAST,
                    *overrides,
                ],
            )
        return train(Plan.for_run(cfg, path))
    finally:
        torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def killed_writers(tmp_path_factory):
    """Six writers killed with SIGKILL after different times (all at once, to save time)."""
    root = tmp_path_factory.mktemp("killed")
    delays = [0.3, 0.45, 0.6, 0.75, 0.9, 1.1]
    procs = []
    for i, _ in enumerate(delays):
        path = root / f"w{i}" / "run.h5"
        procs.append(
            (
                path,
                subprocess.Popen(
                    [sys.executable, "-c", WRITER, str(path)], env=cli_env(), cwd=REPO, stdout=subprocess.PIPE, text=True
                ),
            )
        )
    for path, p in procs:  # wait until every writer is writing
        assert p.stdout.readline().strip() == "1", f"writer {path} did not start"
    start = time.monotonic()
    flushed = []
    for (path, p), delay in zip(procs, delays):
        time.sleep(max(0.0, start + delay - time.monotonic()))
        p.send_signal(signal.SIGKILL)
        out, _ = p.communicate()
        lines = ["1", *out.split()]
        flushed.append((path, int(lines[-1])))
    return root, flushed


@pytest.mark.process
@pytest.mark.slow  # known rare failure (see below): kept out of the CI suite, run by `make test-slow`
def test_killed_writer_file_is_readable_up_to_its_last_flush(killed_writers):
    """Plain HDF5 has no atomic flush: a SIGKILL inside a flush that allocates file space
    can leave the newest chunk unreadable ("addr overflow"). Seen in about 1 of 150 kills of
    a writer that only appends and flushes, and once in a CI-like run of this test under
    heavy load (6 kills). Documented in higbench/runfile/writer.py; open issue.
    """
    _, flushed = killed_writers
    for path, n in flushed:
        meta, curves = load_run(path)  # no repair step needed (no h5clear)
        assert meta["status"] == "running", path
        assert len(curves) >= n, f"{path}: {n} rows were flushed, {len(curves)} readable"
        assert curves["step"].tolist()[:n] == list(range(n))
        assert len(load_updates(path)) >= 3 * n
    assert max(n for _, n in flushed) > min(n for _, n in flushed), "kills should land at different points"


def test_index_reports_broken_files_without_crashing(tmp_path):
    from in_process import seen_from_another_process
    from synthetic import write_run

    index = pytest.importorskip("higbench.results.index")
    root = tmp_path / "outputs"
    good = root / "good" / "run.h5"
    _train_small(good, "optimizer=adam")
    data = good.read_bytes()
    broken = {
        "half": data[: len(data) // 2],
        "head": data[:1024],
        "empty": b"",
        "garbage": b"\x89HDF\r\n\x1a\n" + b"\x00garbage" * 100,
    }
    for name, content in broken.items():
        (root / name).mkdir(parents=True)
        (root / name / "run.h5").write_bytes(content)
    # A writer killed in the middle of a burst of appends: the rows since its last flush are
    # partly on disk (what the slow test above makes with real kills, at random moments).
    writer = write_run(tmp_path / "writing" / "run.h5", close=False)
    for i in range(50):
        writer.append_row("curves", {"step": 100 + i, "test_loss": 0.001})
        writer.append_rows("updates", {"step": np.arange(100 + 3 * i, 103 + 3 * i)})
    with seen_from_another_process(writer.f, root / "killed.h5", flush=False):
        pass  # the lock goes with the killed writer
    writer.f.close()

    runs = index.load_runs(root)
    status = {str(p).replace(str(root) + "/", ""): s for p, s in zip(runs["path"], runs["status"])}
    assert status["good/run.h5"] == "completed"
    assert status["killed.h5"] == "running", "a killed run must never look completed"
    for name in broken:
        assert status[f"{name}/run.h5"] not in ("completed", "diverged", "interrupted"), (name, status)
        row = runs[runs["path"].astype(str).str.endswith(f"{name}/run.h5")].iloc[0]
        assert row["error"], name
    assert list(index.best_runs(runs, by="problem.name")["path"].astype(str)) == [str(good)]
    for name in broken:  # the plain loader refuses them with an error, it does not crash Python
        with pytest.raises(OSError):
            load_run(root / name / "run.h5")


def test_corrupt_checkpoint_is_refused_and_run_kept(tmp_path, monkeypatch, capsys):
    run_dir = tmp_path / "run"
    run_file = run_dir / "run.h5"
    _train_small(run_file, "optimizer=adam")
    # make it look interrupted with a half-written checkpoint next to it
    import h5py

    with h5py.File(run_file, "r+") as f:
        f.attrs["status"] = "interrupted"
    checkpoint_path(run_file).write_bytes(b"PK\x03\x04 truncated")
    before = run_file.read_bytes()
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(cli, "_run_job", lambda cfg: pytest.fail("reached the job"))
    with pytest.raises(SystemExit) as info:
        cli.main([f"resume={run_dir}"])
    err = capsys.readouterr().err
    assert info.value.code == 2 and "resume=" in err and "unreadable" in err, err
    assert run_file.read_bytes() == before
    assert sorted(p.name for p in run_dir.iterdir()) == ["run.h5", "run.h5.ckpt"]


def test_truncated_init_from_is_refused(tmp_path, monkeypatch, capsys):
    src = tmp_path / "src" / "run.h5"
    _train_small(src, "optimizer=adam")
    (tmp_path / "cut.h5").write_bytes(src.read_bytes()[:2048])
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setattr(cli, "_run_job", lambda cfg: pytest.fail("reached the job"))
    with pytest.raises(SystemExit) as info:
        cli.main([f"init_from={tmp_path / 'cut.h5'}"])
    err = capsys.readouterr().err
    assert info.value.code == 2 and "init_from=" in err and "cut.h5" in err and "not a readable run file" in err, err
    assert list(work.iterdir()) == []
