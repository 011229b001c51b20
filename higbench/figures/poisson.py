"""Figures 3a-c and 7: the Poisson problem (paper 3.2, appendix B.3).

fig3c / fig7b chain runs through ``init_from``: Adam (eta=1e-4, the fig3b run) ->
Adam continued and HIG (eta=0.02) continued from its final weights -> Adam continued
from the HIG run (fig7b). A continued run's curve is drawn after its parent's.

Deviation (quick and smoke presets): HIG uses b=16 (quick) / 8 (smoke) instead of the
paper's 64: one HIG update at b=64 (4096 x 41408 Jacobian) takes about a minute on 2 CPU
cores, so a 60 s run would make one update.
"""

from __future__ import annotations

import numpy as np

from higbench.figures.claims import (
    PAPER,
    POISSON_HIG_HOUR,
    Cause,
    at_update,
    best,
    claim,
    end_time,
    final,
    loss_at,
    probe_values,
    require,
    sci,
    updates_of,
)
from higbench.figures.data import COLORS, FigureData
from higbench.figures.plot import Curves, Series, legend, new_figure
from higbench.figures.spec import Budget, Figure, PerPreset, Preset, Sweep

MAIN = Budget(seconds={"paper": 3600, "quick": 60, "standard": 60, "long": 3000})
ADAM_LRS, HIG_LRS, TUNED_CONT_LRS = [1e-4, 1e-3, 1e-2], [0.005, 0.02, 0.1], [3e-4, 1e-3]  # not given in the paper
ADAM_LR, HIG_LR = 1e-4, 0.02  # figure 3c
HIG_BATCH = PerPreset(64, 16, 8, long=64)
BLUES, GREENS = ("#9ecae1", "#4292c6", "#08306b"), ("#a1d99b", "#41ab5d", "#00441b")


def notes(p: Preset) -> list[str]:
    b = HIG_BATCH.for_preset(p)
    return (
        [] if b == 64 else [f"deviation: HIG batch size {b} instead of the paper's 64 (CPU cost of the b=64 Jacobian inversion)"]
    )


# Evaluated by updates, so that curves per update and per epoch start at the first updates
# (by time, Adam's first evaluation came ~30 epochs in and its log-axis curve looked flat).
EVALS = {"hig": {"eval_unit": "updates", "eval_every": 1}, "adam": {"eval_unit": "updates", "eval_every": 25}}


def poi(name: str, opt: str, init_from: str | None = None, grid=None, **fixed) -> Sweep:
    batch = {"batch_size": HIG_BATCH} if opt == "hig" else {}
    fixed = {"problem": "poisson", "optimizer": opt, **batch, **EVALS[opt], **fixed}
    return Sweep(name, fixed, MAIN, grid or {}, init_from=init_from)


FIG3B = [
    poi("adam", "adam", grid={"optimizer.lr": PerPreset(ADAM_LRS, smoke=ADAM_LRS[:2])}),
    poi("hig", "hig", grid={"optimizer.lr": PerPreset(HIG_LRS, smoke=[HIG_LR])}),
]
FIG3C = [
    poi("adam_pre", "adam", **{"optimizer.lr": ADAM_LR}),  # = fig3b's Adam eta=1e-4
    poi("adam_cont", "adam", "adam_pre", **{"optimizer.lr": ADAM_LR}),
    poi("hig_cont", "hig", "adam_pre", **{"optimizer.lr": HIG_LR}),
    # Fair baseline: the continued Adam with a re-tuned learning rate, same budget.
    poi("adam_cont_tuned", "adam", "adam_pre", grid={"optimizer.lr": PerPreset(TUNED_CONT_LRS, smoke=TUNED_CONT_LRS[:1])}),
]
CHAIN = [
    Series("adam_pre", name="Adam", color=COLORS["adam"]),
    Series("adam_cont", name="Adam, continued", color="#08306b"),
    Series("hig_cont", name="HIG pre-trained with Adam", color=COLORS["hig"]),
]
BY_LR = [Series("adam", "optimizer.lr", color=BLUES), Series("hig", "optimizer.lr", color=GREENS)]


