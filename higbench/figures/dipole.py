"""Figures 4a-c, 8-11: quantum dipole control (paper 3.3, appendix B.4), MLP and CNN.

The quick preset evaluates on 256 instead of 1024 test states (see spec.PROBLEM_OVERRIDES).
"""

from __future__ import annotations

import numpy as np

from higbench.figures import checks
from higbench.figures.checks import best, e, final, loss_at, verdict
from higbench.figures.data import COLORS, FigureData, RunData, legend, new_figure, num, semilogy_axes
from higbench.figures.registry import Claim, claim, register
from higbench.figures.spec import Budget, Figure, Preset, Sweep

MAIN = Budget(seconds={"paper": 3600, "quick": 60, "standard": 270})
GRID = Budget(seconds={"paper": 3600, "quick": 20, "standard": 120})
FIG4B_ADAM = [1e-4, 1e-3, 1e-2]
FIG4B_HIG = [0.1, 0.5, 1.0]
TAUS = [1e-6, 1e-5, 1e-4, 1e-3, 1e-2]
PLATEAU = (0.4, 0.6)  # "Adam stagnates at a loss value of 0.5"


def notes(p: Preset) -> list[str]:
    return ["deviation: test set of 256 states instead of 1024 (evaluation cost)"] if p.name == "quick" else []


def fig4b_runs(p: Preset) -> list[Sweep]:
    return [
        Sweep(
            "adam",
            {"problem": "dipole", "optimizer": "adam"},
            MAIN,
            grid={"optimizer.lr": p.pick(paper=FIG4B_ADAM, smoke=[1e-4])},
        ),
        Sweep(
            "hig", {"problem": "dipole", "optimizer": "hig"}, MAIN, grid={"optimizer.lr": p.pick(paper=FIG4B_HIG, smoke=[0.5])}
        ),
    ]


def fig4c_runs(p: Preset) -> list[Sweep]:
    # Figure 4c's settings are the per-pair defaults (conf/problem_optimizer/dipole_*.yaml):
    # Adam eta=1e-4, HIG eta=0.5 tau=1e-5, b=16; seed 0 is fig4b's run.
    seeds = p.pick(paper=[0, 1, 2], smoke=[0])  # comparisons use the median of 3 seeds
    return [
        Sweep("adam", {"problem": "dipole", "optimizer": "adam"}, MAIN, seeds=seeds),
        Sweep("hig", {"problem": "dipole", "optimizer": "hig"}, MAIN, seeds=seeds),
    ]


def fig4a_runs(p: Preset) -> list[Sweep]:
    return [Sweep("hig", {"problem": "dipole", "optimizer": "hig"}, MAIN)]  # = fig4c's HIG run, seed 0


def fig8_runs(p: Preset) -> list[Sweep]:
    return [
        Sweep(
            "adam",
            {"problem": "dipole", "optimizer": "adam"},
            GRID,
            grid={
                "optimizer.lr": p.pick(paper=[1e-5, 1e-4, 1e-3, 1e-2], quick=[1e-4, 1e-3, 1e-2], smoke=[1e-3]),
                "batch_size": p.pick(paper=[16, 256, 512, 1024], quick=[16, 256], smoke=[16]),
            },
        )
    ]


def fig9_runs(p: Preset) -> list[Sweep]:
    return [
        Sweep(
            "hig",
            {"problem": "dipole", "optimizer": "hig"},
            GRID,
            grid={
                "optimizer.lr": p.pick(paper=[0.1, 0.5, 1.0], quick=[0.5]),
                "batch_size": p.pick(paper=[8, 16], quick=[16], smoke=[8]),
                "optimizer.tau": p.pick(paper=TAUS, smoke=[1e-5, 1e-2]),
            },
        )
    ]


def fig10_runs(p: Preset) -> list[Sweep]:
    return [
        Sweep(
            "adam",
            {"problem": "dipole_cnn", "optimizer": "adam"},
            GRID,
            grid={
                "optimizer.lr": p.pick(paper=[2e-5, 2e-4, 2e-3], smoke=[2e-4]),
                "batch_size": p.pick(paper=[256, 512, 1024], quick=[256]),
            },
        )
    ]


