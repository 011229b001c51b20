"""Figures 12-13: ablations of beta, kappa and tau on the oscillators (paper appendix C).

HIG's table-2 settings otherwise (eta=1, b=128, tau=1e-6, beta=0, kappa=-1/2); beta=0 of
fig12a and kappa=-1/2 of fig12b are the same run.
"""

from __future__ import annotations

import math

from higbench.figures import checks
from higbench.figures.checks import e, final, verdict
from higbench.figures.data import FigureData, legend, new_figure, num, semilogy_axes
from higbench.figures.registry import Claim, claim, register
from higbench.figures.spec import Budget, Figure, Preset, Sweep

BUDGET = Budget(seconds={"paper": 3600, "quick": 30, "standard": 120})
BETAS = [0.0, -0.1, -0.2, -0.3, -0.4, -0.5]
KAPPAS = [1.0, 0.5, 0.0, -0.25, -0.5, -0.75, -1.0]
TAUS = [1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10]


def fig12_runs(p: Preset) -> list[Sweep]:
    return [
        Sweep(
            "beta",
            {"problem": "oscillator", "optimizer": "hig"},
            BUDGET,
            grid={"optimizer.beta": p.pick(paper=BETAS, quick=[0.0, -0.25, -0.5], smoke=[0.0, -0.5])},
        ),
        Sweep(
            "kappa",
            {"problem": "oscillator", "optimizer": "hig"},
            BUDGET,
            grid={"optimizer.kappa": p.pick(paper=KAPPAS, quick=[1.0, 0.5, 0.0, -0.5, -1.0], smoke=[1.0, -0.5])},
        ),
    ]


def fig13_runs(p: Preset) -> list[Sweep]:
    taus = p.pick(paper=TAUS, quick=[1e-5, 1e-7, 1e-10], smoke=[1e-6])
    from higbench.figures.oscillator import gn_search

    # GN at the best stable seed of fig2b's search (at the default tau 1e-6), then every tau.
    return [
        Sweep(
            opt,
            {"problem": "oscillator", "optimizer": opt},
            BUDGET,
            grid={"optimizer.tau": taus},
            seed_search=gn_search(p, **{"optimizer.tau": 1e-6}) if opt == "gn" else None,
        )
        for opt in ("hig", "gn")
    ]


def _lines(d: FigureData, ax, sweep: str, key: str, symbol: str, panel: str) -> None:
    import matplotlib

    values = sorted({j.overrides[key] for j in d.jobs if j.sweep == sweep}, reverse=True)
    cmap = matplotlib.colormaps["viridis"]
    for i, v in enumerate(values):
        runs = d.runs(sweep, **{key.replace(".", "__"): v})
        if runs:
            # d.curve names a divergence itself; other statuses are said here
            status = "" if runs[0].status in ("completed", "diverged") else f" ({runs[0].status})"
            # viridis up to 0.85: its bright yellow end is nearly invisible on white
            color = cmap(0.85 * i / max(1, len(values) - 1))
            d.curve(ax, runs, f"{symbol}={num(v)}{status}", panel=panel, color=color, lw=1.8)
    semilogy_axes(ax)
    legend(ax)


def plot_fig12(d: FigureData) -> None:
    fig, axes = new_figure(2, 1, width=4.8, height=3.8)
    _lines(d, axes[0, 0], "beta", "optimizer.beta", "β", "a) beta")
    axes[0, 0].set_title("a) oscillators, HIG: prefactor max(s)^β", fontsize=9)
    _lines(d, axes[0, 1], "kappa", "optimizer.kappa", "κ", "b) kappa")
    axes[0, 1].set_title("b) oscillators: exponent κ (1: GD, -1/2: HIG, -1: GN)", fontsize=9)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    d.save(fig)


def plot_fig13(d: FigureData) -> None:
    fig, axes = new_figure(2, 1, width=4.8, height=3.8, sharey=True)
    for ax, opt in zip(axes[0], ("hig", "gn")):
        _lines(d, ax, opt, "optimizer.tau", "τ", opt)
        ax.set_title(f"oscillators, {'HIG' if opt == 'hig' else 'Gauss-Newton'}: truncation τ", fontsize=9)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    d.save(fig)