def plot_fig3a(d: FigureData) -> None:
    import torch

    from higbench.physics.poisson import laplace, laplace_matrix

    fig, axes = new_figure(3, 1, width=3.4, height=3.2)
    if not (runs := d.runs("hig_cont")):
        legend(axes[0, 0])
    else:
        run = runs[0]
        problem, model = run.build_model()
        sample, n = problem.test_set()[:1], problem.n
        with torch.no_grad():
            phi = model(sample.net_inputs).double().reshape(n, n)
        rho = sample.net_inputs.double().reshape(n, n)
        exact = torch.linalg.solve(laplace_matrix(n, n), rho.reshape(-1)).reshape(n, n)
        residual = float(0.5 * ((laplace(phi) - rho) ** 2).sum())
        lim = float(max(phi.abs().max(), exact.abs().max()))
        panels = [("source ρ", rho), (f"inferred potential φ ({run.label()})", phi), ("exact potential L⁻¹ρ", exact)]
        for ax, (title, field) in zip(axes[0], panels):
            im = ax.imshow(
                field.numpy(), cmap="RdBu_r", origin="lower", **({"vmin": -lim, "vmax": lim} if "potential" in title else {})
            )
            fig.colorbar(im, ax=ax, fraction=0.046)
            ax.set(title=title, xticks=[], yticks=[])
            ax.title.set_fontsize(8)
            d.record(title.split(" (")[0], "grid", run, "cell", np.arange(n * n), "value", field.numpy().ravel())
        axes[0, 1].set_xlabel(f"loss ½‖Δφ−ρ‖² = {sci(residual)}", fontsize=8)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    d.save(fig)


FIGURES = [
    Figure(
        "fig3a",
        "Poisson: example source and inferred potential (HIG after Adam pre-training)",
        FIG3C[0:3:2],
        plot=plot_fig3a,
    ),
    Figure(
        "fig3b",
        "Poisson: Adam and HIG for several learning rates",
        FIG3B,
        size=(2, 1, 4.6, 3.6),
        panels=[
            Curves(f"b) Poisson: Adam and HIG ({x} time axis)", BY_LR, f"loss ({x} time)", xscale=x) for x in ("linear", "log")
        ],
    ),
    Figure(
        "fig3c",
        "Poisson: Adam vs HIG pre-trained with Adam",
        FIG3C,
        size=(1, 1, 6.2, 4.0),
        panels=[Curves("c) Poisson: Adam vs HIG pre-trained with Adam", CHAIN)],
    ),
    Figure(
        "fig7",
        "Poisson: a) loss per epoch, b) pre-training in both directions",
        [*FIG3B, *FIG3C, poi("adam_after_hig", "adam", "hig_cont", **{"optimizer.lr": ADAM_LR})],
        size=(2, 1, 4.8, 3.8),
        panels=[
            Curves("a) Poisson: loss per epoch", BY_LR, "a) loss per epoch", "epoch", "log", "epochs (samples seen / 1024)"),
            Curves(
                "b) Poisson: pre-training in both directions",
                [*CHAIN, Series("adam_after_hig", name="Adam pre-trained with HIG", color="tab:purple")],
                "b) pre-training both ways",
            ),
        ],
    ),
]
for _f in FIGURES:
    _f.notes = notes  # every figure of the family states the preset's deviations


# -- claims ---------------------------------------------------------------------------------


@claim(
    "poi-1",
    "fig3b",
    "~3 decades",
    min_seconds=POISSON_HIG_HOUR,  # or the paper's hour of updates (decisive)
    cause=Cause(
        "deviation",
        "HIG ran at b={hig_b} (the paper: {paper_poisson_b}) and made {hig_updates} updates, no fewer than the paper's hour "
        "({poisson_hour_updates}), to {hig_decades:.1f} decades: the batch size, not the budget",
        {
            "a smaller batch than the paper's": lambda v: v["hig_b"] < v["paper_poisson_b"],
            "the paper's hour of updates made": lambda v: v["hig_updates"] >= v["poisson_hour_updates"],
        },
    ),
)
def both_decrease(datas):
    """Poisson: Adam and HIG both decrease the loss by up to three orders of magnitude. Rule: both optimizers' best runs
    >= 2.5 decades below the initial loss (partly: >= 1)"""
    adam, hig = datas["fig3b"].runs("adam"), datas["fig3b"].runs("hig")
    require(adam, hig, what="fig3b")
    dec = {name: max(np.log10(r.initial_loss / best([r])) for r in runs) for name, runs in (("Adam", adam), ("HIG", hig))}
    measured = ", ".join(f"{k} {v:.1f} decades (best run)" for k, v in dec.items())
    n = max(map(updates_of, hig))
    values = {"hig_decades": dec["HIG"], "adam_decades": dec["Adam"], "hig_updates": n, "hig_b": hig[0].cfg("batch_size")}
    values["decisive"] = n >= PAPER["poisson_hour_updates"]  # the paper's hour of HIG updates made
    return measured, all(v >= 2.5 for v in dec.values()), all(v >= 1.0 for v in dec.values()), values


