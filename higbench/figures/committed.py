"""A claim measured again from the committed results, without the run files.

A figure's data files hold every run it used (``<id>.json``: sweep, seed, overrides, status,
run file) and every point it plotted (``<id>.csv``: one row per evaluation, the run file it
came from; all of a run's evaluations up to 1,000, its first, last and lowest beyond). This
module rebuilds a figure's runs from them, duck-typed as the claims read runs
(``runs(sweep, **where)`` with ``curves``, ``cfg``, ``status``, ``seed``, ``logs``), so a rule
changed in this revision is applied to the committed runs by the same measurement code as a
fresh build (``remeasure``). What the plotted data lack (a run's per-update timings, weights,
logs other than the y-space trajectory) is missing here, and a claim that needs it fails as
it would on a run without them; a config value no override sets reads as its default.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pandas as pd
import yaml

from higbench.claims.rules import budget_of, finish, judge, read_results_csv, read_results_json, rule_why
from higbench.errors import dotted_get
from higbench.figures.data import LabelledRun

GROUPS = {"optimizer": "optimizer.name", "problem": "problem.name"}  # a config group's choice, as the config names it
TRAJECTORY = "trajectory"  # fig1's y-space panels: the run's logged probe_output


def scalar(text: str) -> Any:
    """An override's value as Hydra reads it: int, float (1e-6 too, which YAML 1.1 leaves a string), else YAML."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return yaml.safe_load(text) if text else None


def parse_overrides(overrides: list[str]) -> dict[str, Any]:
    """Hydra override strings ("optimizer.lr=0.01") as a dict of values."""
    out = {}
    for item in overrides:
        key, _, text = item.partition("=")
        out[GROUPS.get(key, key)] = scalar(text)
    return out


@dataclass
class CommittedRun(LabelledRun):
    """One run of a figure, read back from its data files."""

    entry: dict
    figure: str
    points: pd.DataFrame  # its rows of <id>.csv
    updates: int | None = None  # the updates it made, where a row measured from its run file stored them
    resolved: dict = field(default_factory=dict)  # its config as the CLI composes its overrides (``resolve``)
    parent_end: float | None = None  # where its parent's plotted curve ends (the continued run is drawn after it)
    config: dict = field(init=False)

    def __post_init__(self):
        self.config = parse_overrides(self.entry["overrides"])
        searched = self.entry["sweep"].endswith("/search")
        self.job = SimpleNamespace(
            figure=self.figure, sweep=self.entry["sweep"], seed=self.entry["seed"], search=[] if searched else None, parent=None
        )
        self.job.overrides = {k: v for k, v in self.config.items() if k != "init_from"}

    meta: dict = field(init=False, default_factory=dict)  # the run file's metadata: not committed
    path = property(lambda self: self.entry["path"])
    seed = property(lambda self: self.entry["seed"])
    status = property(lambda self: self.entry["status"])
    ok = property(lambda self: self.entry["status"] in ("completed", "diverged"))

    def cfg(self, key: str, default: Any = None) -> Any:
        """An override's value, else the composed config's (the default the run had)."""
        if key in self.config:
            return self.config[key]
        return dotted_get(self.resolved, key, default)

    @property
    def curves(self) -> pd.DataFrame:
        """Its evaluations: wall_time (or epoch, as plotted), step where the run evaluated every so many
        updates and every evaluation is plotted, and every metric plotted against them."""
        rows = self.points[~self.points["panel"].str.startswith(TRAJECTORY)]
        frames = []
        for x_name, g in rows.groupby("x_name", sort=False):
            # pivot, not pivot_table: a diverged run's NaN evaluation stays (its final loss is then inf, as in a build)
            wide = g.drop_duplicates(["x", "y_name"]).pivot(index="x", columns="y_name", values="y").sort_index()
            frames.append(wide.rename_axis(None, axis=1).reset_index().rename(columns={"x": x_name}))
        if not frames:
            return pd.DataFrame({"wall_time": [], "step": [], "test_loss": []})
        c = max(frames, key=len)
        if "wall_time" in c and self.config.get("init_from"):  # a continued run is drawn after its parent
            c["wall_time"] -= self.parent_end if self.parent_end is not None else c["wall_time"].iloc[0]
        if "step" not in c and self.config.get("eval_unit") == "updates" and len(c) < 1000:
            c["step"] = np.arange(len(c)) * int(self.config.get("eval_every", 1))  # every evaluation plotted
        elif "step" not in c and self.updates and "wall_time" in c and len(c):
            c["step"] = self.updates * c["wall_time"] / c["wall_time"].iloc[-1]  # a constant update rate: an estimate
        return c

    @property
    def logs(self) -> dict[str, np.ndarray]:
        t = self.points[self.points["panel"].str.startswith(TRAJECTORY)]
        return {"probe_output": t[["x", "y"]].to_numpy(dtype=float)} if len(t) else {}


