"""Figures 3a-c and 7: the Poisson problem (paper 3.2, appendix B.3).

fig3c / fig7b chain runs through ``init_from``: Adam (eta=1e-4, the fig3b run) ->
Adam continued and HIG (eta=0.02) continued from its final weights -> Adam continued
from the HIG run (fig7b). A continued run's curve is drawn after its parent's, shifted
by the parent's final training time.

Deviation (quick and smoke presets): HIG uses b=16 (quick) / 8 (smoke) instead of the
paper's 64: one HIG update at b=64 (4096 x 41408 Jacobian) takes about a minute on 2 CPU
cores, so a 60 s run would make one update.
"""

from __future__ import annotations

import numpy as np

from higbench.figures import checks
from higbench.figures.checks import best, e, final, loss_at, verdict
from higbench.figures.data import COLORS, FigureData, RunData, join_label, legend, new_figure, semilogy_axes
from higbench.figures.registry import Claim, claim, register
from higbench.figures.spec import Budget, Figure, Preset, Sweep

MAIN = Budget(seconds={"paper": 3600, "quick": 60, "standard": 60})
ADAM_LRS = [1e-4, 1e-3, 1e-2]
HIG_LRS = [0.005, 0.02, 0.1]
ADAM_LR, HIG_LR = 1e-4, 0.02  # figure 3c


def hig_batch(p: Preset) -> int:
    return p.pick(paper=64, quick=16, smoke=8)


def notes(p: Preset) -> list[str]:
    if p.name == "paper":
        return []
    return [f"deviation: HIG batch size {hig_batch(p)} instead of the paper's 64 (CPU cost of the b=64 Jacobian inversion)"]


def fig3b_runs(p: Preset) -> list[Sweep]:
    return [
        Sweep(
            "adam",
            {"problem": "poisson", "optimizer": "adam"},
            MAIN,
            grid={"optimizer.lr": p.pick(paper=ADAM_LRS, smoke=ADAM_LRS[:2])},
        ),
        Sweep(
            "hig",
            {"problem": "poisson", "optimizer": "hig", "batch_size": hig_batch(p)},
            MAIN,
            grid={"optimizer.lr": p.pick(paper=HIG_LRS, smoke=[HIG_LR])},
        ),
    ]


def fig3c_runs(p: Preset) -> list[Sweep]:
    return [
        Sweep("adam_pre", {"problem": "poisson", "optimizer": "adam", "optimizer.lr": ADAM_LR}, MAIN),  # = fig3b's Adam eta=1e-4
        Sweep("adam_cont", {"problem": "poisson", "optimizer": "adam", "optimizer.lr": ADAM_LR}, MAIN, init_from="adam_pre"),
        Sweep(
            "hig_cont",
            {"problem": "poisson", "optimizer": "hig", "batch_size": hig_batch(p), "optimizer.lr": HIG_LR},
            MAIN,
            init_from="adam_pre",
        ),
        # Fair baseline: the continued Adam with a re-tuned learning rate, same budget.
        Sweep(
            "adam_cont_tuned",
            {"problem": "poisson", "optimizer": "adam"},
            MAIN,
            grid={"optimizer.lr": p.pick(paper=TUNED_CONT_LRS, smoke=TUNED_CONT_LRS[:1])},
            init_from="adam_pre",
        ),
    ]


TUNED_CONT_LRS = [3e-4, 1e-3]


def fig7_runs(p: Preset) -> list[Sweep]:
    return [
        *fig3b_runs(p),
        *fig3c_runs(p),
        Sweep("adam_after_hig", {"problem": "poisson", "optimizer": "adam", "optimizer.lr": ADAM_LR}, MAIN, init_from="hig_cont"),
    ]


def fig3a_runs(p: Preset) -> list[Sweep]:
    return fig3c_runs(p)[0:3:2]  # adam_pre, hig_cont: the HIG network after Adam pre-training


# -- plots ----------------------------------------------------------------------------------


def plot_fig3a(d: FigureData) -> None:
    import torch

    from higbench.physics.poisson import laplace, laplace_matrix

    fig, axes = new_figure(3, 1, width=3.4, height=3.2)
    runs = d.runs("hig_cont")
    if not runs:
        legend(axes[0, 0])
    else:
        run = runs[0]
        problem, model = run.build_model()
        sample = problem.test_set()[:1]
        n = problem.n
        with torch.no_grad():
            phi = model(sample.net_inputs).double().reshape(n, n)
        rho = sample.net_inputs.double().reshape(n, n)
        exact = torch.linalg.solve(laplace_matrix(n, n), rho.reshape(-1)).reshape(n, n)
        residual = float(0.5 * ((laplace(phi) - rho) ** 2).sum())
        panels = [("source ρ", rho), (f"inferred potential φ ({run.label()})", phi), ("exact potential L⁻¹ρ", exact)]
        lim = float(max(phi.abs().max(), exact.abs().max()))
        for ax, (title, field) in zip(axes[0], panels):
            kw = {"vmin": -lim, "vmax": lim} if "potential" in title else {}
            im = ax.imshow(field.numpy(), cmap="RdBu_r", origin="lower", **kw)
            fig.colorbar(im, ax=ax, fraction=0.046)
            ax.set_title(title, fontsize=8)
            ax.set_xticks([])
            ax.set_yticks([])
            d.record(title.split(" (")[0], "grid", run, "cell", np.arange(n * n), "value", field.numpy().ravel())
        axes[0, 1].set_xlabel(f"loss ½‖Δφ−ρ‖² = {e(residual)}", fontsize=8)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    d.save(fig)


