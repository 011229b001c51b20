"""Figures 4a-c, 8-11: quantum dipole control (paper 3.3, appendix B.4), MLP and CNN.

The grids of figures 8-11 are conf/experiment/fig8_dipole_adam.yaml ... fig11_dipole_cnn_hig.yaml.
The quick preset evaluates on 256 instead of 1024 test states (see spec.PROBLEM_OVERRIDES).
"""

from __future__ import annotations

import numpy as np

from higbench.claims.paper import HE, LE
from higbench.claims.rules import PAPER, float32_loss
from higbench.display import OPTIMIZER_NAMES
from higbench.figures.data import FigureData
from higbench.figures.plot import Curves, Custom, Facets, Series, legend
from higbench.figures.spec import UPDATES_ONLY, Budget, Figure, PerPreset, Preset, Sweep, paper_grid

MAIN = Budget(seconds={"paper": 3600, "quick": 60, "standard": 270})
GRID = Budget(seconds={"paper": 3600, "quick": 20, "standard": 120})
FIG4B_ADAM, FIG4B_HIG = [1e-4, 1e-3, 1e-2], [0.1, 0.5, 1.0]  # not given in the paper


def notes(p: Preset) -> list[str]:
    size = p.problem_overrides("dipole").get("problem.test_size")
    return (
        [f"deviation: test set of {size} states instead of 1024 (evaluation cost)"] if size and p.name not in UPDATES_ONLY else []
    )


# The appendix's grids (conf/experiment/<experiment>.yaml) and their reductions per preset.
GRIDS = {
    "fig8": ("Dipole: Adam for several learning rates and batch sizes", "dipole", "adam", "fig8_dipole_adam"),
    "fig9": ("Dipole: HIG for several learning rates, batch sizes and truncations tau", "dipole", "hig", "fig9_dipole_hig"),
    "fig10": (
        "Dipole with a CNN: Adam for several learning rates and batch sizes",
        "dipole_cnn",
        "adam",
        "fig10_dipole_cnn_adam",
    ),
    "fig11": (
        "Dipole with a CNN: HIG for several learning rates, batch sizes and tau",
        "dipole_cnn",
        "hig",
        "fig11_dipole_cnn_hig",
    ),
}
REDUCED = {
    "fig8": {"lr": {"quick": [1e-4, 1e-3, 1e-2], "smoke": [1e-3]}, "b": {"quick": [16, 256], "smoke": [16]}},
    "fig9": {"lr": {"quick": [0.5]}, "b": {"quick": [16], "smoke": [8]}, "tau": {"smoke": [1e-5, 1e-2]}},
    "fig10": {"lr": {"smoke": [2e-4]}, "b": {"quick": [256]}},
    "fig11": {"lr": {"quick": [0.7]}, "b": {"quick": [16], "smoke": [8]}, "tau": {"smoke": [1e-4]}},
}
KEYS = {"lr": "optimizer.lr", "b": "batch_size", "tau": "optimizer.tau"}
# cnn-1 compares the best CNN settings of figs. 10 and 11, and dip-7 the η of fig. 8 at each b:
# comparisons the median of three seeds decides
SEEDS = {fid: PerPreset([0], long=[0, 1, 2]) for fid in ("fig8", "fig10", "fig11")}  # paper: its configs, one seed


def grid_figure(fid: str, title: str, problem: str, opt: str, experiment: str) -> Figure:
    """Adam: one panel per η, a line per b; HIG: one row per b, a panel per τ, a line per η."""
    grid = {KEYS[k]: PerPreset(paper_grid(experiment, KEYS[k]), **v) for k, v in REDUCED[fid].items()}
    sweep = Sweep(opt, {"problem": problem, "optimizer": opt}, GRID, grid=grid, seeds=SEEDS.get(fid, [0]))
    cnn, name = ("CNN " if problem == "dipole_cnn" else ""), OPTIMIZER_NAMES[opt]
    if opt == "adam":
        facets = Facets([opt], "optimizer.lr", "batch_size", prefix=cnn + name)
    else:
        facets = Facets([opt], "optimizer.tau", "optimizer.lr", rows="batch_size", prefix=cnn + name, size=(3.3, 2.6))
    return Figure(fid, title, [sweep], panels=[facets])


def dip(opt: str, **kw) -> Sweep:
    return Sweep(opt, {"problem": "dipole", "optimizer": opt}, MAIN, **kw)


