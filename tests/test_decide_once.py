"""A run is decided once: per run, the network and the optimizer are built once, each input
file is opened once, the front door keeps no module-level mutable state, and importing the
readers registers nothing with Hydra.

Counted by wrapping the constructors and the file opens around in-process runs of the CLI.
"""

from __future__ import annotations

import ast
import collections
import os
import signal
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from higbench import cli
from higbench.problems.base import Problem
from higbench.runner.train import StopSignals

ROOT = Path(__file__).resolve().parent.parent
TINY = ["budget.max_updates=3", "budget.seconds=null", "eval_unit=updates", "eval_every=1", "progress=false"]


@pytest.fixture
def counted(monkeypatch, tmp_path):
    """Runs the CLI here; counts networks, optimizers (outside the config's trial
    construction on a dummy parameter), and opens of each file by name."""
    monkeypatch.chdir(tmp_path)
    counts: collections.Counter = collections.Counter()
    build_model, optimizer_init, h5_init, os_open = (
        Problem.build_model,
        torch.optim.Optimizer.__init__,
        h5py.File.__init__,
        os.open,
    )

    def count_build(self, *a, **k):
        counts["networks"] += 1
        return build_model(self, *a, **k)

    def count_optimizer(self, *a, **k):
        callers = {frame.f_code.co_name for frame in _frames()}
        if "check_optimizer" not in callers:  # validation's trial on a dummy parameter: not the run's
            counts["optimizers"] += 1
        return optimizer_init(self, *a, **k)

    def count_h5(self, name, *a, **k):
        if isinstance(name, (str, os.PathLike)):
            counts[f"h5 {Path(name).resolve().relative_to(tmp_path)}"] += 1
        return h5_init(self, name, *a, **k)

    def count_open(path, *a, **k):
        if str(path).endswith(".ckpt"):
            counts[f"open {Path(path).resolve().relative_to(tmp_path)}"] += 1
        return os_open(path, *a, **k)

    monkeypatch.setattr(Problem, "build_model", count_build)
    monkeypatch.setattr(torch.optim.Optimizer, "__init__", count_optimizer)
    monkeypatch.setattr(h5py.File, "__init__", count_h5)
    monkeypatch.setattr(os, "open", count_open)

    def run(*argv: str) -> collections.Counter:
        counts.clear()
        try:
            cli.main(list(argv))
        except SystemExit as exc:
            assert exc.code in (0, 128 + signal.SIGTERM), exc.code
        return collections.Counter(counts)

    return run


def _frames():
    frame = sys._getframe(1)
    while frame is not None:
        yield frame
        frame = frame.f_back


def test_one_run_builds_its_network_and_optimizer_once(counted):
    counts = counted(*TINY, "problem=toy", "optimizer=hig", "hydra.run.dir=a")
    assert counts["networks"] == 1 and counts["optimizers"] == 1, counts
    # its own run file: written once (the summary lines read what its writer kept as it closed it)
    assert counts["h5 a/run.h5"] == 1, counts


def test_an_init_from_file_is_opened_once(counted):
    counted(*TINY, "problem=toy", "optimizer=adam", "hydra.run.dir=a")
    counts = counted(*TINY, "problem=toy", "optimizer=adam", "hydra.run.dir=b", "init_from=a/run.h5")
    assert counts["h5 a/run.h5"] == 1, counts
    assert counts["networks"] == 1 and counts["optimizers"] == 1, counts


def test_a_resume_reads_its_run_file_and_checkpoint_once(counted, monkeypatch):
    turns = {"n": 0}
    check = StopSignals.check

    def stop_after_three(self):
        turns["n"] += 1
        if turns["n"] == 3:
            self.signum = signal.SIGTERM  # as a SIGTERM between updates: interrupted, checkpointed
        check(self)

    with monkeypatch.context() as m:
        m.setattr(StopSignals, "check", stop_after_three)
        counted("problem=toy", "optimizer=hig", "hydra.run.dir=c", "budget.max_updates=10", "eval_unit=updates", "progress=false")
    counts = counted("resume=c")
    assert counts["open c/run.h5.ckpt"] == 1, counts
    # read once to plan, reopened once by its writer (and not read back for the summary lines)
    assert counts["h5 c/run.h5"] == 2, counts
    assert counts["networks"] == 1 and counts["optimizers"] == 1, counts


def test_the_summary_of_what_the_writer_kept_is_the_closed_file_s(tmp_path):
    """The end-of-run lines read the tables the writer kept as it closed the file: the same row
    as the closed file gives (the index's view)."""
    from higbench.results.index import read_run_summary
    from higbench.runfile.writer import RunFileWriter

    writer = RunFileWriter(tmp_path / "run.h5", "seed: 0\n", [], env={"threads": 1}, meta={"problem": "toy"})
    for step in range(3):
        writer.append_row("curves", {"step": step, "wall_time": 0.5 * step, "test_loss": 1.0 / (step + 1)})
        writer.append_row("updates", {"step": step, "update_s": 0.01, "loss": 1.0})
    writer.write_final({"test_losses": np.array([0.1, 0.3])}, 2)
    writer.close("completed")
    kept, read = (read_run_summary(tmp_path / "run.h5", [0.5], tables=t)[0] for t in (writer.final_tables, None))
    assert writer.final_tables is not None and kept.keys() == read.keys()
    assert all(kept[k] == read[k] or (kept[k] != kept[k] and read[k] != read[k]) for k in read), (kept, read)


FRONT_DOOR = ["cli.py", "preflight.py", "config.py", "schema.py", "errors.py", "jobs", "runner"]
MUTABLE = (ast.List, ast.Dict, ast.Set, ast.ListComp, ast.DictComp, ast.SetComp)


def _module_state(path: Path) -> list[str]:
    """Module-level names bound to mutable containers, and ``global`` statements."""
    tree = ast.parse(path.read_text())
    found = []
    for node in tree.body:
        value = node.value if isinstance(node, (ast.Assign, ast.AnnAssign)) else None
        targets = node.targets if isinstance(node, ast.Assign) else [getattr(node, "target", None)]
        names = [t.id for t in targets if isinstance(t, ast.Name)]
        if isinstance(value, MUTABLE) and names != ["__all__"]:
            found += [f"{path.name}:{node.lineno} {n}" for n in names]
    found += [f"{path.name}:{n.lineno} global {', '.join(n.names)}" for n in ast.walk(tree) if isinstance(n, ast.Global)]
    return found


def test_the_front_door_keeps_no_module_level_mutable_state():
    files = [p for name in FRONT_DOOR for p in sorted((ROOT / "higbench" / name).glob("*.py")) or [ROOT / "higbench" / name]]
    state = [entry for path in files for entry in _module_state(path)]
    assert state == [], state


@pytest.mark.process  # a fresh interpreter: what importing does, before anything else ran
def test_importing_the_readers_registers_nothing_with_hydra():
    probe = (
        "import higbench.results.index, higbench.runner.train, higbench.runner.plan\n"
        "from hydra.core.config_store import ConfigStore\n"
        "from omegaconf import OmegaConf\n"
        "assert 'higbench_schema.yaml' not in ConfigStore.instance().repo\n"
        "assert not OmegaConf.has_resolver('higbench.flat_dirname')\n"
    )
    subprocess.run([sys.executable, "-c", probe], check=True, cwd=ROOT)
