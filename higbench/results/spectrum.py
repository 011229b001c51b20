"""The spectrum of GN/HIG/LM steps, read back from run files.

The runner records, per update, the singular values of that step's Jacobian J (on the Gram
route the square roots of the eigenvalues of J J^T, so the same numbers): ``/updates/sv_max``,
``sv_min_kept`` (the smallest the truncation tau kept), ``sv_dropped`` (how many it dropped),
and at every evaluation ``/logs/sv_quantiles`` (quantiles 0, 0.1, ..., 1 of the last step's
singular values). First-order runs and files written before the spectrum was recorded have
none of it.

    conditioning(updates)  # the index's columns for one run: how ill-conditioned its steps were
    read_spectrum(path)    # the series of one run for ``plot.plot_spectrum`` (None without them)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from higbench.runfile.reader import UPDATE_SPECTRUM_COLUMNS, load_logs, read_tables

# The index's columns (NaN for runs without a spectrum). cond_kept = sv_max / sv_min_kept: the
# condition number of the part of J the step inverts (with relative truncation at most 1/tau).
CONDITIONING_COLUMNS = ("cond_kept_median", "cond_kept_max", "sv_dropped_mean")


def conditioning(updates: dict[str, np.ndarray]) -> dict[str, float]:
    """Median and maximum over updates of sv_max / sv_min_kept, and the mean of sv_dropped.

    ``updates``: the run's /updates columns. Updates without a spectrum (NaN, e.g. nothing
    kept) are left out; a run with none gets NaN everywhere.
    """
    out = dict.fromkeys(CONDITIONING_COLUMNS, math.nan)
    sv_max, sv_min = updates.get("sv_max"), updates.get("sv_min_kept")
    if sv_max is not None and sv_min is not None:
        with np.errstate(divide="ignore", invalid="ignore"):
            cond = np.asarray(sv_max, dtype=np.float64) / np.asarray(sv_min, dtype=np.float64)
        cond = cond[np.isfinite(cond)]
        if len(cond):
            out["cond_kept_median"], out["cond_kept_max"] = float(np.median(cond)), float(cond.max())
    dropped = updates.get("sv_dropped")
    if dropped is not None:
        dropped = np.asarray(dropped, dtype=np.float64)
        dropped = dropped[np.isfinite(dropped)]
        if len(dropped):
            out["sv_dropped_mean"] = float(dropped.mean())
    return out


@dataclass
class RunSpectrum:
    """One run's spectrum over training.

    step, sv_max, sv_min_kept, sv_dropped: per update. eval_step, quantiles (n_evals, k),
    levels (k,): the quantiles recorded at the evaluations (empty if the file has none).
    tau, truncation: the optimizer's cutoff (tau None where the config has none: LM).
    """

    path: str
    step: np.ndarray
    sv_max: np.ndarray
    sv_min_kept: np.ndarray
    sv_dropped: np.ndarray
    eval_step: np.ndarray
    quantiles: np.ndarray
    levels: np.ndarray
    tau: float | None
    truncation: str

    def cutoff(self) -> np.ndarray | None:
        """The truncation threshold per update: tau * sv_max (relative) or tau (absolute)."""
        if self.tau is None:
            return None
        if self.truncation == "absolute":
            return np.full(len(self.step), self.tau)
        return self.tau * self.sv_max


def read_spectrum(path: str | Path) -> RunSpectrum | None:
    """The spectrum series of one run file; None if it recorded none (or no finite value)."""
    wanted = {"updates": ("step", *UPDATE_SPECTRUM_COLUMNS), "curves": ("step",)}
    run = read_tables(path, wanted, locking=False)
    updates = run.tables.get("updates", {})
    if not all(c in updates for c in ("step", *UPDATE_SPECTRUM_COLUMNS)):
        return None
    n = min(len(v) for v in updates.values())  # a killed writer may leave columns ragged
    u = {k: np.asarray(v[:n], dtype=np.float64) for k, v in updates.items()}
    if not np.isfinite(u["sv_max"]).any():
        return None
    quantiles = np.asarray(load_logs(path).get("sv_quantiles", np.empty((0, 0))), dtype=np.float64)
    eval_step = np.asarray(run.tables.get("curves", {}).get("step", np.empty(0)), dtype=np.float64)
    if quantiles.ndim != 2:
        quantiles = np.empty((0, 0))
    m = min(len(quantiles), len(eval_step))  # one row per evaluation, as the curves
    optimizer = run.config.get("optimizer") if isinstance(run.config.get("optimizer"), dict) else {}
    try:
        tau = float(optimizer["tau"])
    except (KeyError, TypeError, ValueError):  # no tau (LM) or not a number
        tau = None
    return RunSpectrum(
        path=str(path),
        step=u["step"],
        sv_max=u["sv_max"],
        sv_min_kept=u["sv_min_kept"],
        sv_dropped=u["sv_dropped"],
        eval_step=eval_step[:m],
        quantiles=quantiles[:m],
        levels=np.linspace(0.0, 1.0, quantiles.shape[1]) if quantiles.shape[1] > 1 else np.empty(0),
        tau=tau,
        truncation=str(optimizer.get("truncation", "relative")),
    )
