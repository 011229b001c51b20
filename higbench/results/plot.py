"""Plots of your own runs: loss curves over seeds (``--plot``) and performance profiles (``--profile``).

``plot_curves`` takes ``load_runs(root, curves=True)`` with a ``setting`` column
(``profile.setting_labels``); ``plot_profile`` takes ``profile.performance_profile``'s table.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

GRID_POINTS = 200


def seed_band(curves: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(time grid, median, min, max) over runs of (time, loss) curves.

    Each curve is interpolated in log(loss) onto a common grid up to the earliest end among
    the runs, so every point of the band has every seed behind it.
    """
    ends = [t[-1] for t, _ in curves if len(t)]
    grid = np.linspace(0.0, min(ends), GRID_POINTS) if ends else np.empty(0)
    logs = []
    for t, loss in curves:
        ok = np.isfinite(loss) & (loss > 0)
        if ok.sum() < 1:
            continue
        logs.append(np.interp(grid, t[ok], np.log10(loss[ok])))
    if not logs:
        return grid, *(np.full(len(grid), np.nan) for _ in range(3))
    stack = np.vstack(logs)
    return grid, 10 ** np.median(stack, axis=0), 10 ** stack.min(axis=0), 10 ** stack.max(axis=0)


def plot_curves(runs: pd.DataFrame, curves: pd.DataFrame, path: str | Path, setting: str = "setting") -> Path:
    """Test loss against the training clock: one panel per problem, one line per setting
    (median over its seeds) with a band from the lowest to the highest seed; log y."""
    problems = sorted(runs["problem.name"].dropna().unique())
    fig, axes = plt.subplots(1, max(len(problems), 1), figsize=(6.0 * max(len(problems), 1), 4.2), squeeze=False)
    by_path = {p: g for p, g in curves.groupby("path", observed=True)}
    for ax, problem in zip(axes[0], problems):
        group = runs[runs["problem.name"] == problem]
        for name, runs_of_setting in group.groupby(setting, sort=True):
            parts = [
                (c["wall_time"].to_numpy(dtype=float), c["test_loss"].to_numpy(dtype=float))
                for p in runs_of_setting["path"]
                if (c := by_path.get(p)) is not None and len(c)
            ]
            if not parts:
                continue
            grid, median, low, high = seed_band(parts)
            (line,) = ax.plot(grid, median, label=f"{name} ({len(parts)} seed{'s' * (len(parts) != 1)})")
            if len(parts) > 1:
                ax.fill_between(grid, low, high, color=line.get_color(), alpha=0.2, linewidth=0)
        ax.set_yscale("log")
        ax.set_title(problem)
        ax.set_xlabel("training clock [s]")
        ax.set_ylabel("test loss")
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=8)
    fig.text(0.01, 0.01, "line: median over seeds; band: lowest to highest seed", fontsize=8, color="0.4")
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    return _save(fig, path)


def profile_taus(times: pd.DataFrame, points: int = 200) -> np.ndarray:
    """tau from 1 to a bit past the largest finite ratio, log-spaced (at least up to 10)."""
    ratios = times["ratio"].to_numpy(dtype=float)
    finite = ratios[np.isfinite(ratios)]
    top = max(10.0, 1.2 * float(finite.max())) if len(finite) else 10.0
    return np.logspace(0.0, math.log10(top), points)


def plot_profile(rho: pd.DataFrame, path: str | Path, n_pairs: int) -> Path:
    """rho(tau) per setting as a step function, log tau."""
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for name in rho.columns:
        ax.step(rho.index, rho[name], where="post", label=name)
    ax.set_xscale("log")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("tau (time to target / fastest setting's)")
    ax.set_ylabel("fraction of (problem, target) pairs")
    ax.set_title(f"performance profile over {n_pairs} (problem, target) pairs")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    return _save(fig, path)


def _save(fig: plt.Figure, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