def continued_from_adam(table, lr: float = 0.01) -> dict:
    """The data probe's Adam-pretrained rows (scripts/probe_poisson_data.py): start, HIG at ``lr`` and Adam, per data."""
    rows = table[table["from"] == "Adam-pretrained"]
    out = {"lr": lr}
    for data, name in (("phiflow_noise", "phiflow"), ("fourier", "fourier")):
        mine = rows[rows["data"] == data]
        hig = mine[(mine["optimizer"] == "hig") & np.isclose(mine["lr"], lr)]
        adam = mine[mine["optimizer"] == "adam"]
        out |= {f"{name}_start": float(hig["test_start"].iloc[0]), f"{name}_hig": float(hig["test_end"].iloc[0])}
        out[f"{name}_adam"] = float(adam["test_end"].iloc[0])
    return out


@claim(
    "poi-2",
    "fig3c",
    "quick drop, HIG below Adam",
    min_seconds=600,
    min_seeds=3,
    cause=Cause(
        "disagreement",
        "not the data distribution: in the data probe (the authors' network and batch size, one seed) HIG "
        "η={probe_lr:g} continued from Adam's weights ends at {probe_phiflow_hig:e} from {probe_phiflow_start:e} "
        "on the authors' PhiFlow noise and at {probe_fourier_hig:e} from {probe_fourier_start:e} on ours, while Adam "
        "continued for the same time ends at {probe_phiflow_adam:e} and {probe_fourier_adam:e}; here (b={hig_b}, "
        "data {data}) HIG {start:e} -> "
        "{hig_final:e}, Adam {adam_final:e}",
        {
            "Adam below HIG here": lambda v: v["adam_final"] < v["hig_final"],
            "Adam below HIG on the authors' data": lambda v: v["probe_phiflow_adam"] < v["probe_phiflow_hig"],
            "Adam below HIG on ours": lambda v: v["probe_fourier_adam"] < v["probe_fourier_hig"],
        },
        probe=probe_values("poisson_data.csv", continued_from_adam),
    ),
)
def pretrained(datas):
    """Poisson: HIG after Adam pre-training drops the loss quickly and ends below Adam. Rule: HIG's final loss <= half of
    the best Adam continued from the same weights, paper η or re-tuned (partly: below it)"""
    d = datas["fig3c"]
    hig, adam = d.runs("hig_cont"), d.runs("adam_cont")
    require(hig, adam, what="fig3c continuations")
    h = hig[0]
    drop = h.initial_loss / loss_at(h, 0.25 * end_time(h))
    fh, fa = final(hig), final(adam)
    tuned = {r.cfg("optimizer.lr"): final([r]) for r in d.runs("adam_cont_tuned")}
    fa_best = min([fa, *tuned.values()])
    measured = (
        f"start {sci(h.initial_loss)}; HIG after 1/4 of its budget {drop:.1f}x lower, final {sci(fh)} vs Adam continued "
        f"{sci(fa)} (η=1e-4, paper)"
        + "".join(f", η={lr:g} {sci(v)}" for lr, v in sorted(tuned.items()))
        + f"; HIG's advantage {fa / fh:.2g}x (paper η), {fa_best / fh:.2g}x (best Adam)"
    )
    values = {"start": h.initial_loss, "hig_final": fh, "adam_final": fa_best, "hig_b": h.cfg("batch_size")}
    values |= {"data": h.cfg("problem.data", "fourier"), "decisive": fh > h.initial_loss > fa_best}  # rising vs falling
    return measured, fh <= 0.5 * fa_best, fh < fa_best, values


