"""The one plotting layer: panels declared as data (``Curves`` of ``Series``, ``Facets``,
``Custom``) drawn from a ``FigureData``, every plotted point recorded in the figure's table.

A ``Series`` is one line per setting: the runs of a sweep (matching ``where``), split into one
line per value of ``by`` if given; several seeds of a setting draw their median with a
min-max band (named in the legend and the caption), a diverged run is marked where its last
finite evaluation was. A run continued from another run drawn in the same panel
(``init_from``) is drawn after it, shifted by the parent's final training time.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from higbench.display import COLORS, OPTIMIZER_NAMES
from higbench.figures.data import FigureData, RunData, kv

TIME = "training time [s] (training clock, evaluations excluded)"
FACET_TIME = "training time [s]"  # under each column of a grid: the long label overlaps its neighbours
PALETTE = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple")


@dataclass
class Series:
    """label: a format of ``label`` (the run's), ``short`` (optimizer, η and τ), ``kv`` (the ``by``
    value, 'η=1e-4'); ``name`` instead: 'name (the run's label)'. color: a colour, a list (by the
    ``by`` value's index), "optimizer" (each optimizer's colour) or a colormap name."""

    sweep: str
    by: str | None = None
    where: dict[str, Any] = field(default_factory=dict)
    label: str = "{label}"
    name: str | None = None
    color: Any = "optimizer"
    ls: Any = "-"  # a style, or a list by the ``by`` value's index
    y: str = "test_loss"
    reverse: bool = False
    lw: float | None = None


@dataclass
class Curves:
    """One axes of loss curves (log y)."""

    title: str
    series: list[Series]
    panel: str = "loss"  # the panel's name in the data table
    x: str = "wall_time"  # or "epoch" (samples seen / epoch size)
    xscale: str = "linear"
    xlabel: str = TIME
    ylabel: str = "test loss"
    ncol: int = 1
    extra: Callable | None = None  # extra(d, ax) draws more on the axes


@dataclass
class Custom:
    """An axes drawn by ``draw(d, ax, **kw)`` (fields, trajectories)."""

    draw: Callable
    kw: dict = field(default_factory=dict)


@dataclass
class Facets:
    """A grid of axes over the values found in the runs: one row per ``rows`` value ("sweep": one
    per sweep), one column per ``cols`` value, one line per ``lines`` value."""

    sweeps: list[str]
    cols: str
    lines: str
    rows: str | None = None
    prefix: str = ""
    size: tuple = (3.4, 2.9)


def new_figure(ncols: int = 1, nrows: int = 1, width: float = 4.2, height: float = 3.2, **kw):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(nrows, ncols, figsize=(width * ncols, height * nrows + 0.3), squeeze=False, **kw)


OUTSIDE = {"loc": "upper left", "bbox_to_anchor": (1.02, 1.0), "borderaxespad": 0.0}  # beside the axes, off the data
LEGEND_WIDTH = 2.6  # inches a panel gains for its legend beside it


def legend(ax, shown: bool = True, **kw) -> None:
    """The axes' legend beside it, right of the data (``kw``: another placement; ``shown``: False where the figure
    has one legend for all its axes)."""
    if ax.get_legend_handles_labels()[0]:
        if shown:
            ax.legend(fontsize=7, **(kw if "loc" in kw else {**OUTSIDE, **kw}))
    else:
        ax.text(0.5, 0.5, "no runs", transform=ax.transAxes, ha="center", va="center", color="0.5")


def style(ax, title: str, xlabel: str = TIME, ylabel: str = "test loss", xscale: str = "linear", fontsize=9, **legend_kw):
    legend_kw.pop("ncol", None)  # beside the axes one column reads best
    ax.set_yscale("log")
    ax.set_xscale(xscale)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, which="major", alpha=0.3)
    ax.set_title(title, fontsize=fontsize)
    legend(ax, **legend_kw)


def join_label(name: str, detail: str) -> str:
    """'HIG after Adam' + 'HIG η=0.02' -> 'HIG after Adam (η=0.02)'; a detail naming itself stays."""
    if detail.startswith(name):
        return detail
    first, _, rest = detail.partition(" ")
    detail = rest if first in name.split() else detail
    return f"{name} ({detail})" if detail else name


def epochs(run: RunData, curves) -> np.ndarray:
    """Epochs as samples seen / epoch size (an epoch is a bookkeeping unit on infinite data)."""
    return curves["step"].to_numpy(dtype=float) * float(run.cfg("batch_size")) / float(run.cfg("problem.epoch_size"))


CURVE_POINTS = 500  # evaluations drawn per run and scale (a 3,000 s Adam run has ~54,000)


def thinned(n: int, y: np.ndarray, keep: int = CURVE_POINTS) -> np.ndarray:
    """Indices of the evaluations to draw of ``n``: all if few, else ``keep`` evenly spread and
    ``keep`` log-spaced (dense early: log axes), the first, the last and the lowest ``y``."""
    if n <= 2 * keep:
        return np.arange(n)
    even = np.linspace(0, n - 1, keep).round()
    early = np.geomspace(1, n, keep).round() - 1
    lowest = [np.nanargmin(y)] if np.isfinite(y).any() else []
    return np.unique(np.concatenate([even, early, lowest, [0, n - 1]]).astype(int))


def curve(d: FigureData, ax, runs, label, *, panel, x="wall_time", y="test_loss", color=None, ls="-", x_offset=0.0, **kw):
    """One setting: a line for one seed, median line + min-max band for several.

    On a log x axis the points at x <= 0 (the evaluation before the first update) are left
    out: drawn at a clipped tiny x they would pull a flat line at the first later value
    across the visible decades (fig7a's Adam once looked flat from ~160)."""
    runs = [r for r in runs if r.ok and y in r.curves]
    series, diverged = [], []
    for r in runs:
        c = r.curves.iloc[thinned(len(r.curves), r.curves[y].to_numpy(dtype=float))]
        xs = (epochs(r, c) if x == "epoch" else c[x].to_numpy(dtype=float)) + x_offset
        ys = c[y].to_numpy(dtype=float)
        d.record(panel, label, r, x, xs, y, ys)
        ok = np.isfinite(ys) & np.isfinite(xs) & ((xs > 0) | (ax.get_xscale() != "log"))
        if ok.any():
            series.append((xs[ok], ys[ok]))
            if r.status == "diverged":
                diverged.append((xs[ok][-1], ys[ok][-1], r.meta.get("status_step")))
    if not series:
        return None
    if diverged:
        steps = sorted({s for *_, s in diverged if s is not None})
        label += f" (diverged{' at step ' + ', '.join(map(str, steps)) if steps else ''})"
    if len(series) == 1:
        (line,) = ax.plot(*series[0], label=label, color=color, ls=ls, **kw)
    else:
        lo, hi = max(s[0][0] for s in series), min(s[0][-1] for s in series)
        grid = np.linspace(lo, hi, 200) if hi > lo else np.array([lo])
        logs = np.array([np.interp(grid, xs, np.log10(np.maximum(ys, 1e-300))) for xs, ys in series])
        label += f" (median of {len(series)} seeds, band: min-max)"
        (line,) = ax.plot(grid, 10 ** np.median(logs, axis=0), label=label, color=color, ls=ls, **kw)
        ax.fill_between(grid, 10 ** logs.min(axis=0), 10 ** logs.max(axis=0), color=line.get_color(), alpha=0.2, lw=0)
        d.banded = True
    c = line.get_color()
    for dx, dy, _ in diverged:  # where a diverged run's last finite evaluation was, named in the plot
        ax.plot([dx], [dy], marker="X", ms=10, mew=1, mec="black", color=c, ls="none", zorder=5)
        earlier = sum(t.get_text() == "diverged" for t in ax.texts)  # stacked: one run's label never hides another's
        ax.annotate(
            "diverged",
            (dx, dy),
            xytext=(10, -14 - 12 * earlier),  # below right: inside the axes, clear of the title (markers sit near loss 1)
            textcoords="offset points",
            ha="left",
            va="top",
            fontsize=7,
            color=c,
            fontweight="bold",
            arrowprops={"arrowstyle": "-", "color": c, "lw": 0.8},
        )
        d.diverged_marked = True
    return line


def _pick(spec: Any, i: int, n: int, opt: str) -> Any:
    if spec == "optimizer":
        return COLORS.get(opt)
    if isinstance(spec, str) and spec in ("viridis", "plasma"):
        import matplotlib

        return matplotlib.colormaps[spec](0.85 * i / max(1, n - 1))  # its bright yellow end is nearly invisible
    if isinstance(spec, (list, tuple)):
        return spec[i % len(spec)]
    return spec


def draw_curves(d: FigureData, ax, p: Curves) -> None:
    ends: dict[str, float] = {}  # a sweep's final training time, for runs continued from it
    ax.set_xscale(p.xscale)  # before the curves: a log axis leaves out x <= 0 (``curve``)
    for s in p.series:
        values = d.values(s.sweep, s.by) if s.by else [None]
        values = values[::-1] if s.reverse else values
        for i, v in enumerate(values):
            where = {**s.where, **({s.by: v} if s.by else {})}
            runs = d.runs(s.sweep, **{k.replace(".", "__"): w for k, w in where.items()})
            if not runs:
                continue
            run = runs[0]
            parent = run.job.parent
            offset = ends.get(parent.sweep, 0.0) if parent is not None else 0.0
            label = s.label.format(
                label=run.label(), short=run.label(("optimizer.lr", "optimizer.tau")), kv=kv(s.by, v) if s.by else ""
            )
            label = join_label(s.name, run.label()) if s.name else label
            opt = run.cfg("optimizer.name", "")
            kw = {"lw": s.lw} if s.lw else {}
            color, ls = _pick(s.color, i, len(values), opt), _pick(s.ls, i, len(values), opt)
            curve(d, ax, runs, label, panel=p.panel, x=p.x, y=s.y, color=color, ls=ls, x_offset=offset, **kw)
            ends[s.sweep] = offset + float(run.curves["wall_time"].iloc[-1])
    if p.extra is not None:
        p.extra(d, ax)
    style(ax, p.title, p.xlabel, p.ylabel, p.xscale, ncol=p.ncol)


def draw_facets(d: FigureData, f: Facets) -> None:
    rows = []  # (sweep, row value or None, column values)
    for sweep in f.sweeps:
        for rv in d.values(sweep, f.rows) if f.rows not in (None, "sweep") else [None]:
            rows.append((sweep, rv, d.values(sweep, f.cols)))
    lines = sorted({v for s in f.sweeps for v in d.values(s, f.lines)})
    if len(rows) == 1 and len(lines) == 1:
        return draw_one_panel(d, f, rows[0], lines[0])
    ncols = max(len(r[2]) for r in rows)
    fig, axes = new_figure(ncols, len(rows), *f.size, sharey=True)
    for r, (sweep, rv, cols) in enumerate(rows):
        head = sweep if f.rows == "sweep" else (kv(f.rows, rv) if f.rows else "")
        for c, cv in enumerate(cols):
            ax, panel = axes[r, c], f"{head} {kv(f.cols, cv)}".strip()
            for i, lv in enumerate(lines):
                where = {f.cols: cv, f.lines: lv, **({f.rows: rv} if rv is not None else {})}
                runs = d.runs(sweep, **{k.replace(".", "__"): w for k, w in where.items()})
                if runs:
                    curve(d, ax, runs, kv(f.lines, lv), panel=panel, color=PALETTE[i % len(PALETTE)])
            title = f"{f.prefix} {OPTIMIZER_NAMES.get(sweep, sweep) if f.rows == 'sweep' else head} {kv(f.cols, cv)}"
            xlabel, ylabel = FACET_TIME if r == len(rows) - 1 else "", "test loss" if c == 0 else ""
            style(ax, " ".join(title.split()), xlabel, ylabel, fontsize=8, shown=False)
        for c in range(len(cols), ncols):
            axes[r, c].axis("off")
    # One time axis for all panels: a panel whose runs all diverged at once would otherwise
    # zoom into its first milliseconds (overlapping tick labels).
    if ends := [ax.get_xlim()[1] for ax in axes.ravel() if ax.lines]:  # none: no run done yet ("no runs")
        for ax in axes.ravel():
            ax.set_xlim(0, max(ends))
    facet_legend(d, fig, f.lines, lines)
    fig.tight_layout(rect=(0, 0.03, 1, 0.93))
    d.save(fig)


def facet_legend(d: FigureData, fig, key: str, values: list) -> None:
    """One legend above a grid for the lines every panel shares (a legend in each panel covers its data)."""
    from matplotlib.lines import Line2D

    seeds = " (median of the seeds, band: min-max)" if d.banded else ""
    handles = [Line2D([], [], color=PALETTE[i % len(PALETTE)], label=kv(key, v) + seeds) for i, v in enumerate(values)]
    if d.diverged_marked:
        handles.append(Line2D([], [], marker="X", ms=8, mec="black", color="0.6", ls="none", label="diverged (last value)"))
    fig.legend(handles=handles, loc="upper center", ncol=len(handles), fontsize=8, frameon=False, bbox_to_anchor=(0.5, 1.0))


def draw_one_panel(d: FigureData, f: Facets, row: tuple, lv: Any) -> None:
    """Facets with one line per panel and one row (a reduced grid): one panel, a line per column value."""
    (sweep, rv, cols), (fig, axes) = row, new_figure(1, 1, 6.4, 4.2)
    head = f"{f.prefix} {kv(f.lines, lv)}" + (f" {kv(f.rows, rv)}" if rv is not None and f.rows != "sweep" else "")
    for i, cv in enumerate(cols):
        where = {f.cols: cv, f.lines: lv, **({f.rows: rv} if rv is not None else {})}
        if runs := d.runs(sweep, **{k.replace(".", "__"): w for k, w in where.items()}):
            curve(d, axes[0, 0], runs, kv(f.cols, cv), panel=head, color=PALETTE[i % len(PALETTE)])
    style(axes[0, 0], " ".join(head.split()))
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    d.save(fig)


def draw(d: FigureData) -> None:
    """Draw a figure's declared panels (one ``Facets``, or one axes per panel in ``size``'s columns;
    a ``Curves`` panel none of whose sweeps the preset declares is left out)."""
    f = d.figure
    if len(f.panels) == 1 and isinstance(f.panels[0], Facets):
        return draw_facets(d, f.panels[0])
    declared = {s.name for s in f.runs(d.preset)}  # a preset may leave a setup out (fig3b: the authors')
    panels = [p for p in f.panels if not isinstance(p, Curves) or any(s.sweep in declared for s in p.series)]
    cols, width, height = f.size
    width += LEGEND_WIDTH if any(isinstance(p, Curves) for p in panels) else 0.0  # the legends sit beside the axes
    fig, axes = new_figure(cols, -(-len(panels) // cols), width, height, sharey=f.sharey)
    for ax, p in zip(axes.ravel(), panels):
        draw_curves(d, ax, p) if isinstance(p, Curves) else p.draw(d, ax, **p.kw)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    d.save(fig)
