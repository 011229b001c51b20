"""The one helper that runs higbench as a process of its own.

Use it where the process is the point: signals, pipes, concurrent runs, the installed entry
point; mark such a test ``process`` (tests/process_starts.py). Everything else calls the CLI
in this process (the ``higbench`` fixture in tests/conftest.py) or composes configs with
Hydra's compose API (tests/in_process.py).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

CLI = (sys.executable, "-m", "higbench.cli")


def cli_env(*, launcher_threads: bool = False, **extra: str) -> dict[str, str]:
    """The environment of a CLI process: one torch thread unless a sweep's launcher should
    choose (``launcher_threads``: joblib caps its workers' threads), no HYDRA_FULL_ERROR."""
    env = dict(os.environ)
    env.pop("HYDRA_FULL_ERROR", None)
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.pop(var, None)
    if not launcher_threads:
        env["OMP_NUM_THREADS"] = "1"  # 2 shared cores: 2 threads per process oversubscribe them
    env.update(extra)
    return env


def run_cli(
    args: list[str], cwd: Path, *, timeout: float = 180, env: dict | None = None, check: bool = False
) -> subprocess.CompletedProcess:
    """``python -m higbench.cli *args`` in ``cwd``, output captured; ``check``: fail the test
    (with both outputs) unless it exits 0."""
    proc = subprocess.run([*CLI, *args], cwd=cwd, env=env or cli_env(), capture_output=True, text=True, timeout=timeout)
    if check and proc.returncode != 0:
        pytest.fail(
            f"higbench {' '.join(args)} exited {proc.returncode}\nstdout:\n{proc.stdout[-3000:]}\nstderr:\n{proc.stderr[-3000:]}"
        )
    return proc


def start_cli(args: list[str], cwd: Path, *, env: dict | None = None) -> subprocess.Popen:
    """The same, started and left running (to signal it, or to race another)."""
    return subprocess.Popen(
        [*CLI, *args], cwd=cwd, env=env or cli_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
