"""Helpers for the sweep tests: run the CLI as a subprocess with a tiny budget, in tmp dirs."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]  # pytest puts this folder on sys.path for its tests (synthetic.py)

# Three updates of the toy problem, an evaluation after each: a job takes well under a second
# once Python and torch are up.
TINY = ["budget.max_updates=3", "budget.seconds=null", "eval_unit=updates", "eval_every=1", "progress=false", "problem=toy"]
GRID = {(0.01, 64), (0.01, 128), (0.1, 64), (0.1, 128)}  # conf/experiment/toy_lr_grid.yaml


def cli_env(**extra: str) -> dict[str, str]:
    env = dict(os.environ)
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):  # let the launcher decide (joblib caps them)
        env.pop(var, None)
    env.update(extra)
    return env


def cli_command(*args: str) -> list[str]:
    return [sys.executable, "-m", "higbench.cli", *args]


def run_cli(*args: str, cwd: Path, timeout: float = 180) -> subprocess.CompletedProcess:
    proc = subprocess.run(cli_command(*args), cwd=cwd, env=cli_env(), capture_output=True, text=True, timeout=timeout)
    if proc.returncode != 0:
        pytest.fail(
            f"higbench {' '.join(args)} exited {proc.returncode}\nstdout:\n{proc.stdout[-3000:]}\nstderr:\n{proc.stderr[-3000:]}"
        )
    return proc