register(
    Figure(
        "fig12", "Oscillator ablation: a) beta from 0 to -0.5, b) kappa from 1 to -1", fig12_runs, plot_fig12, family="ablation"
    )
)
register(Figure("fig13", "Oscillator ablation: tau from 1e-5 to 1e-10, HIG and GN", fig13_runs, plot_fig13, family="ablation"))


def check_beta(datas):
    runs = datas["fig12"].runs("beta")
    if len(runs) < 2:
        return checks.na("fig12a")
    fin = {r.cfg("optimizer.beta"): final([r]) for r in runs}
    finite = [v for v in fin.values() if math.isfinite(v)]
    spread = max(finite) / min(finite) if finite else math.inf
    measured = ", ".join(f"β={num(b)}: {e(v)}" for b, v in sorted(fin.items(), reverse=True)) + f" (spread {spread:.1f}x)"
    return (
        measured,
        verdict(spread < 10 and len(finite) == len(fin), spread < 100),
        "rule: final losses over β within 10x, none diverged (partly: within 100x)",
    )


def check_kappa(datas):
    runs = datas["fig12"].runs("kappa")
    pos = [final([r]) for r in runs if r.cfg("optimizer.kappa") > 0]
    neg = [final([r]) for r in runs if r.cfg("optimizer.kappa") < 0]
    if not pos or not neg:
        return checks.na("fig12b (needs kappa > 0 and < 0)")
    bp, bn = min(pos), min(neg)
    ratio = bp / bn if bn > 0 else math.inf
    return (
        f"best κ>0 {e(bp)}, best κ<0 {e(bn)} ({ratio:.0f}x)",
        verdict(ratio >= 100, ratio >= 10),
        "rule: best negative-κ run >= 100x below the best positive-κ run (partly: >= 10x)",
    )


def _stable(r) -> bool:
    return r.status == "completed" and r.final_loss < r.initial_loss


def check_tau(datas):
    d = datas["fig13"]
    hig, gn = d.runs("hig"), d.runs("gn")
    if not hig or not gn:
        return checks.na("fig13")
    tau = {id(r): r.cfg("optimizer.tau") for r in gn + hig}
    large = [r for r in gn if tau[id(r)] >= 1e-6]
    small = [r for r in gn if tau[id(r)] <= 1e-9]
    gn_best = min(final([g]) for g in gn)
    gn_stable_large = bool(large) and all(_stable(r) for r in large)
    gn_fails_small = bool(small) and all(r.status == "diverged" or final([r]) > 10 * gn_best for r in small)
    hig_stable = all(_stable(r) for r in hig)
    hig_better = min(final([r]) for r in hig) < gn_best
    seed = gn[0].seed
    from higbench.figures.oscillator import gn_search_summary

    measured = (
        f"GN (seed {seed}): "
        + ", ".join(f"τ={num(tau[id(r)])} {r.status} {e(final([r]))}" for r in gn)
        + "; HIG: "
        + ", ".join(f"τ={num(tau[id(r)])} {e(final([r]))}" for r in hig)
        + f"; GN seed search at τ=1e-6: {gn_search_summary(d, 'gn/search')}"
    )
    rule = (
        "rule: GN (best stable seed) stable at τ >= 1e-6 and diverging or >10x worse at τ <= 1e-9, every HIG run stable "
        "and HIG's best below GN's (partly: the GN part or the HIG part)"
    )
    if not small or not large:
        return measured, checks.NA, rule + "; needs GN runs at τ >= 1e-6 and at τ <= 1e-9"
    gn_part, hig_part = gn_stable_large and gn_fails_small, hig_stable and hig_better
    return measured, verdict(gn_part and hig_part, gn_part or hig_part), rule


claim(Claim("abl-1", ("fig12",), "Ablation: β has little influence on the outcome", "little influence", check_beta))
claim(
    Claim(
        "abl-2",
        ("fig12",),
        "Ablation: κ > 0 stagnates early; κ < 0 ends orders of magnitude lower",
        "orders of magnitude",
        check_kappa,
    )
)
claim(
    Claim(
        "abl-3",
        ("fig13",),
        "Ablation: GN becomes unstable for small τ (diverges at 1e-9, 1e-10); HIG tolerates τ and ends lower",
        "GN diverges, HIG stable",
        check_tau,
    )
)
