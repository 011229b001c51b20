"""What a plot function sees: the figure's runs (read from their run files only) and helpers
that draw curves while recording every plotted point in the figure's data table.

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

from higbench.figures.runs import Job
from higbench.figures.spec import Figure, Preset
from higbench.runfile.reader import load_logs, load_run, load_updates, load_weights

OPTIMIZER_NAMES = {
    "adam": "Adam", "sgd": "SGD", "adagrad": "Adagrad", "adadelta": "Adadelta",
    "rmsprop": "RMSprop", "gn": "GN", "hig": "HIG",
}  # fmt: skip
COLORS = {
    "adam": "tab:blue", "gn": "tab:red", "hig": "tab:green", "sgd": "tab:gray",
    "adagrad": "tab:purple", "adadelta": "tab:brown", "rmsprop": "tab:orange",
}  # fmt: skip


def num(v: Any) -> str:
    """Compact number for labels: 0.0003 -> 3e-4, 1.0 -> 1, 128 -> 128."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return str(v)
    if isinstance(v, int) or (float(v).is_integer() and abs(v) < 1e5):
        return str(int(v))
    m, e = f"{v:.0e}".split("e")
    if abs(v) >= 1e-2 and abs(v) < 1e3:
        return f"{v:g}"
    return f"{m}e{int(e)}"


