"""`make figures`: find the runs the figures need, run the missing ones, draw, report.

from higbench.figures.build import build
build(["fig1", "fig2b"], preset="quick", runs_root="outputs", out_dir="figures")
"""

from __future__ import annotations

import os
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

from higbench.figures import plot, registry
from higbench.figures.claims import judge
from higbench.figures.data import FigureData
from higbench.figures.runs import Composer, Job, RunIndex, expand, job_seconds, launch, resolve
from higbench.figures.spec import Figure, Preset


@dataclass
class BuildResult:
    launched: int = 0
    run_files: list[Path] = field(default_factory=list)
    drawn: list[str] = field(default_factory=list)
    errors: dict[str, str] = field(default_factory=dict)
    missing: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0


def _budgets(figure: Figure, preset: Preset) -> dict[str, str]:
    per = {s.name: s.budget.describe(preset) for s in figure.runs(preset)}
    if not per:
        return {"all runs": "no runs (benchmark script's table)"}
    values = sorted(set(per.values()))
    return {"all runs": values[0]} if len(values) == 1 else per


class Builder:
    def __init__(
        self,
        preset: str,
        runs_root: str | Path = "outputs",
        out_dir: str | Path = "figures",
        *,
        jobs: int | None = None,
        launcher: str = "auto",
        log=print,
    ):
        self.preset = Preset(preset, str(runs_root))
        self.runs_root = Path(runs_root)
        self.out_dir = Path(out_dir)
        self.n_jobs = jobs or max(1, min(os.cpu_count() or 1, 2))
        self.launcher = launcher
        self.log = log
        self.composer = Composer(self.runs_root / "figures-runs" / ".compose-cache.json")
        self.index = RunIndex.scan(self.runs_root)
        self.jobs: dict[str, list[Job]] = {}

    def jobs_of(self, figure: Figure) -> list[Job]:
        if figure.id not in self.jobs:
            self.jobs[figure.id] = expand(figure, self.preset)
        return self.jobs[figure.id]

    def resolve(self, figures: list[Figure]) -> list[Job]:
        todo = [j for f in figures for j in self.jobs_of(f)]
        resolve(todo, self.composer, self.index)
        return todo

    def pending(self, figures: list[Figure], launched: set[str]) -> list[Job]:
        """Jobs to run now: not done, parents done, not yet tried in this build (deduplicated)."""
        out, seen = [], set()
        for job in self.resolve(figures):
            if job.done or job.status == "waiting" or job.identity in launched or job.identity in seen:
                continue
            seen.add(job.identity)
            out.append(job)
        return out

    def run_missing(self, figures: list[Figure], result: BuildResult) -> None:
        launched: set[str] = set()
        while True:
            todo = self.pending(figures, launched)
            if not todo:
                break
            written = launch(todo, self.runs_root, n_jobs=self.n_jobs, launcher=self.launcher, log=self.log)
            result.launched += len(todo)
            result.run_files.extend(written)
            launched.update(j.identity for j in todo)
            for path in written:
                self.index.add(path)

    def plan(self, figures: list[Figure]) -> list[tuple[str, int, int, float]]:
        """(figure, runs needed, runs missing, training seconds missing) without running."""
        self.resolve(figures)
        rows, seen = [], set()
        for f in figures:
            jobs = self.jobs_of(f)
            miss = [j for j in jobs if not j.done]
            new = []
            for j in miss:
                key = j.identity or (j.figure, j.sweep, j.seed, tuple(j.override_list()))
                if key not in seen:
                    seen.add(key)
                    new.append(j)
            rows.append((f.id, len(jobs), len(miss), sum(job_seconds(j) for j in new)))
        return rows

    def figure_data(self, figure: Figure) -> FigureData:
        jobs = self.jobs_of(figure)
        if any(j.config is None and j.status != "waiting" for j in jobs):
            resolve(jobs, self.composer, self.index)
        data = FigureData(figure, self.preset, self.out_dir, jobs, budgets=_budgets(figure, self.preset))
        if figure.notes is not None:
            data.notes = list(figure.notes(self.preset))
        return data

    def draw(self, figure: Figure, result: BuildResult) -> None:
        data = self.figure_data(figure)
        extra: dict = {}
        try:
            (figure.plot or plot.draw)(data)  # declared panels, or the figure's own function
            if figure.kind == "figure":
                data.write_data()
            result.drawn.append(figure.id)
        except Exception as exc:  # noqa: BLE001 - one broken figure does not stop the others
            result.errors[figure.id] = f"{type(exc).__name__}: {exc}"
            extra["error"] = traceback.format_exc(limit=6)
            self.log(f"[figures] {figure.id}: plot failed: {type(exc).__name__}: {exc}")
        extra["claims"] = self.check_claims(figure)
        extra["made"] = provenance()
        miss = len(data.missing())
        if miss:
            result.missing[figure.id] = miss
        data.write_sidecar(extra)

    def check_claims(self, figure: Figure) -> list[dict]:
        known, out = registry.figures(), []
        for c in (c for c in registry.claims().values() if c.figures[0] == figure.id):
            datas = {fid: self.figure_data(known[fid]) for fid in c.figures}
            out.append(judge(c, datas, self.preset.name))
        return out

    def close(self) -> None:
        self.composer.close()


def provenance() -> dict:
    """Where and when a figure's runs were judged: git revision, date, machine and load."""
    import platform
    import subprocess

    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=5).stdout.strip()
    except OSError:
        rev = ""
    machine = f"{os.cpu_count()} CPU cores ({platform.machine()} {platform.system()})"
    load = "load {:.1f} {:.1f} {:.1f}".format(*os.getloadavg()) if hasattr(os, "getloadavg") else ""
    return {
        "revision": rev or "unknown",
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": machine,
        "load": load,
    }


def build(
    ids: list[str],
    preset: str = "quick",
    runs_root: str | Path = "outputs",
    out_dir: str | Path = "figures",
    *,
    jobs: int | None = None,
    launcher: str = "auto",
    run: bool = True,
    report: bool = True,
    bench: bool = True,
    log=print,
) -> BuildResult:
    t0 = time.perf_counter()
    figures = registry.select(ids)
    result = BuildResult()
    if run and bench and any(f.id in ("table3", "table4", "table5") for f in figures):
        from higbench.figures.tables import ensure_bench

        ensure_bench(Preset(preset, str(runs_root)), log)  # before the tables declare their runs
    builder = Builder(preset, runs_root, out_dir, jobs=jobs, launcher=launcher, log=log)
    try:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        if run:
            builder.run_missing(figures, result)
        else:
            builder.resolve(figures)
        for f in figures:
            builder.draw(f, result)
        if report:
            from higbench.figures.report import write_report

            write_report(Path(out_dir))
    finally:
        builder.close()
    result.seconds = time.perf_counter() - t0
    return result


def plan(ids: list[str], preset: str, runs_root: str | Path = "outputs") -> list[tuple[str, int, int, float]]:
    builder = Builder(preset, runs_root, "figures")
    try:
        return builder.plan(registry.select(ids))
    finally:
        builder.close()


__all__ = ["build", "plan", "Builder", "BuildResult"]
