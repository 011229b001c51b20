"""Helpers of the fault-injection suite (tests/reliability): train in this process, watch a run file; the
CLI as a process comes from tests/cli_runner.py."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import h5py
import pytest
from cli_runner import cli_env, run_cli, start_cli  # noqa: F401  (the one process runner, re-exported)
from in_process import compose_here, train_here  # noqa: F401  (re-exported)

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


def sha256(path: Path) -> str:
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def stopped_run(path: Path, monkeypatch, overrides=(), after: int = 25):
    """A run trained here and stopped cleanly (as by SIGTERM) after ``after`` loop turns:
    status interrupted, checkpoint saved next to it."""
    from higbench.runner.checkpoint import checkpoint_path

    with monkeypatch.context() as m:
        stop_after(m, after)
        cfg = compose_here(
            ["problem=toy", "optimizer=adam", "budget.max_updates=1000", "eval_unit=updates", "eval_every=5", *FAST, *overrides]
        )
        summary = train_here(cfg, path)
    assert summary.status == "interrupted" and checkpoint_path(path).is_file()
    return summary


def stop_after(monkeypatch, turns: int) -> None:
    """The run stops cleanly after ``turns`` loop turns, as on SIGTERM (checkpoint, status
    interrupted): the runner's own stop path, no timed signal."""
    import signal

    from higbench.runner.train import StopSignals

    calls = {"n": 0}
    original = StopSignals.check

    def check(self):
        calls["n"] += 1
        if calls["n"] == turns:
            self.signum = signal.SIGTERM
        original(self)

    monkeypatch.setattr(StopSignals, "check", check)


def refused(argv: list[str], capsys) -> str:
    """Run ``higbench argv`` in-process: it must exit 2 with one line; the line."""
    from higbench import cli

    with pytest.raises(SystemExit) as info:
        cli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert info.value.code == 2 and len(err) == 1 and err[0].startswith("higbench: error: "), err
    return err[0]