@claim(
    "poi-3",
    "fig7",
    "loss goes back up",
    min_seconds=300,
    cause=Cause(
        "unspecified",
        "follows from poi-2: HIG ends at {hig_final:e}, above its start {start:e}, so there is no HIG progress for Adam to "
        "lose (Adam from it ends at {adam_after:e})",
        {"HIG above its start": lambda v: v["hig_final"] > v["start"]},
    ),
)
def adam_after_hig(datas):
    """Poisson: Adam started from the HIG run loses HIG's progress. Rule: Adam after HIG ends >= 2x above the HIG run's
    final loss (partly: above it)"""
    hig, after = datas["fig7"].runs("hig_cont"), datas["fig7"].runs("adam_after_hig")
    require(hig, after, what="fig7b")
    fh, fa, start = final(hig), final(after), hig[0].initial_loss
    values = {"hig_final": fh, "adam_after": fa, "start": start, "decisive": fh > start}  # no progress to lose
    return f"HIG ended at {sci(fh)}; Adam continued from it ends at {sci(fa)}", fa >= 2 * fh, fa > fh, values


@claim("poi-4", "fig7", "HIG faster per iteration", min_seconds=60, min_seeds=3)
def per_update(datas):
    """Poisson: per iteration, HIG converges faster than Adam. Rule: at HIG's last update count HIG's loss <= half of
    Adam's after as many updates (best runs; partly: below it)"""
    adam, hig = datas["fig7"].runs("adam"), datas["fig7"].runs("hig")
    require(adam, hig, what="fig7a")
    a, h = min(adam, key=lambda r: r.final_loss), min(hig, key=lambda r: r.final_loss)
    n = min(updates_of(h), updates_of(a))
    first = int(a.curves["step"].iloc[1]) if len(a.curves) > 1 else n + 1
    if first > n:  # Adam's curve says nothing about its first n updates (evaluated by time)
        return f"Adam's first evaluation after {first} updates, HIG's run {n}", None, "needs Adam evaluated by updates"
    la, lh = at_update(a, n), at_update(h, n)
    values = {"n": n, "hig": lh, "adam": la}
    return f"after {n} updates: HIG {sci(lh)} vs Adam {sci(la)} (best runs)", lh <= 0.5 * la, lh < la, values


def log_time_slope(run, start: float = 0.5) -> float:
    """d log10(loss) / d log10(t) over the run's last half (least squares on its evaluations)."""
    c = run.curves[(run.curves["wall_time"] >= start * end_time(run)) & (run.curves["wall_time"] > 0)]
    if len(c) < 2:
        return float("nan")
    return float(np.polyfit(np.log10(c["wall_time"]), np.log10(c["test_loss"]), 1)[0])


# Slopes on a log-time axis need the paper's hour of updates.
@claim("poi-5", "fig3b", "smallest-η Adam best; HIG steeper on log time", min_seconds=POISSON_HIG_HOUR)
def adam_lr_and_slope(datas):
    """Poisson (fig. 3b): the smallest-η Adam run is the best Adam per unit time, and on a log-time axis HIG's slope
    stays steeper. Rule: the smallest-η Adam run ends lowest of the Adam grid, and the best HIG run's log-log slope
    over the last half is steeper than the best Adam run's (partly: one of the two)"""
    adam, hig = datas["fig3b"].runs("adam"), datas["fig3b"].runs("hig")
    require(adam, hig, what="fig3b")
    small = min(adam, key=lambda r: r.cfg("optimizer.lr"))
    best_adam, best_hig = min(adam, key=lambda r: final([r])), min(hig, key=lambda r: final([r]))
    sa, sh = log_time_slope(best_adam), log_time_slope(best_hig)
    measured = f"best Adam: {best_adam.label()}; log-time slope over the last half: HIG {sh:.2f}, Adam {sa:.2f}"
    values = {"adam_slope": sa, "hig_slope": sh}
    return measured, small is best_adam and sh < sa, small is best_adam or sh < sa, values
