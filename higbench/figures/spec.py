"""What a figure is: the runs it needs (as Hydra overrides) and a plot function.

A ``Figure`` declares its runs as ``Sweep`` objects: a cartesian product of Hydra
overrides (one run per combination and seed), with the budget and the grid chosen by the
``Preset``. ``higbench.figures.runs`` turns them into jobs, finds the ones already run
(same resolved config), runs the missing ones through the CLI's Hydra multirun, and the
plot function then reads only the run files (``higbench.figures.data.FigureData``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

PRESETS = ("smoke", "quick", "standard", "paper")

# Per-problem overrides that a preset applies to every run of that problem (the config
# group choice, e.g. "dipole_cnn", is the key). smoke: small test sets so that every figure
# runs in a test; quick: a smaller dipole test set (an evaluation of 1024 samples through
# 384 Crank-Nicolson steps costs about as much as 10 Adam updates on 2 cores).
PROBLEM_OVERRIDES: dict[str, dict[str, dict[str, Any]]] = {
    "smoke": {
        "toy": {"problem.test_size": 64},
        "oscillator": {"problem.test_size": 64},
        "poisson": {"problem.test_size": 32},
        "dipole": {"problem.test_size": 16},
        "dipole_cnn": {"problem.test_size": 16},
    },
    "quick": {
        "dipole": {"problem.test_size": 256},
        "dipole_cnn": {"problem.test_size": 256},
    },
    # standard: quick's grids with budgets sized to show the claims in ~2 h on 2 cores; the
    # dipole test set stays at 256 (one evaluation of 1024 would cost ~4x per evaluation).
    "standard": {
        "dipole": {"problem.test_size": 256},
        "dipole_cnn": {"problem.test_size": 256},
    },
    "paper": {},
}

SMOKE_UPDATES = 2  # smoke preset: every run stops after this many updates


@dataclass(frozen=True)
class Preset:
    """smoke (code paths, tiny budgets), quick (scaled-down budgets, ~45 min on 2 cores),
    standard (quick's grids, budgets sized so that most claims can show: ~2 h on 2 cores),
    paper (the paper's grids and budgets)."""

    name: str
    runs_root: str = "outputs"  # where runs and benchmark outputs (<runs_root>/bench) are looked for

    def __post_init__(self):
        if self.name not in PRESETS:
            raise ValueError(f"--preset {self.name!r}: expected one of {', '.join(PRESETS)}")

    def pick(self, paper: Any, quick: Any = None, smoke: Any = None, standard: Any = None) -> Any:
        """The value for this preset; quick falls back to paper, standard and smoke to quick."""
        if self.name == "paper":
            return paper
        if self.name == "standard" and standard is not None:
            return standard
        if self.name in ("quick", "standard"):
            return paper if quick is None else quick
        return smoke if smoke is not None else (paper if quick is None else quick)

    def problem_overrides(self, problem: str) -> dict[str, Any]:
        return dict(PROBLEM_OVERRIDES[self.name].get(problem, {}))


@dataclass(frozen=True)
class Budget:
    """A run's budget under each preset.

    seconds: training-clock seconds per preset (``{"paper": 3600, "quick": 120, "standard": 600}``); the
    smoke preset always stops after ``SMOKE_UPDATES`` updates. updates: a budget in updates
    instead (timing runs of the tables), with one evaluation at the start and one at the end.
    """

    seconds: dict[str, float] | None = None
    updates: dict[str, int] | None = None

    def overrides(self, preset: Preset) -> dict[str, Any]:
        if self.updates is not None:
            n = int(self.updates.get(preset.name, self.updates.get("quick", 1)))
            return {"budget.seconds": None, "budget.max_updates": n, "eval_unit": "updates", "eval_every": n}
        if preset.name == "smoke" or self.seconds is None:
            return {"budget.seconds": None, "budget.max_updates": SMOKE_UPDATES, "eval_unit": "updates", "eval_every": 1}
        return {"budget.seconds": float(self.seconds[preset.name])}

    def describe(self, preset: Preset) -> str:
        o = self.overrides(preset)
        if o.get("budget.max_updates") is not None:
            return f"{o['budget.max_updates']} updates"
        return f"{o['budget.seconds']:g} s"


@dataclass
class SeedSearch:
    """The authors' "best stable run of a fixed seed": short runs over ``seeds`` first, then
    the sweep's run with the best stable one (``runs.pick_seed``: completed, final test loss
    finite and below the initial one, lowest final loss). ``overrides`` replace the sweep's
    values in the search runs (e.g. fig13 searches at the default tau and then sweeps tau
    with that seed). The search runs form the sweep ``<name>/search`` of the figure."""

    seeds: list[int]
    budget: Budget
    overrides: dict[str, Any] = field(default_factory=dict)


@dataclass
class Sweep:
    """Runs of one setting family: fixed overrides x grid (cartesian) x seeds.

    name: the sweep's key inside its figure (plots and init_from refer to it).
    fixed: overrides every run gets, in order ("problem", "optimizer" first).
    grid: swept overrides, key -> values (already chosen for the preset).
    init_from: the name of another sweep of the same figure; each run here starts from the
    final weights of that sweep's run with the same seed (or its only run).
    """

    name: str
    fixed: dict[str, Any]
    budget: Budget
    grid: dict[str, list[Any]] = field(default_factory=dict)
    seeds: list[int] = field(default_factory=lambda: [0])
    init_from: str | None = None
    seed_search: SeedSearch | None = None  # seeds then come from a search (one run per grid point)


@dataclass
class Figure:
    """One figure or table of the paper.

    runs(preset) -> list[Sweep]; plot(data) draws/writes the outputs from the run files
    (``data`` is a ``FigureData``). kind: "figure" (png + pdf + data csv) or "table"
    (md + csv). title: the paper's caption, shortened.
    """

    id: str
    title: str
    runs: Callable[[Preset], list[Sweep]]
    plot: Callable[..., None]
    kind: str = "figure"
    family: str = ""
    notes: Callable[[Preset], list[str]] | None = None  # deviations from the paper at a preset
