"""Figures 12-13: ablations of beta, kappa and tau on the oscillators (paper appendix C).

HIG's table-2 settings otherwise (eta=1, b=128, tau=1e-6, beta=0, kappa=-1/2); the grids are
conf/experiment/fig12a_beta.yaml, fig12b_kappa.yaml and fig13_tau.yaml.
"""

from __future__ import annotations

from higbench.figures.oscillator import gn_search
from higbench.figures.plot import Curves, Series
from higbench.figures.spec import Budget, Figure, PerPreset, Sweep, paper_grid

BUDGET = Budget(seconds={"paper": 3600, "quick": 30, "standard": 120})
FIG12 = Budget(seconds=BUDGET.seconds | {"long": 900})  # long: abl-1 past its 120 s
BETAS = paper_grid("fig12a_beta", "optimizer.beta")
KAPPAS = paper_grid("fig12b_kappa", "optimizer.kappa")
TAUS = paper_grid("fig13_tau", "optimizer.tau")


def sweep(name: str, opt: str, key: str, values: PerPreset, budget: Budget = BUDGET, **kw) -> Sweep:
    return Sweep(name, {"problem": "oscillator", "optimizer": opt}, budget, grid={key: values}, **kw)


# Categorical colours (the values are settings, not a scale); κ's name the optimizer each value stands for.
CATEGORIES = ("tab:gray", "tab:orange", "tab:purple", "tab:green", "tab:red")  # κ=1 (GD) ... -1/2 (HIG), -1 (GN)


def lines(title: str, sweep: str, key: str, panel: str) -> Curves:
    """One line per value of ``key``, in categorical colours, largest value first."""
    return Curves(title, [Series(sweep, key, label="{kv}", color=list(CATEGORIES), reverse=True, lw=1.8)], panel)


FIGURES = [
    Figure(
        "fig12",
        "Oscillator ablation: a) beta from 0 to -0.5, b) kappa from 1 to -1",
        size=(2, 4.8, 3.8),
        sweeps=[
            sweep("beta", "hig", "optimizer.beta", PerPreset(BETAS, [0.0, -0.25, -0.5], [0.0, -0.5]), FIG12),
            sweep("kappa", "hig", "optimizer.kappa", PerPreset(KAPPAS, [1.0, 0.5, 0.0, -0.5, -1.0], [1.0, -0.5]), FIG12),
        ],
        panels=[
            lines("a) oscillators, HIG: prefactor max(s)^β", "beta", "optimizer.beta", "a) beta"),
            lines("b) oscillators: exponent κ (1: GD, -1/2: HIG, -1: GN)", "kappa", "optimizer.kappa", "b) kappa"),
        ],
    ),
    # GN at the best stable seed of a search at the default tau 1e-6, then every tau.
    Figure(
        "fig13",
        "Oscillator ablation: tau from 1e-5 to 1e-10, HIG and GN",
        size=(2, 4.8, 3.8),
        sharey=True,
        sweeps=[
            sweep(
                o,
                o,
                "optimizer.tau",
                PerPreset(TAUS, [1e-5, 1e-7, 1e-10], [1e-6]),
                seed_search=gn_search(**{"optimizer.tau": 1e-6}) if o == "gn" else None,
            )
            for o in ("hig", "gn")
        ],
        panels=[
            lines(f"oscillators, {name}: truncation τ", o, "optimizer.tau", o)
            for o, name in (("hig", "HIG"), ("gn", "Gauss-Newton"))
        ],
    ),
]