def plot_fig3b(d: FigureData) -> None:
    fig, axes = new_figure(2, 1, width=4.6, height=3.6)
    for ax, xscale in zip(axes[0], ("linear", "log")):
        for name, shades in (("adam", ("#9ecae1", "#4292c6", "#08306b")), ("hig", ("#a1d99b", "#41ab5d", "#00441b"))):
            lrs = sorted({j.overrides["optimizer.lr"] for j in d.jobs if j.sweep == name})
            for lr, color in zip(lrs, shades[-len(lrs) :] if len(lrs) < 3 else shades):
                runs = d.runs(name, optimizer__lr=lr)
                if runs:
                    d.curve(ax, runs, runs[0].label(), panel=f"loss ({xscale} time)", color=color)
        semilogy_axes(ax)
        ax.set_xscale(xscale)
        ax.set_title(f"b) Poisson: Adam and HIG ({xscale} time axis)", fontsize=9)
        legend(ax)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    d.save(fig)


def _chain(d: FigureData, ax, names: list[tuple[str, str, str]], panel: str) -> None:
    """Curves of a chain of continued runs, each shifted by its parent's final time."""
    ends: dict[str, float] = {}
    for sweep, label, color in names:
        runs = d.runs(sweep)
        if not runs:
            continue
        run = runs[0]
        parent = run.job.parent
        offset = 0.0
        if parent is not None:
            parent_sweep = parent.sweep
            offset = ends.get(parent_sweep, 0.0)
        d.curve(ax, runs, join_label(label, run.label()), panel=panel, color=color, x_offset=offset)
        ends[sweep] = offset + float(run.curves["wall_time"].iloc[-1])
    semilogy_axes(ax)
    legend(ax)


def plot_fig3c(d: FigureData) -> None:
    fig, axes = new_figure(1, 1, width=6.2, height=4.0)
    _chain(
        d,
        axes[0, 0],
        [
            ("adam_pre", "Adam", COLORS["adam"]),
            ("adam_cont", "Adam, continued", "#08306b"),
            ("hig_cont", "HIG pre-trained with Adam", COLORS["hig"]),
        ],
        "loss",
    )
    axes[0, 0].set_title("c) Poisson: Adam vs HIG pre-trained with Adam", fontsize=9)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    d.save(fig)


def _epochs(run: RunData, curves) -> np.ndarray:
    """Epochs as samples seen / epoch size (an epoch is a bookkeeping unit on infinite data)."""
    return curves["step"].to_numpy(dtype=float) * float(run.cfg("batch_size")) / float(run.cfg("problem.epoch_size"))


def plot_fig7(d: FigureData) -> None:
    fig, axes = new_figure(2, 1, width=4.8, height=3.8)
    ax = axes[0, 0]
    for name, shades in (("adam", ("#9ecae1", "#4292c6", "#08306b")), ("hig", ("#a1d99b", "#41ab5d", "#00441b"))):
        lrs = sorted({j.overrides["optimizer.lr"] for j in d.jobs if j.sweep == name})
        for lr, color in zip(lrs, shades):
            runs = d.runs(name, optimizer__lr=lr)
            if runs:
                d.curve(ax, runs, runs[0].label(), panel="a) loss per epoch", x="epoch", transform=_epochs, color=color)
    semilogy_axes(ax, xlabel="epochs (samples seen / 1024)")
    ax.set_xscale("log")
    ax.set_title("a) Poisson: loss per epoch", fontsize=9)
    legend(ax)
    _chain(
        d,
        axes[0, 1],
        [
            ("adam_pre", "Adam", COLORS["adam"]),
            ("adam_cont", "Adam, continued", "#08306b"),
            ("hig_cont", "HIG pre-trained with Adam", COLORS["hig"]),
            ("adam_after_hig", "Adam pre-trained with HIG", "tab:purple"),
        ],
        "b) pre-training both ways",
    )
    axes[0, 1].set_title("b) Poisson: pre-training in both directions", fontsize=9)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    d.save(fig)