def fig11_runs(p: Preset) -> list[Sweep]:
    return [
        Sweep(
            "hig",
            {"problem": "dipole_cnn", "optimizer": "hig"},
            GRID,
            grid={
                "optimizer.lr": p.pick(paper=[0.3, 0.7, 1.0], quick=[0.7]),
                "batch_size": p.pick(paper=[8, 16], quick=[16], smoke=[8]),
                "optimizer.tau": p.pick(paper=TAUS, smoke=[1e-4]),
            },
        )
    ]


# -- plots ----------------------------------------------------------------------------------


def plot_fig4a(d: FigureData) -> None:
    fig, axes = new_figure(1, 1, width=6.6, height=4.4)
    ax = axes[0, 0]
    runs = d.runs("hig")
    if not runs:
        legend(ax)
    else:
        run = runs[0]
        problem, model = run.build_model()
        batch = problem.test_set()[:1]
        states, u = problem.trajectory(model, batch)
        states = states[0].double().numpy()  # (steps+1, 14, 2)
        prob = states[..., 0] ** 2 + states[..., 1] ** 2
        n_x = prob.shape[1]
        dt = float(problem.cfg.dt)
        t = np.arange(prob.shape[0]) * dt
        x = (np.arange(1, n_x + 1)) * 2.0 / (n_x + 1)
        im = ax.imshow(prob.T, aspect="auto", origin="lower", extent=(t[0], t[-1], x[0], x[-1]), cmap="magma")
        fig.colorbar(im, ax=ax, orientation="horizontal", fraction=0.05, pad=0.2, label="|Ψ(t,x)|²")
        ax2 = ax.twinx()
        uu = u[0].double().numpy()
        ax2.plot((np.arange(len(uu)) + 0.5) * dt, uu, color="tab:blue", alpha=0.7, lw=1)
        ax2.set_ylabel("network output u(t)", color="tab:blue")
        for k in range(n_x):
            d.record("probability", f"x={x[k]:.3f}", run, "t", t, "abs_psi_sq", prob[:, k])
        d.record("control", "u", run, "t", (np.arange(len(uu)) + 0.5) * dt, "u", uu)
        fin = float(problem.loss(problem.physics(batch.inputs, u), batch.targets)[0])
        ax.set_title(f"a) dipole: |Ψ|² under the HIG-trained network ({run.label()}); loss of this state {e(fin)}", fontsize=8)
    ax.set_xlabel("time t")
    ax.set_ylabel("x")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    d.save(fig)


def plot_fig4b(d: FigureData) -> None:
    fig, axes = new_figure(1, 1, width=6.2, height=4.0)
    ax = axes[0, 0]
    for name, shades in (("adam", ("#08306b", "#4292c6", "#9ecae1")), ("hig", ("#a1d99b", "#41ab5d", "#00441b"))):
        lrs = sorted({j.overrides["optimizer.lr"] for j in d.jobs if j.sweep == name})
        for lr, color in zip(lrs, shades):
            runs = d.runs(name, optimizer__lr=lr)
            if runs:
                d.curve(ax, runs, runs[0].label(), panel="loss", color=color)
    semilogy_axes(ax)
    ax.set_title("b) dipole: Adam and HIG for several η (b=16)", fontsize=9)
    legend(ax)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    d.save(fig)


def plot_fig4c(d: FigureData) -> None:
    fig, axes = new_figure(1, 1, width=6.2, height=4.0)
    ax = axes[0, 0]
    for name in ("adam", "hig"):
        runs = d.runs(name)
        if not runs:
            continue
        for metric, ls, tag in (("test_low_energy_loss", "-", "LE"), ("test_high_energy_loss", "--", "HE")):
            d.curve(ax, runs, f"{tag} {runs[0].label()}", panel="energy losses", y=metric, color=COLORS[name], ls=ls)
    semilogy_axes(ax, ylabel="low-energy (LE) / high-energy (HE) loss")
    ax.set_title("c) dipole: low- and high-energy losses", fontsize=9)
    legend(ax)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    d.save(fig)


