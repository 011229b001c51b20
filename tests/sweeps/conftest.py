"""Helpers for the sweep tests: the repository, the grid of conf/experiment/toy_lr_grid.yaml."""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[2]  # pytest puts this folder on sys.path for its tests (synthetic.py)

GRID = {(0.01, 64), (0.01, 128), (0.1, 64), (0.1, 128)}  # conf/experiment/toy_lr_grid.yaml
