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

from higbench.figures import registry
from higbench.figures.data import FigureData
from higbench.figures.runs import Composer, Job, RunIndex, expand, job_seconds, launch, resolve
from higbench.figures.spec import UPDATES_ONLY, Figure, Preset


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
            figure.draw(data)
            if figure.kind == "figure":
                data.write_data()
            result.drawn.append(figure.id)
        except Exception as exc:  # noqa: BLE001 - one broken figure does not stop the others
            result.errors[figure.id] = f"{type(exc).__name__}: {exc}"
            extra["error"] = traceback.format_exc(limit=6)
            self.log(f"[figures] {figure.id}: plot failed: {type(exc).__name__}: {exc}")
        extra["claims"] = self.check_claims(figure)
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


def judge(c, datas: dict, preset: str) -> dict:
    """A claim's row of the report: its rule's verdict on the runs, then the budget, seed and smoke limits."""
    missing, cause = sum(len(d.missing()) for d in datas.values()), c.cause
    try:
        measured, verdict, why = c.check(datas)
    except Exception as exc:  # noqa: BLE001 - one broken claim does not stop the others
        measured, verdict, why = "-", "n/a", f"could not be evaluated: {type(exc).__name__}: {exc}"
    if missing and verdict != "n/a":
        why += f" ({missing} run(s) missing)"
    seconds, seeds = claim_budget(datas), claim_seeds(datas)
    if c.min_seconds and verdict != "n/a" and seconds is not None and seconds < c.min_seconds:
        why = f"budget {seconds:g} s per run is below the {c.min_seconds:g} s this claim needs to show; {would(verdict)}{why}"
        verdict, cause = "n/a (budget)", ("budget", f"needs >= {c.min_seconds:g} s per run")
    elif verdict == "reproduced" and seeds < c.min_seeds:
        why = f"only {seeds} seed(s) per setting (a comparison needs the median of {c.min_seeds}): at most partly. {why}"
        verdict, cause = "partly", ("seeds", f"{seeds} seed(s) per setting at this preset")
    if preset in UPDATES_ONLY and verdict != "n/a" and any(d.jobs for d in datas.values()):
        why = f"smoke preset ({preset}: a few updates per run) checks code paths only, no verdict; {would(verdict)}{why}"
        verdict = "n/a"
    if verdict in ("not", "partly") and not cause:
        cause = ("open", "no targeted run has examined this verdict yet")
    budgets = "; ".join(sorted({b for d in datas.values() for b in d.budgets.values()}))
    return {
        "id": c.id,
        "figures": list(c.figures),
        "statement": c.statement,
        "paper": c.paper,
        "measured": measured,
        "budget": budgets,
        "verdict": verdict,
        "why": why,
        "cause": list(cause) if cause and verdict not in ("reproduced", "n/a") else None,
        "seeds": seeds,
        "preset": preset,
    }


def would(verdict: str) -> str:
    return f"the rule would say '{verdict}'. "


def _main_jobs(datas: dict) -> list:
    return [j for d in datas.values() for j in d.jobs if not j.sweep.endswith("/search")]


def claim_budget(datas: dict) -> float | None:
    """The smallest training budget in seconds of the claim's runs (None: budgets in updates)."""
    secs = [float(s) for j in _main_jobs(datas) if (s := j.overrides.get("budget.seconds")) is not None]
    return min(secs) if secs else None


def claim_seeds(datas: dict) -> int:
    """The fewest seeds of any setting (sweep and overrides but the seed) behind the claim;
    a setting whose seed came from a seed search counts as settled (the paper's fixed seed)."""
    groups: dict[tuple, set] = {}
    for j in (j for j in _main_jobs(datas) if not j.search):
        key = (j.figure, j.sweep, tuple(sorted((k, str(v)) for k, v in j.overrides.items() if k != "seed")))
        groups.setdefault(key, set()).add(j.seed)
    return min(len(s) for s in groups.values()) if groups else 99


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
