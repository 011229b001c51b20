"""Figure 1: the toy example (paper 2.1, appendix B.1), gamma = 1 and gamma = 0.01.

Columns: test loss over wall-clock time (median and min-max band over seeds); the
data-set mean (line) and standard deviation (band) of one hidden neuron's output over
time (for each run the neuron with the smallest final standard deviation, i.e. the most
saturated one; first seed); the y-space trajectory of the probe sample (first seed).
"""

from __future__ import annotations

import numpy as np

from higbench.figures import checks
from higbench.figures.checks import e, final, verdict
from higbench.figures.data import COLORS, OPTIMIZER_NAMES, FigureData, RunData, legend, new_figure, semilogy_axes
from higbench.figures.registry import Claim, claim, register
from higbench.figures.spec import Budget, Figure, Preset, Sweep

GAMMAS = (1.0, 0.01)
OPTIMIZERS = ("adam", "gn", "hig")
BUDGET = Budget(seconds={"paper": 120, "quick": 30, "standard": 60})
# A tanh neuron whose output hardly varies over the data set and sits near +-1.
SATURATED_STD, SATURATED_MEAN = 0.1, 0.9


def fig1_runs(p: Preset) -> list[Sweep]:
    return [
        Sweep(
            "toy",
            {"problem": "toy"},
            BUDGET,
            grid={"problem.gamma": list(GAMMAS), "optimizer": list(OPTIMIZERS)},
            seeds=SEEDS(p),
        ),
        # Fair baseline: Adam's learning rate re-tuned at the same budget (the paper's is 0.3).
        Sweep(
            "adam_tuned",
            {"problem": "toy", "optimizer": "adam", "problem.gamma": 0.01},
            BUDGET,
            grid={"optimizer.lr": p.pick(paper=TUNED_LRS, smoke=TUNED_LRS[:1])},
            seeds=SEEDS(p),
        ),
    ]


TUNED_LRS = [0.003, 0.03]


def SEEDS(p: Preset) -> list[int]:  # noqa: N802
    return p.pick(paper=[0, 1, 2], smoke=[0, 1])


def saturated(run: RunData) -> int:
    """Hidden neurons saturated at the last evaluation (|mean| > 0.9 and std < 0.1)."""
    logs = run.logs
    if "neuron_mean" not in logs:
        return 0
    mean, std = logs["neuron_mean"][-1], logs["neuron_std"][-1]
    return int(np.sum((np.abs(mean) > SATURATED_MEAN) & (std < SATURATED_STD)))


def plot_fig1(d: FigureData) -> None:
    fig, axes = new_figure(3, 2, width=4.3, height=3.1)
    for row, gamma in enumerate(GAMMAS):
        ax_loss, ax_neuron, ax_traj = axes[row]
        tag = f"γ={gamma:g}"
        for opt in OPTIMIZERS:
            runs = d.runs("toy", problem__gamma=gamma, optimizer__name=opt)
            if not runs:
                continue
            color = COLORS[opt]
            d.curve(ax_loss, runs, runs[0].label(("optimizer.lr", "optimizer.tau")), panel=f"loss {tag}", color=color)
            first = runs[0]
            logs = first.logs
            t = first.curves["wall_time"].to_numpy(dtype=float)
            if "neuron_mean" in logs:
                mean, std = logs["neuron_mean"], logs["neuron_std"]
                n = min(len(t), len(mean))
                k = int(np.argmin(std[n - 1]))
                name = f"{OPTIMIZERS_NAME(opt)} neuron {k}"
                ax_neuron.plot(t[:n], mean[:n, k], color=color, label=name)
                ax_neuron.fill_between(t[:n], mean[:n, k] - std[:n, k], mean[:n, k] + std[:n, k], color=color, alpha=0.2, lw=0)
                d.record(f"neuron mean {tag}", name, first, "wall_time", t[:n], "neuron_mean", mean[:n, k])
                d.record(f"neuron std {tag}", name, first, "wall_time", t[:n], "neuron_std", std[:n, k])
            if "probe_output" in logs:
                y = logs["probe_output"]
                ax_traj.plot(y[:, 0], y[:, 1], color=color, marker=".", ms=2, lw=1, label=OPTIMIZERS_NAME(opt))
                d.record(f"trajectory {tag}", OPTIMIZERS_NAME(opt), first, "y1", y[:, 0], "y2", y[:, 1])
                target = logs.get("probe_target")
                if target is not None and opt == OPTIMIZERS[-1]:
                    ax_traj.plot(target[-1, 0], target[-1, 1], "k*", ms=10, label="target ŷ")
        semilogy_axes(ax_loss)
        ax_loss.set_title(f"{'ab'[row]}) {tag}: loss", fontsize=9)
        legend(ax_loss)
        ax_neuron.set_xlabel("wall-clock time [s]")
        ax_neuron.set_ylabel("neuron output: mean ± std over data")
        ax_neuron.set_title(f"{tag}: most saturated neuron (seed 0)", fontsize=9)
        legend(ax_neuron)
        ax_traj.set_xlabel("y¹")
        ax_traj.set_ylabel("y² (= γ·f²)")
        ax_traj.set_title(f"{tag}: trajectory of x=probe in y-space", fontsize=9)
        legend(ax_traj)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    d.save(fig)