def resolve_configs(entries: list[dict]) -> list[dict]:
    """Each run's config as the CLI composes its overrides (Hydra, ``higbench.jobs.compose``); {} for
    a run whose overrides no longer compose (a key since removed): its overrides alone then."""
    from higbench.jobs import compose, hydra_conf

    out = []
    with hydra_conf():
        for e in entries:
            try:
                out.append(compose(tuple(o for o in e["overrides"] if not o.startswith("init_from="))))
            except Exception:  # noqa: BLE001 - an old override: fall back to the overrides
                out.append({})
    return out


def _match(value: Any, want: Any) -> bool:
    if isinstance(want, float) and isinstance(value, (int, float)):
        return math.isclose(value, want, rel_tol=1e-9)
    return value == want


@dataclass
class CommittedFigure:
    """A figure's runs and budgets as its committed data files give them."""

    info: dict
    table: pd.DataFrame
    updates: dict[str, int] = field(default_factory=dict)  # run file -> updates made (``CommittedRun.updates``)

    @classmethod
    def load(cls, out_dir: Path, fid: str, updates: dict[str, int] | None = None) -> CommittedFigure:
        info = read_results_json(Path(out_dir) / f"{fid}.json")
        path = Path(out_dir) / f"{fid}.csv"
        table = read_results_csv(path) if os.path.lexists(path) else pd.DataFrame(columns=["run"])
        return cls(info, table, updates or {})

    @property
    def frame(self) -> pd.DataFrame:
        """A table's measured values (<id>.csv of a table: the benchmark's frame as the table drew it)."""
        return self.table

    @property
    def budgets(self) -> dict[str, str]:
        return self.info.get("budgets", {})

    @property
    def jobs(self) -> list:
        return [r.job for r in self._runs]

    def missing(self) -> list:
        return []

    @property
    def _runs(self) -> list[CommittedRun]:
        if "_cache" not in self.__dict__:
            by_run = dict(tuple(self.table.groupby("run"))) if "run" in self.table else {}
            empty = self.table.iloc[:0]
            entries = self.info.get("runs", [])
            resolved = resolve_configs(entries)
            runs = [
                CommittedRun(e, self.info["id"], by_run.get(e["path"], empty), self.updates.get(e["path"]), cfg)
                for e, cfg in zip(entries, resolved)
            ]
            for r in runs:  # init_from names the parent's run file where it was run: the parent as listed here
                parent = str(r.config.get("init_from") or "")
                found = next((p for p in runs if parent == p.path or parent.endswith("/" + p.path)), None)
                r.config["init_from"] = found.path if found else (parent or None)
                r.job.parent = found.job if found else None
            for r in runs:
                if r.job.parent is not None:
                    parent = next(p for p in runs if p.job is r.job.parent)
                    rows = parent.points[parent.points["x_name"] == "wall_time"]
                    r.parent_end = float(rows["x"].max()) if len(rows) else None
            self.__dict__["_cache"] = runs
        return self.__dict__["_cache"]

    def runs(self, sweep: str | None = None, only_ok: bool = True, **where: Any) -> list[CommittedRun]:
        out = []
        for r in self._runs:
            if sweep is not None and r.job.sweep != sweep:
                continue
            if any(not _match(r.cfg(k.replace("__", ".")), v) for k, v in where.items()):
                continue
            if not only_ok or r.status in ("completed", "diverged"):
                out.append(r)
        return out

    def values(self, sweep: str, key: str) -> list:
        return sorted({v for r in self._runs if r.job.sweep == sweep and (v := r.cfg(key)) is not None})


