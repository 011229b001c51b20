"""What a figure's drawing sees: its runs (read from their run files only), the record of every
plotted point, and the writers of its outputs.

Every figure writes ``<out>/<id>.csv`` (the plotted data, one row per point, with the run
file it came from), ``<out>/<id>.png`` and ``.pdf``, and ``<out>/<id>.json`` (preset,
budgets, the runs used, their identities and statuses, deviations from the paper).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from higbench.display import OPTIMIZER_NAMES, fmt, md_table, num
from higbench.figures.spec import Figure, Preset
from higbench.jobs import Job
from higbench.runfile.reader import load_logs, load_run, load_updates, load_weights

COLUMNS = ("panel", "series", "seed", "run", "x_name", "x", "y_name", "y")  # of a figure's data table
SYMBOLS = {
    "optimizer.lr": "η",
    "optimizer.tau": "τ",
    "batch_size": "b",
    "optimizer.kappa": "κ",
    "optimizer.beta": "β",
    "problem.gamma": "γ",
    "seed": "seed",
}


LABEL_KEYS = ("optimizer.lr", "optimizer.tau", "batch_size")  # a run's legend label names these


def kv(key: str, value: Any) -> str:
    """'optimizer.lr', 1e-4 -> 'η=1e-4'."""
    return f"{SYMBOLS.get(key, key)}={num(value)}"


class LabelledRun:
    """What a figure reads of a run besides its data: the test loss at both ends and a legend
    label. For run records with ``cfg(key)`` and ``curves`` (``RunData``, and
    ``figures.committed.CommittedRun`` rebuilt from committed data)."""

    @property
    def final_loss(self) -> float:
        c = self.curves
        return float(c["test_loss"].iloc[-1]) if len(c) else math.nan

    @property
    def initial_loss(self) -> float:
        c = self.curves
        return float(c["test_loss"].iloc[0]) if len(c) else math.nan

    def label(self, keys: Iterable[str] = LABEL_KEYS) -> str:
        """'HIG η=1 τ=1e-6 b=128': optimizer and the given hyper-parameters (GN has no η)."""
        opt = self.cfg("optimizer.name", "?")
        parts = [OPTIMIZER_NAMES.get(opt, opt)]
        for key in keys:
            if (key == "optimizer.lr" and opt == "gn") or (key == "optimizer.tau" and opt not in ("gn", "hig")):
                continue
            if (v := self.cfg(key)) is not None:
                parts.append(kv(key, v))
        return " ".join(parts)


@dataclass
class RunData(LabelledRun):
    """One job of the figure and, if it ran, its run file (read lazily)."""

    job: Job

    path = property(lambda self: self.job.path)
    seed = property(lambda self: self.job.seed)
    status = property(lambda self: self.job.status)
    ok = property(lambda self: self.job.path is not None and self.job.done)
    meta = property(lambda self: self._run[0])
    curves = property(lambda self: self._run[1])

    def cfg(self, key: str, default: Any = None) -> Any:
        return self.job.value(key, default)

    @cached_property
    def _run(self):
        return load_run(self.path)

    @cached_property
    def updates(self) -> pd.DataFrame:
        return load_updates(self.path)

    @cached_property
    def logs(self) -> dict[str, np.ndarray]:
        return load_logs(self.path)

    @cached_property
    def weights(self) -> dict[str, np.ndarray]:
        return load_weights(self.path)

    def build_model(self):
        """(problem, model) rebuilt from the run's config with its final weights loaded."""
        import torch
        from omegaconf import OmegaConf

        from higbench.dtypes import DTYPES  # torch: imported only when a figure rebuilds a network
        from higbench.problems import build_problem

        cfg = OmegaConf.create(self.meta["config"])
        dtype = DTYPES[cfg.dtype]
        problem = build_problem(cfg.problem, dtype=dtype, device=torch.device("cpu"), seed=int(cfg.seed))
        model = problem.build_model()
        model.load_state_dict({k: torch.as_tensor(v) for k, v in self.weights.items()})
        model.eval()
        return problem, model