def OPTIMIZERS_NAME(opt: str) -> str:  # noqa: N802
    return OPTIMIZER_NAMES.get(opt, opt)


register(
    Figure(
        "fig1",
        "Toy problem: loss, neuron saturation and y-space trajectory for gamma = 1 and 0.01; Adam, GN, HIG",
        fig1_runs,
        plot_fig1,
        family="toy",
    )
)


# -- claims ---------------------------------------------------------------------------------


def _by_opt(d: FigureData, gamma: float) -> dict[str, list[RunData]]:
    return {o: d.runs("toy", problem__gamma=gamma, optimizer__name=o) for o in OPTIMIZERS}


def check_well_conditioned(datas):
    runs = _by_opt(datas["fig1"], 1.0)
    if checks.missing_runs(*runs.values()):
        return checks.na("fig1 gamma=1")
    orders = {o: checks.median([np.log10(r.initial_loss / r.final_loss) for r in rs]) for o, rs in runs.items()}
    measured = ", ".join(f"{OPTIMIZERS_NAME(o)} {v:.1f}" for o, v in orders.items()) + " decades"
    v = verdict(all(x >= 2.5 for x in orders.values()), all(x >= 1.5 for x in orders.values()))
    return measured, v, "rule: every optimizer >= 2.5 decades below its initial loss (partly: >= 1.5)"


def check_stall(datas):
    runs = _by_opt(datas["fig1"], 0.01)
    if checks.missing_runs(runs["adam"], runs["gn"]):
        return checks.na("fig1 gamma=0.01")
    fa, fg = final(runs["adam"]), final(runs["gn"])
    # A stall is a plateau: the loss at the end no lower than 1/1.5 of the loss at half the run
    # (a run cut off while still falling does not count).
    half = {o: checks.median([checks.loss_at(r, 0.5 * float(r.curves["wall_time"].iloc[-1])) for r in runs[o]]) for o in runs}
    flat = {o: final(runs[o]) >= half[o] / 1.5 for o in ("adam", "gn")}
    level = all(0.1 <= x <= 0.4 for x in (fa, fg))
    full = level and all(flat.values())
    part = all(flat.values()) and all(x >= 0.05 for x in (fa, fg))
    return (
        f"final loss Adam {e(fa)} (half-way {e(half['adam'])}), GN {e(fg)} (half-way {e(half['gn'])}) (medians)",
        verdict(full, part or level),
        "rule: both final losses in [0.1, 0.4] and flat over the second half of the run (partly: both flat above 0.05, "
        "or both in [0.1, 0.4])",
    )


def check_hig_best(datas):
    d = datas["fig1"]
    runs = _by_opt(d, 0.01)
    if checks.missing_runs(*runs.values()):
        return checks.na("fig1 gamma=0.01")
    fh, fa, fg = final(runs["hig"]), final(runs["adam"]), final(runs["gn"])
    tuned = {lr: final(d.runs("adam_tuned", optimizer__lr=lr)) for lr in TUNED_LRS if d.runs("adam_tuned", optimizer__lr=lr)}
    fa_best = min([fa, *tuned.values()])
    other = min(fa_best, fg)
    tuned_text = ", ".join(f"η={lr:g} {e(v)}" for lr, v in tuned.items())
    return (
        f"final loss (median of seeds) HIG {e(fh)} vs Adam η=0.3 (paper) {e(fa)} ({fa / fh:.1f}x), GN {e(fg)}; "
        f"re-tuned Adam: {tuned_text or 'not run'} (HIG's advantage against the best: {fa_best / fh:.1f}x)",
        verdict(fh < 0.5 * other, fh < other),
        "rule: HIG below half of the better of GN and the best Adam (paper η or re-tuned) (partly: below it)",
    )


def check_saturation(datas):
    runs = _by_opt(datas["fig1"], 0.01)
    if checks.missing_runs(runs["gn"], runs["hig"]):
        return checks.na("fig1 gamma=0.01")
    sg = checks.median([saturated(r) for r in runs["gn"]])
    sh = checks.median([saturated(r) for r in runs["hig"]])
    sa = checks.median([saturated(r) for r in runs["adam"]]) if runs["adam"] else float("nan")
    return (
        f"saturated neurons (of 7, median over seeds): GN {sg:g}, HIG {sh:g}, Adam {sa:g}",
        verdict(sg >= 1 and sh == 0, sg > sh),
        (
            f"saturated: |mean| > {SATURATED_MEAN} and std < {SATURATED_STD} over the data at the end; rule: GN >= 1 and "
            "HIG 0 (partly: GN > HIG)"
        ),
    )


claim(
    Claim(
        "toy-1",
        ("fig1",),
        "Toy, gamma=1: Adam, GN and HIG all decrease the loss by about three orders of magnitude",
        "~3 decades",
        check_well_conditioned,
    )
)
claim(
    Claim(
        "toy-2", ("fig1",), "Toy, gamma=0.01: Adam and GN stall (loss plateau near 0.2)", "plateau ~0.2 (figure 1b)", check_stall
    )
)
claim(Claim("toy-3", ("fig1",), "Toy, gamma=0.01: HIG reaches a better loss than Adam and GN", "HIG lowest", check_hig_best))
claim(
    Claim(
        "toy-4", ("fig1",), "Toy, gamma=0.01: GN oversaturates neurons, HIG does not", "GN saturates, HIG not", check_saturation
    )
)
