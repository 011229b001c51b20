"""Helpers for the sweep tests: run the CLI as a subprocess with a tiny budget, in tmp dirs."""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[2]  # pytest puts this folder on sys.path for its tests (synthetic.py)

# Three updates of the toy problem, an evaluation after each: a job takes well under a second
# once Python and torch are up.
TINY = ["budget.max_updates=3", "budget.seconds=null", "eval_unit=updates", "eval_every=1", "progress=false", "problem=toy"]
GRID = {(0.01, 64), (0.01, 128), (0.1, 64), (0.1, 128)}  # conf/experiment/toy_lr_grid.yaml
