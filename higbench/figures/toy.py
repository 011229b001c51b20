"""Figure 1: the toy example (paper 2.1, appendix B.1), gamma = 1 and gamma = 0.01.

Columns: test loss over wall-clock time (median and min-max band over seeds); the
data-set mean (line) and standard deviation (band) of one hidden neuron's output over
time (for each run the neuron with the smallest final standard deviation, i.e. the most
saturated one; first seed); the y-space trajectory of the probe sample (first seed).
"""

from __future__ import annotations

import numpy as np

from higbench.claims.paper import TOY_OPTIMIZERS, TOY_TUNED_LRS
from higbench.display import COLORS, OPTIMIZER_NAMES
from higbench.figures.data import FigureData
from higbench.figures.plot import TIME, Curves, Custom, Series, legend
from higbench.figures.spec import Budget, Figure, PerPreset, Sweep

GAMMAS = (1.0, 0.01)
BUDGET = Budget(seconds={"paper": 120, "quick": 30, "standard": 60})
SEEDS = PerPreset([0, 1, 2], smoke=[0, 1])


def _neurons(d: FigureData, ax, gamma: float, tag: str) -> None:
    for opt in TOY_OPTIMIZERS:
        runs = d.runs("toy", problem__gamma=gamma, optimizer__name=opt)
        if runs and "neuron_mean" in runs[0].logs:
            first, logs = runs[0], runs[0].logs
            t = first.curves["wall_time"].to_numpy(dtype=float)
            mean, std = logs["neuron_mean"], logs["neuron_std"]
            n = min(len(t), len(mean))
            k = int(np.argmin(std[n - 1]))
            name, m, s = f"{OPTIMIZER_NAMES[opt]} neuron {k}", mean[:n, k], std[:n, k]
            ax.plot(t[:n], m, color=COLORS[opt], label=name)
            ax.fill_between(t[:n], m - s, m + s, color=COLORS[opt], alpha=0.2, lw=0)
            d.record(f"neuron mean {tag}", name, first, "wall_time", t[:n], "neuron_mean", m)
            d.record(f"neuron std {tag}", name, first, "wall_time", t[:n], "neuron_std", s)
    ax.set(xlabel=TIME, ylabel="neuron output: mean ± std over data")
    ax.set_title(f"{tag}: most saturated neuron (seed 0)", fontsize=9)
    legend(ax)


def _trajectories(d: FigureData, ax, gamma: float, tag: str) -> None:
    for opt in TOY_OPTIMIZERS:
        runs = d.runs("toy", problem__gamma=gamma, optimizer__name=opt)
        if runs and "probe_output" in runs[0].logs:
            y, name = runs[0].logs["probe_output"], OPTIMIZER_NAMES[opt]
            ax.plot(y[:, 0], y[:, 1], color=COLORS[opt], marker=".", ms=2, lw=1, label=name)
            d.record(f"trajectory {tag}", name, runs[0], "y1", y[:, 0], "y2", y[:, 1])
            if (target := runs[0].logs.get("probe_target")) is not None and opt == TOY_OPTIMIZERS[-1]:
                ax.plot(target[-1, 0], target[-1, 1], "k*", ms=10, label="target ŷ")
    ax.set(xlabel=r"$y_1$", ylabel=r"$y_2 = \gamma\, f_2$")  # subscripts: y¹, y² read as powers
    ax.set_title(f"{tag}: trajectory of x=probe in y-space", fontsize=9)
    legend(ax)


def _row(i: int, gamma: float) -> list:
    tag = f"γ={gamma:g}"
    loss = Curves(
        f"{'ab'[i]}) {tag}: loss", [Series("toy", "optimizer.name", {"problem.gamma": gamma}, "{short}")], f"loss {tag}"
    )
    return [loss, Custom(_neurons, {"gamma": gamma, "tag": tag}), Custom(_trajectories, {"gamma": gamma, "tag": tag})]


FIGURES = [
    Figure(
        "fig1",
        "Toy problem: loss, neuron saturation and y-space trajectory for gamma = 1 and 0.01; Adam, GN, HIG",
        [
            Sweep(
                "toy",
                {"problem": "toy"},
                BUDGET,
                grid={"problem.gamma": list(GAMMAS), "optimizer": list(TOY_OPTIMIZERS)},
                seeds=SEEDS,
            ),
            Sweep(
                "adam_tuned",
                {"problem": "toy", "optimizer": "adam", "problem.gamma": 0.01},
                BUDGET,
                grid={"optimizer.lr": PerPreset(TOY_TUNED_LRS, smoke=TOY_TUNED_LRS[:1])},
                seeds=SEEDS,
            ),
        ],
        panels=[*_row(0, GAMMAS[0]), *_row(1, GAMMAS[1])],
        size=(3, 4.3, 3.1),
    )
]
