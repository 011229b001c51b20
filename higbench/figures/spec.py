"""What a figure is, as data: its runs (``Sweep``s of Hydra overrides, values per preset) and
its panels (``higbench.figures.plot``), or a plot function for the few that draw fields.

Presets. ``PRESETS`` maps each preset to the one it falls back to: a value (grid, seeds,
budget, per-problem override) with no entry for a preset is taken from the next preset of
its chain (smoke -> quick -> paper). Adding a preset is one entry here plus the values it
wants different from its fallback (``Budget(seconds={..., "standard": 600})``,
``PerPreset(paper, standard=[...])``); everything else it inherits.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

from higbench.errors import dotted_get
from higbench.errors import override_value as fmt
from higbench.jobs import Job

# Each preset falls back to another for what it does not set. smoke: code paths, tiny budgets;
# quick: scaled-down budgets (~45 min on 2 cores); standard: quick's grids with budgets sized so
# that most claims can show (~2 h on 2 cores); paper: the paper's grids and budgets.
# long: standard's grids with the budgets the paper-hour claims need (osc-2/osc-3: the paper's
# hour of oscillator updates, ~740 s; Poisson: HIG at the paper's b=64 for its hour of updates).
PRESETS: dict[str, str | None] = {"smoke": "quick", "quick": "paper", "standard": "quick", "long": "standard", "paper": None}
# Presets whose runs stop after this many updates whatever their seconds budget (code paths only).
UPDATES_ONLY = {"smoke": 2}
# Overrides a preset applies to every run of a problem (key: the problem's config group).
# smoke: small test sets; quick: a smaller dipole test set (an evaluation of 1024 samples
# through 384 Crank-Nicolson steps costs about as much as 10 Adam updates on 2 cores).
PROBLEM_OVERRIDES: dict[str, dict[str, dict[str, Any]]] = {
    "smoke": {
        "toy": {"problem.test_size": 64},
        "oscillator": {"problem.test_size": 64},
        "poisson": {"problem.test_size": 32},
        "dipole": {"problem.test_size": 16},
        "dipole_cnn": {"problem.test_size": 16},
    },
    "quick": {"dipole": {"problem.test_size": 256}, "dipole_cnn": {"problem.test_size": 256}},
}


def lookup(values: dict[str, Any], preset: str, default: Any = None) -> Any:
    """``values[preset]``, else the value of the next preset of its fallback chain."""
    name: str | None = preset
    while name is not None:
        if name in values:
            return values[name]
        name = PRESETS.get(name)
    return default


@dataclass(frozen=True)
class Preset:
    name: str
    runs_root: str = "outputs"  # where runs and benchmark outputs (<runs_root>/bench) are looked for

    def __post_init__(self):
        if self.name not in PRESETS:
            raise ValueError(f"--preset {self.name!r}: expected one of {', '.join(PRESETS)}")

    def problem_overrides(self, problem: str) -> dict[str, Any]:
        return dict(lookup({k: v[problem] for k, v in PROBLEM_OVERRIDES.items() if problem in v}, self.name, {}))


class PerPreset:
    """A value per preset: ``PerPreset([1e-4, 1e-3, 1e-2], smoke=[1e-4])``; missing presets fall back."""

    def __init__(self, paper: Any, quick: Any = None, smoke: Any = None, **more: Any):
        self.values = {"paper": paper, **{k: v for k, v in dict(quick=quick, smoke=smoke, **more).items() if v is not None}}

    def for_preset(self, preset: Preset) -> Any:
        return lookup(self.values, preset.name)


def for_preset(value: Any, preset: Preset) -> Any:
    """``value`` with every ``PerPreset`` inside it (dicts, lists, dataclasses) chosen for ``preset``."""
    if isinstance(value, PerPreset):
        return value.for_preset(preset)
    if isinstance(value, dict):
        return {k: for_preset(v, preset) for k, v in value.items()}
    if isinstance(value, list):
        return [for_preset(v, preset) for v in value]
    if isinstance(value, (Sweep, SeedSearch)):
        return dataclasses.replace(
            value, **{f.name: for_preset(getattr(value, f.name), preset) for f in dataclasses.fields(value)}
        )
    return value


@dataclass(frozen=True)
class Budget:
    """A run's budget per preset: training seconds (``{"paper": 3600, "quick": 120}``) or a number
    of updates (timing runs, one evaluation at the start and one at the end)."""

    seconds: dict[str, float] | None = None
    updates: dict[str, int] | None = None

    def overrides(self, preset: Preset) -> dict[str, Any]:
        if self.updates is not None:
            n = int(lookup(self.updates, preset.name, 1))
            return {"budget.seconds": None, "budget.max_updates": n, "eval_unit": "updates", "eval_every": n}
        if preset.name in UPDATES_ONLY or self.seconds is None:
            n = UPDATES_ONLY.get(preset.name, 2)
            return {"budget.seconds": None, "budget.max_updates": n, "eval_unit": "updates", "eval_every": 1}
        return {"budget.seconds": float(lookup(self.seconds, preset.name))}

    def describe(self, preset: Preset) -> str:
        o = self.overrides(preset)
        return f"{o['budget.max_updates']} updates" if o.get("budget.max_updates") is not None else f"{o['budget.seconds']:g} s"


@dataclass
class SeedSearch:
    """The authors' "best stable run of a fixed seed": short runs over ``seeds`` first, then the
    sweep's run with the best stable one (``runs.pick_seed``). ``overrides`` replace the sweep's
    values in the search runs; the search runs form the sweep ``<name>/search``."""

    seeds: list[int] | PerPreset
    budget: Budget
    overrides: dict[str, Any] = field(default_factory=dict)


@dataclass
class Sweep:
    """Runs of one setting: fixed overrides x grid (cartesian) x seeds; values may be ``PerPreset``.
    init_from: another sweep of the figure whose final weights (same seed) each run starts from."""

    name: str
    fixed: dict[str, Any]
    budget: Budget
    grid: dict[str, Any] = field(default_factory=dict)
    seeds: Any = field(default_factory=lambda: [0])
    init_from: str | None = None
    seed_search: SeedSearch | None = None


@dataclass
class Figure:
    """One figure or table: its sweeps (a list, or a function of the preset) and either its
    panels (drawn by ``plot.draw``, which the builder calls) or a plot function ``plot(data)``."""

    id: str
    title: str
    sweeps: list[Sweep] | Callable[[Preset], list[Sweep]]
    plot: Callable[..., None] | None = None
    panels: list = field(default_factory=list)
    size: tuple = (1, 6.4, 4.2)  # columns, and width and height of one panel (inches); rows: as many as the panels fill
    kind: str = "figure"
    notes: Callable[[Preset], list[str]] | None = None  # deviations from the paper at a preset
    sharey: bool = False
    # Every panel drawn from its plotted data (<id>.csv) alone, so ``committed.redraw`` can draw it
    # again without the run files (not: neurons, trajectories and fields, an epoch axis, update times).
    redrawable: bool = False
    bench: bool = False  # reads the benchmark's table (tables 3-5): a build runs the benchmark first where it is missing

    def runs(self, preset: Preset) -> list[Sweep]:
        return for_preset(self.sweeps(preset) if callable(self.sweeps) else self.sweeps, preset)


# -- the jobs a figure needs at a preset --------------------------------------------------
def expand(figure: Figure, preset: Preset) -> list[Job]:
    """The jobs of a figure at a preset, in declaration order (a parent or seed search before its jobs)."""
    by_name: dict[str, list[Job]] = {}
    jobs: list[Job] = []
    for sweep in figure.runs(preset):
        mine = _sweep_jobs(figure.id, sweep, preset)
        if sweep.seed_search is not None:
            mine = _with_search(figure.id, sweep, mine, preset, jobs)
        if sweep.init_from is not None:
            if not (parents := by_name.get(sweep.init_from)):
                raise ValueError(f"{figure.id}: sweep {sweep.name!r} starts from {sweep.init_from!r}, not declared before it")
            for job in mine:
                job.parent = next((p for p in parents if p.seed == job.seed), parents[0])
        by_name[sweep.name] = mine
        jobs.extend(mine)
    return jobs


def _sweep_jobs(figure_id: str, sweep: Sweep, preset: Preset) -> list[Job]:
    """Fixed overrides x grid (cartesian) x seeds, then the budget and the preset's problem overrides."""
    problem = sweep.fixed.get("problem")
    extra = preset.problem_overrides(str(problem)) if problem is not None else {}
    out = []
    for combo in itertools.product(*sweep.grid.values()):
        for seed in sweep.seeds:
            ov = {**sweep.fixed, **dict(zip(sweep.grid, combo)), "seed": seed, **sweep.budget.overrides(preset)}
            out.append(Job(figure_id, sweep.name, {**ov, **{k: v for k, v in extra.items() if k not in ov}}, seed))
    return out