register(
    Figure(
        "fig3a",
        "Poisson: example source and inferred potential (HIG after Adam pre-training)",
        fig3a_runs,
        plot_fig3a,
        family="poisson",
        notes=notes,
    )
)
register(
    Figure("fig3b", "Poisson: Adam and HIG for several learning rates", fig3b_runs, plot_fig3b, family="poisson", notes=notes)
)
register(Figure("fig3c", "Poisson: Adam vs HIG pre-trained with Adam", fig3c_runs, plot_fig3c, family="poisson", notes=notes))
register(
    Figure(
        "fig7",
        "Poisson: a) loss per epoch, b) pre-training in both directions",
        fig7_runs,
        plot_fig7,
        family="poisson",
        notes=notes,
    )
)


# -- claims ---------------------------------------------------------------------------------


def check_both_decrease(datas):
    d = datas["fig3b"]
    adam, hig = d.runs("adam"), d.runs("hig")
    if not adam or not hig:
        return checks.na("fig3b")
    dec = {name: max(np.log10(r.initial_loss / best([r])) for r in runs) for name, runs in (("Adam", adam), ("HIG", hig))}
    measured = ", ".join(f"{k} {v:.1f} decades (best run)" for k, v in dec.items())
    return (
        measured,
        verdict(all(v >= 2.5 for v in dec.values()), all(v >= 1.0 for v in dec.values())),
        "rule: both optimizers' best runs >= 2.5 decades below the initial loss (partly: >= 1)",
    )


def check_pretrained(datas):
    d = datas["fig3c"]
    hig, adam = d.runs("hig_cont"), d.runs("adam_cont")
    if not hig or not adam:
        return checks.na("fig3c continuations")
    h = hig[0]
    quarter = 0.25 * float(h.curves["wall_time"].iloc[-1])
    drop = h.initial_loss / loss_at(h, quarter)
    fh, fa = final(hig), final(adam)
    tuned = {r.cfg("optimizer.lr"): final([r]) for r in d.runs("adam_cont_tuned")}
    fa_best = min([fa, *tuned.values()])
    measured = (
        f"start {e(h.initial_loss)}; HIG after 1/4 of its budget {drop:.1f}x lower, final {e(fh)} vs Adam continued "
        f"{e(fa)} (η=1e-4, paper)"
        + "".join(f", η={lr:g} {e(v)}" for lr, v in sorted(tuned.items()))
        + f"; HIG's advantage {fa / fh:.2g}x (paper η), {fa_best / fh:.2g}x (best Adam)"
    )
    return (
        measured,
        verdict(fh <= 0.5 * fa_best, fh < fa_best),
        "rule: HIG's final loss <= half of the best Adam continued from the same weights, paper η or re-tuned (partly: below it)",
    )


def check_adam_after_hig(datas):
    d = datas["fig7"]
    hig, after = d.runs("hig_cont"), d.runs("adam_after_hig")
    if not hig or not after:
        return checks.na("fig7b")
    fh, fa = final(hig), final(after)
    return (
        f"HIG ended at {e(fh)}; Adam continued from it ends at {e(fa)}",
        verdict(fa >= 2 * fh, fa > fh),
        "rule: Adam after HIG ends >= 2x above the HIG run's final loss (partly: above it)",
    )


def check_per_epoch(datas):
    d = datas["fig7"]
    adam, hig = d.runs("adam"), d.runs("hig")
    if not adam or not hig:
        return checks.na("fig7a")
    # Best run of each (lowest final loss), compared at the same number of samples seen.
    a = min(adam, key=lambda r: r.final_loss)
    h = min(hig, key=lambda r: r.final_loss)
    xh = _epochs(h, h.curves)
    xa = _epochs(a, a.curves)
    x = min(xh[-1], xa[-1])
    la = float(10 ** np.interp(x, xa, np.log10(a.curves["test_loss"].to_numpy(dtype=float))))
    lh = float(10 ** np.interp(x, xh, np.log10(h.curves["test_loss"].to_numpy(dtype=float))))
    return (
        f"at {x:.2f} epochs: HIG {e(lh)} vs Adam {e(la)} (best runs)",
        verdict(lh <= 0.5 * la, lh < la),
        "rule: at equal samples seen HIG <= half of Adam's loss (partly: below it)",
    )


claim(
    Claim(
        "poi-1",
        ("fig3b",),
        "Poisson: Adam and HIG both decrease the loss by up to three orders of magnitude",
        "~3 decades",
        check_both_decrease,
    )
)
claim(
    Claim(
        "poi-2",
        ("fig3c",),
        "Poisson: HIG after Adam pre-training drops the loss quickly and ends below Adam",
        "quick drop, HIG below Adam",
        check_pretrained,
    )
)
claim(
    Claim(
        "poi-3",
        ("fig7",),
        "Poisson: Adam started from the HIG run loses HIG's progress",
        "loss goes back up",
        check_adam_after_hig,
    )
)
claim(Claim("poi-4", ("fig7",), "Poisson: per epoch, HIG converges faster than Adam", "HIG faster per epoch", check_per_epoch))
