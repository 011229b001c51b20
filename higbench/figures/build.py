"""`make figures`: find the runs the figures need, run the missing ones, draw, report.

from higbench.figures.build import build
build(["fig1", "fig2b"], preset="quick", runs_root="outputs", out_dir="figures")
"""

from __future__ import annotations

import os
import time
import traceback
from dataclasses import dataclass, field
from datetime import datetime, timezone
from functools import cache
from pathlib import Path

from higbench.bench.tables import ensure_bench
from higbench.claims.rules import judge
from higbench.figures import plot, registry
from higbench.figures.data import FigureData
from higbench.figures.report import write_report
from higbench.figures.spec import UPDATES_ONLY, Figure, Preset, expand
from higbench.jobs import Job, Launcher, job_seconds, launch, resolve, run_index


@dataclass
class BuildResult:
    launched: int = 0
    run_files: list[Path] = field(default_factory=list)
    drawn: list[str] = field(default_factory=list)
    errors: dict[str, str] = field(default_factory=dict)
    missing: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0


class Builder:
    """The jobs of the figures at a preset, resolved against the runs root's index."""

    def __init__(
        self,
        preset: str,
        runs_root: str | Path = "outputs",
        out_dir: str | Path = "figures",
        *,
        jobs: int | None = None,
        launcher: str | Launcher = "auto",
        log=print,
    ):
        self.preset = Preset(preset, str(runs_root))
        self.runs_root, self.out_dir = Path(runs_root), Path(out_dir)
        self.n_jobs = jobs or max(1, min(os.cpu_count() or 1, 2))
        self.launcher, self.log = launcher, log
        self.index = run_index(self.runs_root)
        self.jobs: dict[str, list[Job]] = {}

    def jobs_of(self, figure: Figure) -> list[Job]:
        if figure.id not in self.jobs:
            self.jobs[figure.id] = expand(figure, self.preset)
        return self.jobs[figure.id]

    def resolve(self, figures: list[Figure]) -> list[Job]:
        todo = [j for f in figures for j in self.jobs_of(f)]
        resolve(todo, self.index)
        return todo

    def run_missing(self, figures: list[Figure], result: BuildResult) -> None:
        """Rounds of one multirun each: every job not done whose parent and seed search are
        (shared jobs once), until none is left; a job is tried once per build."""
        tried: set[str] = set()
        while True:
            todo: dict[str, Job] = {}
            for job in self.resolve(figures):
                if not job.done and job.status != "waiting" and job.identity not in tried:
                    todo.setdefault(job.identity, job)
            if not todo:
                return
            written = launch(list(todo.values()), self.runs_root, n_jobs=self.n_jobs, launcher=self.launcher, log=self.log)
            result.launched += len(todo)
            result.run_files.extend(written)
            tried.update(todo)
            self.index = run_index(self.runs_root)

    def plan(self, figures: list[Figure]) -> list[tuple[str, int, int, float]]:
        """(figure, runs needed, runs missing, training seconds missing; shared runs counted once)."""
        self.resolve(figures)
        rows, seen = [], set()
        for f in figures:
            jobs = self.jobs_of(f)
            miss = [j for j in jobs if not j.done]
            seconds = 0.0
            for j in miss:
                seconds += 0.0 if (key := _same_run(j)) in seen else job_seconds(j)
                seen.add(key)
            rows.append((f.id, len(jobs), len(miss), seconds))
        return rows

    def figure_data(self, figure: Figure) -> FigureData:
        jobs = self.jobs_of(figure)
        if any(j.config is None and j.status != "waiting" for j in jobs):
            resolve(jobs, self.index)
        per = {s.name: s.budget.describe(self.preset) for s in figure.runs(self.preset)}
        budgets = {"all runs": v[0]} if len(v := sorted(set(per.values()))) == 1 else per
        data = FigureData(
            figure, self.preset, self.out_dir, jobs, budgets=budgets or {"all runs": "no runs (benchmark script's table)"}
        )
        data.notes = list(figure.notes(self.preset)) if figure.notes is not None else []
        return data

    def draw(self, figure: Figure, result: BuildResult) -> None:
        data, extra = self.figure_data(figure), {}
        try:
            (figure.plot or plot.draw)(data)  # declared panels, or the figure's own function
            if figure.kind == "figure":
                data.write_data()
            result.drawn.append(figure.id)
        except Exception as exc:  # noqa: BLE001 - one broken figure does not stop the others
            result.errors[figure.id] = f"{type(exc).__name__}: {exc}"
            extra["error"] = traceback.format_exc(limit=6)
            self.log(f"[figures] {figure.id}: plot failed: {type(exc).__name__}: {exc}")
        known = registry.figures()
        mine = [c for c in registry.claims().values() if c.figures[0] == figure.id]
        smoke = self.preset.name in UPDATES_ONLY
        extra["claims"] = [judge(c, {f: self.figure_data(known[f]) for f in c.figures}, self.preset.name, smoke) for c in mine]
        extra["made"] = provenance() | runs_made(data)
        if miss := len(data.missing()):
            result.missing[figure.id] = miss
        data.write_sidecar(extra)