@dataclass
class RunData:
    """One job of the figure and, if it ran, its run file (read lazily)."""

    job: Job

    @property
    def path(self) -> Path | None:
        return self.job.path

    @property
    def ok(self) -> bool:
        return self.job.path is not None and self.job.done

    @property
    def seed(self) -> int:
        return self.job.seed

    def cfg(self, key: str, default: Any = None) -> Any:
        return self.job.value(key, default)

    @cached_property
    def _run(self):
        return load_run(self.path)

    @property
    def meta(self) -> dict:
        return self._run[0]

    @property
    def curves(self) -> pd.DataFrame:
        return self._run[1]

    @cached_property
    def updates(self) -> pd.DataFrame:
        return load_updates(self.path)

    @cached_property
    def logs(self) -> dict[str, np.ndarray]:
        return load_logs(self.path)

    @cached_property
    def weights(self) -> dict[str, np.ndarray]:
        return load_weights(self.path)

    @property
    def status(self) -> str:
        return self.job.status

    @property
    def final_loss(self) -> float:
        c = self.curves
        return float(c["test_loss"].iloc[-1]) if len(c) else math.nan

    @property
    def initial_loss(self) -> float:
        c = self.curves
        return float(c["test_loss"].iloc[0]) if len(c) else math.nan

    def label(self, keys: Iterable[str] = ("optimizer.lr", "optimizer.tau", "batch_size")) -> str:
        """'HIG η=1 τ=1e-6 b=128': optimizer and the given hyper-parameters (GN has no η)."""
        opt = self.cfg("optimizer.name", "?")
        parts = [OPTIMIZER_NAMES.get(opt, opt)]
        symbols = {
            "optimizer.lr": "η", "optimizer.tau": "τ", "batch_size": "b", "optimizer.kappa": "κ",
            "optimizer.beta": "β", "problem.gamma": "γ", "seed": "seed",
        }  # fmt: skip
        for key in keys:
            if key == "optimizer.lr" and opt == "gn":
                continue
            if key == "optimizer.tau" and opt not in ("gn", "hig"):
                continue
            v = self.cfg(key)
            if v is not None:
                parts.append(f"{symbols.get(key, key)}={num(v)}")
        return " ".join(parts)

    def build_model(self):
        """(problem, model) rebuilt from the run's config with its final weights loaded."""
        import torch
        from omegaconf import OmegaConf

        from higbench.problems import build_problem

        cfg = OmegaConf.create(self.meta["config"])
        dtype = {"float32": torch.float32, "float64": torch.float64}[cfg.dtype]
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

    def runs(self, sweep: str | None = None, only_ok: bool = True, **where: Any) -> list[RunData]:
        """Runs of a sweep (all sweeps if None) whose resolved config matches ``where``
        (keys with dots written with double underscores: optimizer__lr=1e-4)."""
        out = []
        for job in self.jobs:
            if sweep is not None and job.sweep != sweep:
                continue
            if where and any(not _match(job.value(k.replace("__", ".")), v) for k, v in where.items()):
                continue
            rd = self._cache.setdefault(id(job), RunData(job))
            if only_ok and not rd.ok:
                continue
            out.append(rd)
        return out

    @cached_property
    def _cache(self) -> dict[int, RunData]:
        return {}

    def missing(self) -> list[Job]:
        return [j for j in self.jobs if not j.done]

    # -- recording what is plotted ------------------------------------------------------

    def record(self, panel: str, series: str, run: RunData | None, x_name: str, x, y_name: str, y, **extra) -> None:
        x = np.asarray(x, dtype=float).ravel()
        y = np.asarray(y, dtype=float).ravel()
        path = "" if run is None else show_path(run.path)
        seed = "" if run is None else run.seed
        for xi, yi in zip(x, y):
            self.rows.append(
                {
                    "panel": panel,
                    "series": series,
                    "seed": seed,
                    "run": path,
                    "x_name": x_name,
                    "x": xi,
                    "y_name": y_name,
                    "y": yi,
                    **extra,
                }
            )

    def curve(
        self,
        ax,
        runs: list[RunData],
        label: str,
        *,
        panel: str,
        x: str = "wall_time",
        y: str = "test_loss",
        color=None,
        ls="-",
        x_offset: float = 0.0,
        transform=None,
        **kw,
    ):
        """Plot one setting: a line for one seed, median line + min-max band for several."""
        runs = [r for r in runs if r.ok and y in r.curves]
        if not runs:
            return None
        series = []
        diverged = []
        for r in runs:
            c = r.curves
            xs = (transform(r, c) if transform is not None else c[x].to_numpy(dtype=float)) + x_offset
            ys = c[y].to_numpy(dtype=float)
            self.record(panel, label, r, x, xs, y, ys)
            ok = np.isfinite(ys) & np.isfinite(xs)
            series.append((xs[ok], ys[ok]))
            if r.status == "diverged" and ok.any():
                diverged.append((xs[ok][-1], ys[ok][-1], r.meta.get("status_step")))
        series = [s for s in series if len(s[0])]
        if not series:
            return None
        if diverged:
            steps = sorted({d[2] for d in diverged if d[2] is not None})
            label += f" (diverged{' at step ' + ', '.join(map(str, steps)) if steps else ''})"
        if len(series) == 1:
            (line,) = ax.plot(*series[0], label=label, color=color, ls=ls, **kw)
        else:
            lo = max(s[0][0] for s in series)
            hi = min(s[0][-1] for s in series)
            grid = np.linspace(lo, hi, 200) if hi > lo else np.array([lo])
            logs = np.array([np.interp(grid, xs, np.log10(np.maximum(ys, 1e-300))) for xs, ys in series])
            (line,) = ax.plot(
                grid, 10 ** np.median(logs, axis=0), label=f"{label} (median of {len(series)} seeds, band: min-max)",
                color=color, ls=ls, **kw,
            )  # fmt: skip
            ax.fill_between(grid, 10 ** logs.min(axis=0), 10 ** logs.max(axis=0), color=line.get_color(), alpha=0.2, lw=0)
            self.banded = True
        for dx, dy, _ in diverged:  # where a diverged run's last finite evaluation was, named in the plot
            ax.plot([dx], [dy], marker="X", ms=10, mew=1, mec="black", color=line.get_color(), ls="none", zorder=5)
            ax.annotate(
                "diverged", (dx, dy), xytext=(8, 8), textcoords="offset points", fontsize=7, color=line.get_color(),
                fontweight="bold", arrowprops={"arrowstyle": "-", "color": line.get_color(), "lw": 0.8},
            )  # fmt: skip
            self.diverged_marked = True
        return line

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
        fig.text(0.01, 0.005, self.caption(), fontsize=7, color="0.35", ha="left", va="bottom")
        for ext in ("png", "pdf"):
            fig.savefig(self.out_dir / f"{self.figure.id}.{ext}", dpi=120 if ext == "png" else None)
        import matplotlib.pyplot as plt

        plt.close(fig)

    def write_data(self) -> None:
        cols = ["panel", "series", "seed", "run", "x_name", "x", "y_name", "y"]
        df = pd.DataFrame(self.rows)
        if df.empty:
            df = pd.DataFrame(columns=cols)
        df = df[cols + [c for c in df.columns if c not in cols]]
        df.to_csv(self.out_dir / f"{self.figure.id}.csv", index=False)

    def write_table(self, table: pd.DataFrame, *, index: bool = True, title: str | None = None) -> None:
        base = self.out_dir / self.figure.id
        table.to_csv(base.with_suffix(".csv"), index=index)
        md = [f"# {self.figure.id}: {title or self.figure.title}", "", _markdown(table, index), "", f"_{self.caption()}_"]
        md += [f"_{n}_" for n in self.notes]
        base.with_suffix(".md").write_text("\n".join(md) + "\n")
        try:
            base.with_suffix(".tex").write_text(table.to_latex(index=index))
        except Exception:  # noqa: BLE001 - LaTeX only if pandas can (jinja2)
            pass

    def write_sidecar(self, extra: dict | None = None) -> dict:
        info = {
            "id": self.figure.id,
            "title": self.figure.title,
            "kind": self.figure.kind,
            "preset": self.preset.name,
            "budgets": self.budgets,
            "notes": self.notes,
            "generated": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "runs": [
                {
                    "sweep": j.sweep,
                    "seed": j.seed,
                    "overrides": j.override_list(),
                    "identity": j.identity,
                    "status": j.status,
                    "path": show_path(j.path) if j.path else None,
                }
                for j in self.jobs
            ],
            **self.sidecar,
            **(extra or {}),
        }
        (self.out_dir / f"{self.figure.id}.json").write_text(json.dumps(info, indent=1, default=str) + "\n")
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
    """A GitHub table without the tabulate package."""
    frame = df.reset_index() if index else df
    header = [str(c) for c in frame.columns]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    for row in frame.itertuples(index=False):
        lines.append("| " + " | ".join(_cell(v) for v in row) + " |")
    return "\n".join(lines)


def _cell(v: Any) -> str:
    if isinstance(v, float):
        if math.isnan(v):
            return "-"
        return f"{v:.3g}"
    return str(v)


def semilogy_axes(ax, xlabel: str = "wall-clock time [s]", ylabel: str = "test loss") -> None:
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, which="major", alpha=0.3)


def new_figure(ncols: int = 1, nrows: int = 1, width: float = 4.2, height: float = 3.2, **kw):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(nrows, ncols, figsize=(width * ncols, height * nrows + 0.3), squeeze=False, **kw)
    return fig, axes


def join_label(name: str, detail: str) -> str:
    """'Adam' + 'Adam η=1e-4 b=64' -> 'Adam η=1e-4 b=64'; 'HIG after Adam' + 'HIG η=0.02' -> 'HIG after Adam (η=0.02)'."""
    if detail.startswith(name):
        return detail
    first, _, rest = detail.partition(" ")
    if first in name.split():
        detail = rest
    return f"{name} ({detail})" if detail else name


def legend(ax, **kw) -> None:
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(fontsize=7, **kw)
    else:
        ax.text(0.5, 0.5, "no runs", transform=ax.transAxes, ha="center", va="center", color="0.5")
