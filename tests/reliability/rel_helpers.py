"""Helpers of the fault-injection suite (tests/reliability): train in this process, watch a run file; the
CLI as a process comes from tests/cli_runner.py."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import h5py
import pytest
from cli_runner import cli_env, run_cli, start_cli  # noqa: F401  (the one process runner, re-exported)

REPO = Path(__file__).resolve().parents[2]

# Small, fast runs: one torch thread (the test machine has 2 shared cores; 2 threads per
# process oversubscribe it 20x), no progress bar.
FAST = ["threads=1", "progress=false"]


def table_rows(path: Path, group: str = "curves") -> int:
    """Rows of a table of a run file that may be being written (0 if not readable yet)."""
    try:
        with h5py.File(path, "r", locking=False) as f:
            if group not in f or "step" not in f[group]:
                return 0
            return int(f[group]["step"].shape[0])
    except (OSError, KeyError, RuntimeError):  # RuntimeError: h5py read metadata torn by the live writer
        return 0


def wait_for_rows(path: Path, n: int, proc: subprocess.Popen | None = None, timeout: float = 60, group: str = "curves") -> int:
    """Wait until ``path`` has at least ``n`` rows in ``group`` (fails if the process ends first)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        rows = table_rows(path, group)
        if rows >= n:
            return rows
        if proc is not None and proc.poll() is not None:
            out, err = proc.communicate()
            pytest.fail(f"process ended (rc {proc.returncode}) before {path} had {n} {group} rows:\n{out}\n{err}")
        time.sleep(0.05)
    pytest.fail(f"{path} did not reach {n} {group} rows in {timeout}s")


def files_under(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


def compose_here(overrides):
    """The config ``higbench <overrides>`` would run, composed in-process (no Hydra run dir)."""
    from hydra import compose, initialize_config_dir

    from higbench import cli

    with initialize_config_dir(config_dir=cli.config_dir(), version_base="1.3"):
        return compose("config", overrides=list(overrides))


def train_here(cfg, path, **kwargs):
    """``train`` in this process, restoring torch's thread count (a run sets its own)."""
    import torch

    from higbench.runner.plan import Plan
    from higbench.runner.train import train

    threads = torch.get_num_threads()
    try:
        return train(Plan.for_run(cfg, path, **kwargs))
    finally:
        torch.set_num_threads(threads)


def sha256(path: Path) -> str:
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def stopped_run(path: Path, monkeypatch, overrides=(), after: int = 25):
    """A run trained here and stopped cleanly (as by SIGTERM) after ``after`` loop turns:
    status interrupted, checkpoint saved next to it."""
    import signal

    from higbench.runner.checkpoint import checkpoint_path
    from higbench.runner.train import StopSignals

    calls = {"n": 0}
    original = StopSignals.check

    def check(self):
        calls["n"] += 1
        if calls["n"] == after:
            self.signum = signal.SIGTERM
        original(self)

    with monkeypatch.context() as m:
        m.setattr(StopSignals, "check", check)
        cfg = compose_here(
            ["problem=toy", "optimizer=adam", "budget.max_updates=1000", "eval_unit=updates", "eval_every=5", *FAST, *overrides]
        )
        summary = train_here(cfg, path)
    assert summary.status == "interrupted" and checkpoint_path(path).is_file()
    return summary