def fig4a(d: FigureData, ax) -> None:
    if found := d.trajectory("hig"):
        run, problem, batch, states, u = found
        prob = (states[0].double().numpy() ** 2).sum(-1)  # |Psi|^2 over (steps+1, 14)
        dt, n_x = float(problem.cfg.dt), prob.shape[1]
        t, x = np.arange(prob.shape[0]) * dt, np.arange(1, n_x + 1) * 2.0 / (n_x + 1)
        im = ax.imshow(prob.T, aspect="auto", origin="lower", extent=(t[0], t[-1], x[0], x[-1]), cmap="magma")
        ax.figure.colorbar(im, ax=ax, orientation="horizontal", fraction=0.05, pad=0.2, label="|Ψ(t,x)|²")
        uu, tu = u[0].double().numpy(), (np.arange(u.shape[1]) + 0.5) * dt
        ax2 = ax.twinx()
        ax2.plot(tu, uu, color="tab:blue", alpha=0.7, lw=1)
        ax2.set_ylabel("network output u(t)", color="tab:blue")
        for k in range(n_x):
            d.record("probability", f"x={x[k]:.3f}", run, "t", t, "abs_psi_sq", prob[:, k])
        d.record("control", "u", run, "t", tu, "u", uu)
        fin = float(problem.loss(problem.physics(batch.inputs, u), batch.targets)[0])
        title = f"a) dipole: |Ψ|² under the HIG-trained network ({run.label()})\nloss of this state: {float32_loss(fin)}"
        ax.set_title(title, fontsize=8)
    else:
        legend(ax)
    ax.set(xlabel="time t", ylabel="x")


# conf defaults; Adam's seed 0 is fig4b's run. HIG leaves the initial stage within ~130 updates,
# so it is evaluated every 10 updates: by time (every ~4 s) only 1-2 evaluations fell in that stage.
FIG4C = [
    dip("adam", seeds=PerPreset([0, 1, 2], smoke=[0])),
    Sweep(
        "hig",
        {"problem": "dipole", "optimizer": "hig", "eval_unit": "updates", "eval_every": 10},
        MAIN,
        seeds=PerPreset([0, 1, 2], smoke=[0]),
    ),
]


def float32_floor(d: FigureData, ax) -> None:
    """The float32 evaluation floor drawn as such: below it a dipole loss is rounding, not a value (a curve that
    plunges there runs into the shaded band, clipped at a decade and a half below it)."""
    floor = PAPER["float32_floor"]
    ax.axhspan(floor / 30, floor, color="0.85", zorder=0, label="below the float32 evaluation floor: rounding")
    ax.axhline(floor, color="0.4", ls=":", lw=1)
    ax.set_ylim(bottom=floor / 30)


ENERGIES = [
    Series(o, label=f"{tag} {{label}}", y=y, ls=ls) for o in ("adam", "hig") for y, ls, tag in ((LE, "-", "LE"), (HE, "--", "HE"))
]
FIGURES = [
    Figure(
        "fig4a",
        "Dipole: |Psi(t,x)|^2 under a HIG-trained network, control behind it",
        [dip("hig")],
        panels=[Custom(fig4a)],
        size=(1, 6.6, 4.4),
    ),
    Figure(
        "fig4b",
        "Dipole: Adam and HIG for several learning rates",
        [
            dip("adam", grid={"optimizer.lr": PerPreset(FIG4B_ADAM, smoke=[1e-4])}),
            dip("hig", grid={"optimizer.lr": PerPreset(FIG4B_HIG, smoke=[0.5])}),
        ],
        panels=[
            Curves(
                "b) dipole: Adam and HIG for several η (b=16)",
                [
                    Series("adam", "optimizer.lr", color=("#08306b", "#4292c6", "#9ecae1")),
                    Series("hig", "optimizer.lr", color=("#a1d99b", "#41ab5d", "#00441b")),
                ],
                extra=float32_floor,
            )
        ],
        size=(1, 6.2, 4.0),
    ),
    Figure(
        "fig4c",
        "Dipole: low- and high-energy losses, Adam (eta=1e-4) vs HIG (eta=0.5)",
        FIG4C,
        size=(1, 6.2, 4.0),
        panels=[
            Curves(
                "c) dipole: low- and high-energy losses",
                ENERGIES,
                "energy losses",
                ylabel="low-energy (LE) / high-energy (HE) loss",
                extra=float32_floor,
            )
        ],
    ),
    *(grid_figure(fid, *spec) for fid, spec in GRIDS.items()),
]
for _f in FIGURES:
    _f.notes = notes  # every figure of the family states the preset's deviations