def remeasure(out_dir: Path, claim, updates: dict[str, int] | None = None, note: str = "") -> dict:
    """The claim measured again on the committed runs of ``out_dir`` by this revision's code: its
    row (as a fresh build stores it), marked as re-measured from the plotted data. ``updates``:
    the updates each run made (run file -> count) where the plotted data count time only; its
    update axis is then that count spread evenly over its training time (said in the row)."""
    datas = {f: CommittedFigure.load(out_dir, f, updates) for f in claim.figures}
    preset = datas[claim.figures[0]].info.get("preset", "-")
    row = judge(claim, datas, preset)
    runs = [r for d in datas.values() for r in d.runs()]
    budgets = sorted({budget_of(r) for r in runs if r.cfg("budget.seconds") is not None})
    row["budget"] = "; ".join(budgets) or row["budget"]
    if updates:
        note += "; update counts from the row measured on the run files, spread evenly over each run's training time"
    row["remeasured"] = f"re-measured {time.strftime('%Y-%m-%d')} from the committed plotted data{note}"
    return finish(claim, row)


def extend(out_dir: Path, claim, more, note: str) -> dict:
    """The committed row of ``claim`` with the values ``more(datas)`` measures on the committed runs
    added (the same function the claim's measurement calls): where the rest of its measurement
    needs what the plotted data lack."""
    datas = {f: CommittedFigure.load(out_dir, f) for f in claim.figures}
    info = read_results_json(Path(out_dir) / f"{claim.figures[0]}.json")
    row = next(c for c in info["claims"] if c["id"] == claim.id)
    row = {**row, "values": {**row.get("values", {}), **more(datas)}}
    row["remeasured"] = f"values added {time.strftime('%Y-%m-%d')} from the committed plotted data: {note}"
    return finish(claim, {**row, "why": rule_why(row["why"])})


def store(out_dir: Path, row: dict) -> Path:
    """Put a claim's row into the data file of its first figure, in place of the one there."""
    path = Path(out_dir) / f"{row['figures'][0]}.json"
    info = read_results_json(path)
    claims = info.get("claims", [])
    info["claims"] = [row if c["id"] == row["id"] else c for c in claims]
    if row["id"] not in {c["id"] for c in claims}:
        info["claims"].append(row)
    path.write_text(json.dumps(info, indent=1, default=str) + "\n")
    return path


def redrawable() -> list[str]:
    """The figures whose every panel is drawn from what the plotted data hold (``Figure.redrawable``:
    curves; fig. 1's neurons, fig. 7's epoch axis, the trajectories of 2a, 3a, 4a and the reference
    comparison need the run files), in the paper's order."""
    from higbench.figures import registry

    return [fid for fid, f in registry.figures().items() if f.redrawable]


def redraw(out_dir: Path, fid: str) -> Path:
    """Draw figure ``fid`` again from its committed data files, by this revision's plotting code: its
    picture and its plotted data (<id>.png, .pdf, .csv); its data file keeps its runs and claims, and
    records the drawing (revision, date, machine, load) beside when its runs were made."""
    from higbench.figures import plot, registry
    from higbench.figures.build import provenance
    from higbench.figures.data import FigureData
    from higbench.figures.spec import Preset

    if fid not in (ids := redrawable()):
        raise ValueError(f"{fid}: drawn from what the run files hold, not the plotted data (redrawable: {', '.join(ids)})")
    committed = CommittedFigure.load(out_dir, fid)

    class Data(FigureData):
        def runs(self, sweep=None, only_ok=True, **where):
            return committed.runs(sweep, only_ok, **where)

        def missing(self):
            return []

    figure = registry.figures()[fid]
    data = Data(figure, Preset(committed.info["preset"]), Path(out_dir), committed.jobs, budgets=committed.budgets)
    data.notes = list(committed.info.get("notes", []))
    (figure.plot or plot.draw)(data)
    data.write_data()
    info = dict(committed.info)
    info["made"] = {**info.get("made", {}), **provenance(), "redrawn": "from the committed plotted data"}
    path = Path(out_dir) / f"{fid}.json"
    path.write_text(json.dumps(info, indent=1, default=str) + "\n")
    return path