def _grid(d: FigureData, sweep: str, col_key: str, row_key: str, line_key: str, title: str) -> None:
    jobs = [j for j in d.jobs if j.sweep == sweep]
    cols = sorted({j.overrides[col_key] for j in jobs})
    rows = sorted({j.overrides[row_key] for j in jobs})
    lines = sorted({j.overrides[line_key] for j in jobs})
    sym = {"optimizer.lr": "η", "batch_size": "b", "optimizer.tau": "τ"}
    fig, axes = new_figure(len(cols), len(rows), width=3.3, height=2.6, sharey=True)
    palette = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple")
    for r, rv in enumerate(rows):
        for c, cv in enumerate(cols):
            ax = axes[r, c]
            for i, lv in enumerate(lines):
                where = {col_key.replace(".", "__"): cv, row_key.replace(".", "__"): rv, line_key.replace(".", "__"): lv}
                runs = d.runs(sweep, **where)
                if runs:
                    d.curve(
                        ax,
                        runs,
                        f"{sym[line_key]}={num(lv)}",
                        panel=f"{sym[row_key]}={num(rv)} {sym[col_key]}={num(cv)}",
                        color=palette[i % 5],
                    )
            semilogy_axes(ax, xlabel="wall-clock time [s]" if r == len(rows) - 1 else "", ylabel="test loss" if c == 0 else "")
            ax.set_title(f"{title} {sym[row_key]}={num(rv)} {sym[col_key]}={num(cv)}", fontsize=8)
            legend(ax)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    d.save(fig)


def plot_fig8(d: FigureData) -> None:
    _grid_1row(d, "adam", "optimizer.lr", "batch_size", "Adam")


def _grid_1row(d: FigureData, sweep: str, col_key: str, line_key: str, title: str) -> None:
    jobs = [j for j in d.jobs if j.sweep == sweep]
    cols = sorted({j.overrides[col_key] for j in jobs})
    lines = sorted({j.overrides[line_key] for j in jobs})
    sym = {"optimizer.lr": "η", "batch_size": "b", "optimizer.tau": "τ"}
    fig, axes = new_figure(len(cols), 1, width=3.4, height=2.9, sharey=True)
    palette = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple")
    for c, cv in enumerate(cols):
        ax = axes[0, c]
        for i, lv in enumerate(lines):
            runs = d.runs(sweep, **{col_key.replace(".", "__"): cv, line_key.replace(".", "__"): lv})
            if runs:
                d.curve(ax, runs, f"{sym[line_key]}={num(lv)}", panel=f"{sym[col_key]}={num(cv)}", color=palette[i % 5])
        semilogy_axes(ax, ylabel="test loss" if c == 0 else "")
        ax.set_title(f"{title} {sym[col_key]}={num(cv)}", fontsize=9)
        legend(ax)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    d.save(fig)


def plot_fig9(d: FigureData) -> None:
    _grid(d, "hig", "optimizer.tau", "batch_size", "optimizer.lr", "HIG")


def plot_fig10(d: FigureData) -> None:
    _grid_1row(d, "adam", "optimizer.lr", "batch_size", "CNN Adam")


def plot_fig11(d: FigureData) -> None:
    _grid(d, "hig", "optimizer.tau", "batch_size", "optimizer.lr", "CNN HIG")


register(
    Figure(
        "fig4a",
        "Dipole: |Psi(t,x)|^2 under a HIG-trained network, control behind it",
        fig4a_runs,
        plot_fig4a,
        family="dipole",
        notes=notes,
    )
)
register(Figure("fig4b", "Dipole: Adam and HIG for several learning rates", fig4b_runs, plot_fig4b, family="dipole", notes=notes))
register(
    Figure(
        "fig4c",
        "Dipole: low- and high-energy losses, Adam (eta=1e-4) vs HIG (eta=0.5)",
        fig4c_runs,
        plot_fig4c,
        family="dipole",
        notes=notes,
    )
)
register(
    Figure("fig8", "Dipole: Adam for several learning rates and batch sizes", fig8_runs, plot_fig8, family="dipole", notes=notes)
)
register(
    Figure(
        "fig9",
        "Dipole: HIG for several learning rates, batch sizes and truncations tau",
        fig9_runs,
        plot_fig9,
        family="dipole",
        notes=notes,
    )
)
register(
    Figure(
        "fig10",
        "Dipole with a CNN: Adam for several learning rates and batch sizes",
        fig10_runs,
        plot_fig10,
        family="dipole",
        notes=notes,
    )
)
register(
    Figure(
        "fig11",
        "Dipole with a CNN: HIG for several learning rates, batch sizes and tau",
        fig11_runs,
        plot_fig11,
        family="dipole",
        notes=notes,
    )
)


# -- claims ---------------------------------------------------------------------------------


