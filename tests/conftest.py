"""Shared test helpers: run the CLI in a subprocess with tiny budgets, in a tmp dir."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

# A budget of a few updates, one evaluation per update, no progress bar.
TINY = ["budget.max_updates=3", "budget.seconds=null", "eval_unit=updates", "eval_every=1", "progress=false"]


def run_cli(args: list[str], cwd: Path, timeout: float = 180) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), OMP_NUM_THREADS="1")
    return subprocess.run(
        [sys.executable, "-m", "higbench.cli", *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout
    )


@pytest.fixture
def cli(tmp_path):
    """cli(*overrides) -> CompletedProcess, run from a fresh tmp dir (outputs/ lands there)."""

    def _run(*args: str, tiny: bool = True, timeout: float = 180):
        flags = [a for a in args if a.startswith("-")]  # Hydra's flags (-m) before the overrides
        overrides = [a for a in args if not a.startswith("-")]
        return run_cli([*flags, *(TINY if tiny else []), *overrides], cwd=tmp_path, timeout=timeout)

    return _run