@dataclass
class FigureData:
    """A figure's runs by sweep, the preset, the output paths and the plotted-data log."""

    figure: Figure
    preset: Preset
    out_dir: Path
    jobs: list[Job]
    budgets: dict[str, str] = field(default_factory=dict)
    rows: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    banded: bool = False  # a curve drew a min-max band (the caption then says what it is)
    diverged_marked: bool = False  # a diverged run's last point was marked
    sidecar: dict = field(default_factory=dict)  # extra entries a plot puts into <id>.json
    _cache: dict = field(default_factory=dict)

    def runs(self, sweep: str | None = None, only_ok: bool = True, **where: Any) -> list[RunData]:
        """Runs of a sweep (all sweeps if None) whose resolved config matches ``where``
        (dotted keys written with double underscores: optimizer__lr=1e-4)."""
        out = []
        for job in self.jobs:
            if (sweep is not None and job.sweep != sweep) or any(
                not _match(job.value(k.replace("__", ".")), v) for k, v in where.items()
            ):
                continue
            rd = self._cache.setdefault(id(job), RunData(job))
            if rd.ok or not only_ok:
                out.append(rd)
        return out

    def values(self, sweep: str, key: str) -> list:
        """The sorted values of an override over a sweep's jobs (``optimizer.name``: the optimizer)."""
        found = {j.overrides.get(key, j.overrides.get(key.removesuffix(".name"))) for j in self.jobs if j.sweep == sweep}
        if None in found:  # a value the sweep does not set: the resolved configs' (only known for runs composed)
            found = {j.value(key) for j in self.jobs if j.sweep == sweep} - {None}
        return sorted(found)

    def trajectory(self, sweep: str):
        """(run, problem, sample, states, controls): the sweep's first run rebuilt, on its first test sample; None if not run."""
        if not (runs := self.runs(sweep)):
            return None
        problem, model = runs[0].build_model()
        batch = problem.test_set()[:1]
        return (runs[0], problem, batch, *problem.trajectory(model, batch))

    def missing(self) -> list[Job]:
        return [j for j in self.jobs if not j.done]

    def record(self, panel: str, series: str, run: RunData | None, x_name: str, x, y_name: str, y, **extra) -> None:
        path, seed = ("", "") if run is None else (show_path(run.path), run.seed)
        for xi, yi in zip(np.asarray(x, dtype=float).ravel(), np.asarray(y, dtype=float).ravel()):
            self.rows.append(dict(zip(COLUMNS, (panel, series, seed, path, x_name, xi, y_name, yi)), **extra))

    # -- writing ------------------------------------------------------------------------

    def caption(self) -> str:
        budgets = "; ".join(f"{k}: {v}" for k, v in self.budgets.items())
        missing = len(self.missing())
        keys = []  # what the marks mean, for the figures that have them
        if self.banded:
            keys.append("lines: median over seeds, shaded: min-max over seeds")
        if self.diverged_marked:
            keys.append("X: last finite evaluation of a diverged run")
        return (
            f"{self.figure.id} - preset {self.preset.name} - budget per run {budgets}"
            + (f" - {missing} run(s) missing" if missing else "")
            + (f" - {'; '.join(keys)}" if keys else "")
        )

    def save(self, fig) -> None:
        import matplotlib.pyplot as plt

        fig.text(0.01, 0.005, self.caption(), fontsize=7, color="0.35", ha="left", va="bottom")
        for ext in ("png", "pdf"):
            fig.savefig(self.out_dir / f"{self.figure.id}.{ext}", dpi=120 if ext == "png" else None)
        plt.close(fig)

    def write_data(self) -> None:
        cols = list(COLUMNS)
        df = pd.DataFrame(self.rows) if self.rows else pd.DataFrame(columns=cols)
        df[cols + [c for c in df.columns if c not in cols]].to_csv(self.out_dir / f"{self.figure.id}.csv", index=False)

    def write_table(self, table: pd.DataFrame, *, index: bool = True, title: str | None = None) -> None:
        base = self.out_dir / self.figure.id
        table.to_csv(base.with_suffix(".csv"), index=index)
        md = [f"# {self.figure.id}: {title or self.figure.title}", "", _markdown(table, index), "", f"_{self.caption()}_"]
        base.with_suffix(".md").write_text("\n".join(md + [f"_{n}_" for n in self.notes]) + "\n")
        try:
            base.with_suffix(".tex").write_text(table.to_latex(index=index))
        except Exception:  # noqa: BLE001 - LaTeX only if pandas can (jinja2)
            pass

    def write_sidecar(self, extra: dict | None = None) -> dict:
        keys = ("sweep", "seed", "overrides", "identity", "status", "path")
        runs = [
            dict(zip(keys, (j.sweep, j.seed, j.override_list(), j.identity, j.status, j.path and show_path(j.path))))
            for j in self.jobs
        ]
        f = self.figure
        info = {"id": f.id, "title": f.title, "kind": f.kind, "preset": self.preset.name, "budgets": self.budgets}
        info |= {"notes": self.notes, "generated": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "runs": runs, **self.sidecar}
        info |= extra or {}
        (self.out_dir / f"{f.id}.json").write_text(json.dumps(info, indent=1, default=str) + "\n")
        return info


def show_path(path: Path) -> str:
    """A run file's path as written in data tables: relative to the working directory if below it."""
    p = Path(path).resolve()
    try:
        return str(p.relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(p)


def _match(value: Any, want: Any) -> bool:
    if isinstance(want, float) or isinstance(value, float):
        try:
            return math.isclose(float(value), float(want), rel_tol=1e-9)
        except (TypeError, ValueError):
            return False
    return value == want


def _markdown(df: pd.DataFrame, index: bool) -> str:
    frame = df.reset_index() if index else df
    return "\n".join(md_table(list(frame.columns), [map(fmt, row) for row in frame.itertuples(index=False)]))