def plateau_fraction(run: RunData, band=PLATEAU) -> float:
    """Fraction of the run's training time with the test loss inside ``band`` (piecewise constant)."""
    c = run.curves
    t, y = c["wall_time"].to_numpy(dtype=float), c["test_loss"].to_numpy(dtype=float)
    if len(t) < 2 or t[-1] <= 0:
        return float("nan")
    inside = (y[:-1] >= band[0]) & (y[:-1] <= band[1])
    return float(np.sum(np.diff(t)[inside]) / (t[-1] - t[0]))


def energy_ratio(run: RunData) -> float:
    """Median over evaluations (after the first) of high-energy loss / low-energy loss."""
    c = run.curves
    if "test_high_energy_loss" not in c:
        return float("nan")
    he, le = c["test_high_energy_loss"].to_numpy(dtype=float)[1:], c["test_low_energy_loss"].to_numpy(dtype=float)[1:]
    ok = le > 0
    return float(np.median(he[ok] / le[ok])) if ok.any() else float("nan")


def check_plateau(datas):
    d = datas["fig4c"]
    adam, hig = d.runs("adam"), d.runs("hig")
    if not adam or not hig:
        return checks.na("fig4c")
    fa = checks.median([plateau_fraction(r) for r in adam])
    fh = checks.median([plateau_fraction(r) for r in hig])
    measured = (
        f"share of training time with loss in [{PLATEAU[0]}, {PLATEAU[1]}]: Adam {fa:.0%}, HIG {fh:.0%}; Adam final "
        f"{e(final(adam))}"
    )
    left = final(adam) < PLATEAU[0]  # a stall is only a stall once Adam has left it again
    return (
        measured,
        verdict(fa >= 0.2 and fa > fh and left, fa > fh),
        "rule: Adam spends >= 20% of its time near 0.5, more than HIG, and ends below it (partly: more than HIG)",
    )


def check_energy(datas):
    d = datas["fig4c"]
    adam, hig = d.runs("adam"), d.runs("hig")
    if not adam or not hig:
        return checks.na("fig4c")
    ra = checks.median([energy_ratio(r) for r in adam])
    rh = checks.median([energy_ratio(r) for r in hig])
    measured = f"median HE/LE loss ratio: Adam {ra:.1f}, HIG {rh:.1f}"
    return (
        measured,
        verdict(ra >= 3 and rh <= ra / 3, ra > rh),
        (
            "rule: Adam's high-energy loss >= 3x its low-energy loss and HIG's ratio <= a third of Adam's (partly: Adam's "
            "ratio above HIG's)"
        ),
    )


def check_hig_below(datas):
    d = datas["fig4b"]
    adam, hig = d.runs("adam"), d.runs("hig")
    if not adam or not hig:
        return checks.na("fig4b")
    ba = min(final([r]) for r in adam)
    bh = min(final([r]) for r in hig)
    paper = [final([r]) for r in adam if r.cfg("optimizer.lr") == 1e-4]
    vs_paper = f"; Adam at the paper's η=1e-4 {e(paper[0])} (HIG's advantage {paper[0] / bh:.2g}x)" if paper else ""
    return (
        f"best final loss: HIG {e(bh)}, best Adam of the η grid (re-tuned) {e(ba)} (advantage {ba / bh:.2g}x){vs_paper}",
        verdict(bh <= 0.5 * ba, bh < ba),
        "rule: best HIG run's final loss <= half of the best Adam run's of the same-budget η grid (partly: below it)",
    )


def check_limit(datas):
    d = datas["fig4b"]
    runs = d.runs()
    if not runs:
        return checks.na("fig4b")
    low = min(best([r]) for r in runs)
    return (
        f"lowest test loss of any fig4b run: {e(low)}",
        verdict(1e-7 <= low <= 1e-5, 1e-5 < low <= 1e-4),
        (
            "rule: the best run reaches [1e-7, 1e-5] (partly: (1e-5, 1e-4]); higher means the budget was too short to "
            "approach the limit"
        ),
    )


def check_adam_large_lr(datas):
    d = datas["fig4b"]
    adam = d.runs("adam")
    if len(adam) < 2:
        return checks.na("fig4b Adam")
    big = max(adam, key=lambda r: r.cfg("optimizer.lr"))
    t10 = 0.1 * min(float(r.curves["wall_time"].iloc[-1]) for r in adam)
    early = {r.cfg("optimizer.lr"): loss_at(r, t10) for r in adam}
    late = {r.cfg("optimizer.lr"): final([r]) for r in adam}
    lr = big.cfg("optimizer.lr")
    fastest = min(early, key=early.get) == lr
    worst = max(late, key=late.get) == lr
    measured = f"Adam η={num(lr)}: lowest at 10% of the budget: {fastest}; worst at the end: {worst}"
    return (
        measured,
        verdict(fastest and worst, fastest or worst),
        "rule: the largest-η Adam run is the lowest at 10% of the budget and the highest at the end (partly: one of the two)",
    )