def _same_run(job: Job):
    """What makes two jobs one run: its identity, or, while it waits for its parent, its overrides and its parent's."""
    return job.identity or (tuple(job.override_list()), job.parent and _same_run(job.parent))


@cache
def _revision() -> str:
    """The checkout's short revision as run files record it ('-dirty' if modified): once per process."""
    from higbench.runner.revision import git_revision

    rev = git_revision()  # 40 hex digits, then '-dirty' if modified
    return rev[:7] + rev[40:] or "unknown"


def provenance() -> dict:
    """Where and when a figure's runs were judged: git revision, date, machine and load."""
    import platform

    return {
        "revision": _revision(),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": f"{os.cpu_count()} CPU cores ({platform.machine()} {platform.system()})",
        "load": "load {:.1f} {:.1f} {:.1f}".format(*os.getloadavg()) if hasattr(os, "getloadavg") else "",
    }


def runs_made(data: FigureData) -> dict:
    """When (UTC) and at which revisions the figure's runs were made, from their run files: a
    figure redrawn later records its own date and load (``provenance``), not its runs'."""
    metas = [r.meta for r in data.runs()]
    if not metas:
        return {}
    start = min(_utc(m["started"]) for m in metas)
    end = max(_utc(m.get("finished") or m["started"]) for m in metas)
    revisions = sorted({str(m.get("env", {}).get("git_revision", ""))[:7] for m in metas} - {""})
    tail = end.strftime("%H:%M" if end.date() == start.date() else "%Y-%m-%d %H:%M")
    span = f"{start:%Y-%m-%d %H:%M}-{tail} UTC"
    return {"runs": f"runs made {span}" + (f" at {', '.join(revisions)}" if revisions else "") + _cpu_use(metas)}


def _cpu_use(metas: list[dict]) -> str:
    """The range of the runs' CPU shares and 1-minute loads at their ends (run files since
    they record them; "" for older ones)."""
    share = [float(e["cpu_share"]) for m in metas if "cpu_share" in (e := m.get("env", {}))]
    load = [float(str(e["load_at_finish"]).split()[0]) for m in metas if (e := m.get("env", {})).get("load_at_finish")]
    parts = [f"{what} {min(v):.2f}-{max(v):.2f}" for what, v in (("CPU share", share), ("load at the end", load)) if v]
    return f"; {len(share)} of {len(metas)} runs: " + ", ".join(parts) if parts else ""


def _utc(stamp: str) -> datetime:
    """A run file's time stamp (local time with its UTC offset, ``%Y-%m-%dT%H:%M:%S%z``) in UTC."""
    return datetime.strptime(stamp, "%Y-%m-%dT%H:%M:%S%z").astimezone(timezone.utc)


def build(
    ids: list[str],
    preset: str = "quick",
    runs_root: str | Path = "outputs",
    out_dir: str | Path = "figures",
    *,
    jobs: int | None = None,
    launcher: str | Launcher = "auto",
    run: bool = True,
    report: bool = True,
    bench: bool = True,
    log=print,
) -> BuildResult:
    t0 = time.perf_counter()
    _revision()  # read before the build writes its outputs, which would make a clean checkout look modified
    figures = registry.select(ids)
    result = BuildResult()
    if run and bench and preset not in UPDATES_ONLY and any(f.bench for f in figures):
        ensure_bench(runs_root, log)  # before the tables declare their runs
    builder = Builder(preset, runs_root, out_dir, jobs=jobs, launcher=launcher, log=log)
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    if run:
        builder.run_missing(figures, result)
    else:
        builder.resolve(figures)
    for f in figures:
        builder.draw(f, result)
    if report:
        write_report(Path(out_dir), list(registry.figures()))
    result.seconds = time.perf_counter() - t0
    return result


def plan(ids: list[str], preset: str, runs_root: str | Path = "outputs") -> list[tuple[str, int, int, float]]:
    return Builder(preset, runs_root, "figures").plan(registry.select(ids))