def _with_search(figure_id: str, sweep: Sweep, mine: list[Job], preset: Preset, jobs: list[Job]) -> list[Job]:
    """One main job per grid point (seed to be picked) after its seed-search jobs (added to ``jobs``)."""
    search = sweep.seed_search
    main: dict[tuple, Job] = {}
    searches: dict[tuple, list[Job]] = {}  # grid points with the same search share its runs
    for job in mine:
        key = tuple((k, fmt(v)) for k, v in job.overrides.items() if k != "seed")
        if key in main:
            continue
        main[key] = job
        base = {k: v for k, v in job.overrides.items() if not k.startswith("budget.") and k not in ("eval_unit", "eval_every")}
        base.update(search.overrides)
        skey = tuple((k, fmt(v)) for k, v in base.items() if k != "seed")
        if skey not in searches:
            budget = search.budget.overrides(preset)
            searches[skey] = [Job(figure_id, f"{sweep.name}/search", {**base, "seed": s, **budget}, s) for s in search.seeds]
            jobs.extend(searches[skey])
        job.search = searches[skey]
    return list(main.values())


# -- paper facts read from conf/ (one copy: the experiment configs and per-pair defaults) ----


@cache
def _conf(rel: str) -> dict:
    import yaml

    from higbench.config import config_dir

    return yaml.safe_load((Path(config_dir()) / rel).read_text()) or {}


def paper_grid(experiment: str, key: str) -> list:
    """A swept key's values in ``conf/experiment/<experiment>.yaml`` (the paper's grid), in order, as Hydra parses them."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    params = _conf(f"experiment/{experiment}.yaml")["hydra"]["sweeper"]["params"]
    return list(OverridesParser.create().parse_override(f"{key}={params[key]}").sweep_iterator())


def paper_setting(pair: str, key: str) -> Any:
    """A per-pair default of ``conf/problem_optimizer/<pair>.yaml`` (the paper's table 2), dotted key."""
    return dotted_get(_conf(f"problem_optimizer/{pair}.yaml"), key)