def check_tau(datas):
    d = datas["fig9"]
    runs = d.runs("hig")
    if not runs:
        return checks.na("fig9")
    lr_b = {(r.cfg("optimizer.lr"), r.cfg("batch_size")) for r in runs}
    key = (0.5, 16) if (0.5, 16) in lr_b else sorted(lr_b)[0]
    per_tau = {r.cfg("optimizer.tau"): final([r]) for r in runs if (r.cfg("optimizer.lr"), r.cfg("batch_size")) == key}
    mid = [per_tau[t] for t in (1e-5, 1e-4, 1e-3) if t in per_tau]
    if not mid or 1e-2 not in per_tau:
        return "taus run: " + ", ".join(num(t) for t in sorted(per_tau)), checks.NA, "needs tau in {1e-5, 1e-4, 1e-3} and 1e-2"
    stable = max(mid) <= 10 * min(per_tau.values())
    cut = per_tau[1e-2] > max(mid)
    measured = f"η={num(key[0])} b={key[1]}: " + ", ".join(f"τ={num(t)}: {e(v)}" for t, v in sorted(per_tau.items()))
    return (
        measured,
        verdict(stable and cut, stable or cut),
        "rule: τ in 1e-5..1e-3 within 10x of the best τ and τ=1e-2 worse than all of them (partly: one of the two)",
    )


def check_cnn(datas):
    adam, hig = datas["fig10"].runs("adam"), datas["fig11"].runs("hig")
    if not adam or not hig:
        return checks.na("fig10/fig11")
    a = min(adam, key=lambda r: final([r]))
    h = min(hig, key=lambda r: final([r]))
    fa, fh = final([a]), final([h])
    paper = [final([r]) for r in adam if r.cfg("optimizer.lr") == 2e-4 and r.cfg("batch_size") == 256]
    vs_paper = f"; Adam at the paper's η=2e-4 b=256 {e(paper[0])} ({paper[0] / fh:.2g}x)" if paper else ""
    return (
        f"best HIG {e(fh)} ({h.label()}), best Adam of the grid {e(fa)} ({a.label()}; HIG's advantage {fa / fh:.2g}x)" + vs_paper,
        verdict(fh <= 0.5 * fa, fh < fa),
        "rule: best HIG CNN run's final loss <= half of the best Adam CNN run's (partly: below it)",
    )


claim(Claim("dip-1", ("fig4c",), "Dipole: Adam (η=1e-4) first stagnates at a loss of 0.5", "plateau at 0.5", check_plateau))
claim(
    Claim(
        "dip-2",
        ("fig4c",),
        "Dipole: Adam fits the low-energy component first; HIG minimises both uniformly",
        "LE before HE for Adam",
        check_energy,
    )
)
claim(
    Claim(
        "dip-3",
        ("fig4b",),
        "Dipole: HIG minimises the loss faster and to a lower level than Adam",
        "HIG below Adam",
        check_hig_below,
    )
)
claim(
    Claim("dip-4", ("fig4b",), "Dipole: the attainable accuracy (pure physics optimisation) is about 1e-6", "~1e-6", check_limit)
)
claim(
    Claim(
        "dip-5",
        ("fig4b",),
        "Dipole: the largest-η Adam run drops fastest initially but ends worst",
        "fast start, worst end",
        check_adam_large_lr,
    )
)
claim(
    Claim(
        "dip-6",
        ("fig9",),
        "Dipole: HIG trains stably for τ from 1e-5 to 1e-3; τ=1e-2 cuts off information",
        "stable 1e-5..1e-3, 1e-2 worse",
        check_tau,
    )
)
claim(
    Claim(
        "cnn-1",
        ("fig10", "fig11"),
        "Dipole CNN: the best HIG run beats the best Adam run",
        "HIG (η=0.7,b=16,τ=1e-4) below Adam (η=2e-4,b=256)",
        check_cnn,
    )
)
