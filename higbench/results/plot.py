"""Plots of your own runs: loss curves over seeds (``--plot``), performance profiles
(``--profile``) and the spectrum of GN/HIG/LM steps over training (``--spectrum``).

``plot_curves`` takes ``load_runs(root, curves=True)`` with a ``setting`` column
(``profile.setting_labels``); ``plot_profile`` takes ``profile.performance_profile``'s table;
``plot_spectrum`` takes ``spectrum.read_spectrum``'s series, one panel per run.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from higbench.results.spectrum import RunSpectrum, conditioning  # noqa: E402

GRID_POINTS = 200


def seed_band(
    curves: list[tuple[np.ndarray, np.ndarray]], diverged: list[bool] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(time grid, median, min, max) over runs of (time, loss) curves.

    Each curve is interpolated in log(loss) onto a common grid up to the earliest end among
    the runs that ran out their budget, so every point of the band has every seed behind it.
    A diverged run (``diverged[i]``) stopped early for its own reason: after its end it counts
    as an infinite loss, so it neither cuts its setting's line short nor lowers the median
    (the median goes where more than half the seeds diverged, the band's top where one did).
    """
    diverged = list(diverged) if diverged is not None else [False] * len(curves)
    ends = [t[-1] for (t, _), gone in zip(curves, diverged) if len(t) and not gone]
    if not ends:  # every seed diverged: up to the last of them
        ends = [max(t[-1] for t, _ in curves if len(t))] if any(len(t) for t, _ in curves) else []
    grid = np.linspace(0.0, min(ends), GRID_POINTS) if ends else np.empty(0)
    logs = []
    for (t, loss), gone in zip(curves, diverged):
        ok = np.isfinite(loss) & (loss > 0)
        if ok.sum() < 1:
            continue
        log = np.interp(grid, t[ok], np.log10(loss[ok]))
        logs.append(np.where(grid > t[-1], np.inf, log) if gone else log)
    if not logs:
        return grid, *(np.full(len(grid), np.nan) for _ in range(3))
    stack = np.vstack(logs)
    finite = lambda a: np.where(np.isfinite(a), 10**a, np.nan)  # noqa: E731 - inf: not drawn
    return grid, finite(np.median(stack, axis=0)), finite(stack.min(axis=0)), finite(stack.max(axis=0))


def plot_curves(runs: pd.DataFrame, curves: pd.DataFrame, path: str | Path, setting: str = "setting", columns: int = 3) -> Path:
    """Test loss against the training clock: one panel per problem (at most ``columns`` per
    row), one line per setting (median over its seeds) with a band from the lowest to the
    highest seed; log y."""
    problems = sorted(runs["problem.name"].dropna().unique())
    n = max(len(problems), 1)
    rows, cols = -(-n // columns), min(columns, n)
    fig, axes = plt.subplots(rows, cols, figsize=(6.0 * cols, 4.2 * rows), squeeze=False)
    for ax in axes.flat[len(problems) :]:
        ax.set_visible(False)
    by_path = {p: g for p, g in curves.groupby("path", observed=True)}
    for ax, problem in zip(axes.flat, problems):
        group = runs[runs["problem.name"] == problem]
        for name, runs_of_setting in group.groupby(setting, sort=True):
            parts, diverged = [], []
            for p, status in zip(runs_of_setting["path"], runs_of_setting["status"]):
                if (c := by_path.get(p)) is not None and len(c):
                    parts.append((c["wall_time"].to_numpy(dtype=float), c["test_loss"].to_numpy(dtype=float)))
                    diverged.append(status == "diverged")
            if not parts:
                continue
            grid, median, low, high = seed_band(parts, diverged)
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


def plot_spectrum(spectra: list[tuple[str, RunSpectrum]], path: str | Path, columns: int = 3) -> Path:
    """Singular values of each update's J against updates, one panel per (title, run); log y.

    Per update: the largest, the smallest kept and tau's cutoff (where the config has a tau);
    at each evaluation: the deciles of the whole spectrum of the last update (grey; zeros,
    e.g. values below round-off on the Gram route, cannot show on the log axis).
    """
    rows = -(-len(spectra) // columns)
    cols = min(columns, len(spectra))
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 3.6 * rows), squeeze=False)
    for ax, (title, run) in zip(axes.flat, spectra):
        _spectrum_panel(ax, title, run)
    for ax in axes.flat[len(spectra) :]:
        ax.set_visible(False)
    fig.text(0.01, 0.01, "grey: deciles of the last update's singular values at each evaluation", fontsize=8, color="0.4")
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    return _save(fig, path)


def _positive(values: np.ndarray) -> np.ndarray:
    """Values a log axis can show (others as NaN: gaps)."""
    return np.where(values > 0, values, np.nan)


def _spectrum_panel(ax: plt.Axes, title: str, run: RunSpectrum) -> None:
    for i, level in enumerate(run.levels):
        ax.plot(
            run.eval_step,
            _positive(run.quantiles[:, i]),
            color="0.55",
            linewidth=1.2 if level == 0.5 else 0.6,
            linestyle=":" if level in (0.0, 1.0) else "-",
            marker=".",
            markersize=3,
            label="deciles (0, 0.1, ..., 1)" if i == 0 else None,
        )
    marker = "." if len(run.step) < 50 else None  # a run of one or two updates still shows
    ax.plot(run.step, _positive(run.sv_max), color="C0", linewidth=1.0, marker=marker, label="largest")
    ax.plot(run.step, _positive(run.sv_min_kept), color="C1", linewidth=1.0, marker=marker, label="smallest kept")
    cutoff = run.cutoff()
    if cutoff is not None:
        what = f"tau*largest, tau={run.tau:g}" if run.truncation == "relative" else f"tau={run.tau:g}"
        ax.plot(run.step, _positive(cutoff), color="C3", linestyle="--", linewidth=0.9, marker=marker, label=f"cutoff ({what})")
    ax.set_yscale("log")
    c = conditioning({"sv_max": run.sv_max, "sv_min_kept": run.sv_min_kept, "sv_dropped": run.sv_dropped})
    stats = f"largest/smallest kept: median {c['cond_kept_median']:.2g}, max {c['cond_kept_max']:.2g}"
    stats += f"; {c['sv_dropped_mean']:.2g} dropped per update"
    ax.set_title(f"{title}\n{stats}", fontsize=8)
    ax.set_xlabel("update")
    ax.set_ylabel("singular value of J")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7, loc="best")


def _save(fig: plt.Figure, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
