"""Figures 4a-c, 8-11: quantum dipole control (paper 3.3, appendix B.4), MLP and CNN.

The grids of figures 8-11 are conf/experiment/fig8_dipole_adam.yaml ... fig11_dipole_cnn_hig.yaml.
The quick preset evaluates on 256 instead of 1024 test states (see spec.PROBLEM_OVERRIDES).
"""

from __future__ import annotations

import numpy as np

from higbench.figures.claims import (
    DIPOLE_HIG_HOUR,
    Cause,
    below,
    best,
    claim,
    end_time,
    final,
    half_way,
    loss_at,
    median,
    oscillation,
    precision_probe,
    probe_values,
    require,
    sci,
    updates_of,
)
from higbench.figures.data import OPTIMIZER_NAMES, FigureData, RunData, num
from higbench.figures.plot import Curves, Custom, Facets, Series, legend
from higbench.figures.spec import UPDATES_ONLY, Budget, Figure, PerPreset, Preset, Sweep, paper_grid

MAIN = Budget(seconds={"paper": 3600, "quick": 60, "standard": 270})
GRID = Budget(seconds={"paper": 3600, "quick": 20, "standard": 120})
FIG4B_ADAM, FIG4B_HIG = [1e-4, 1e-3, 1e-2], [0.1, 0.5, 1.0]  # not given in the paper
PLATEAU = (0.4, 0.6)  # "Adam stagnates at a loss value of 0.5"
LE, HE = "test_low_energy_loss", "test_high_energy_loss"


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


def grid_figure(fid: str, title: str, problem: str, opt: str, experiment: str) -> Figure:
    """Adam: one panel per η, a line per b; HIG: one row per b, a panel per τ, a line per η."""
    grid = {KEYS[k]: PerPreset(paper_grid(experiment, KEYS[k]), **v) for k, v in REDUCED[fid].items()}
    sweep = Sweep(opt, {"problem": problem, "optimizer": opt}, GRID, grid=grid)
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
        ax.set_title(f"a) dipole: |Ψ|² under the HIG-trained network ({run.label()}); loss of this state {sci(fin)}", fontsize=8)
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
ENERGIES = [
    Series(o, label=f"{tag} {{label}}", y=y, ls=ls) for o in ("adam", "hig") for y, ls, tag in ((LE, "-", "LE"), (HE, "--", "HE"))
]
FIGURES = [
    Figure(
        "fig4a",
        "Dipole: |Psi(t,x)|^2 under a HIG-trained network, control behind it",
        [dip("hig")],
        panels=[Custom(fig4a)],
        size=(1, 1, 6.6, 4.4),
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
            )
        ],
        size=(1, 1, 6.2, 4.0),
    ),
    Figure(
        "fig4c",
        "Dipole: low- and high-energy losses, Adam (eta=1e-4) vs HIG (eta=0.5)",
        FIG4C,
        size=(1, 1, 6.2, 4.0),
        panels=[
            Curves(
                "c) dipole: low- and high-energy losses",
                ENERGIES,
                "energy losses",
                ylabel="low-energy (LE) / high-energy (HE) loss",
            )
        ],
    ),
    *(grid_figure(fid, *spec) for fid, spec in GRIDS.items()),
]
for _f in FIGURES:
    _f.notes = notes  # every figure of the family states the preset's deviations


# -- claims ---------------------------------------------------------------------------------


def plateau_seconds(run: RunData, band=PLATEAU, x: str = "wall_time") -> float:
    """Training seconds (``x="step"``: updates) with the test loss inside ``band`` (piecewise
    constant between evaluations).

    A duration, not a share of the run: the plateau lasts the same time in a longer run."""
    t, y = run.curves[x].to_numpy(dtype=float), run.curves["test_loss"].to_numpy(dtype=float)
    if len(t) < 2:
        return float("nan")
    inside = (y[:-1] >= band[0]) & (y[:-1] <= band[1])
    return float(np.sum(np.diff(t)[inside]))


def energy_ratio(run: RunData, above: float = PLATEAU[0]) -> float:
    """Median of high-energy / low-energy loss over the evaluations of the initial stage (after the
    first, test loss >= ``above``): the paper's claim is about that stage; once Adam has left its
    plateau both losses fall together. NaN when the run has no evaluation in that stage."""
    if HE not in run.curves:
        return float("nan")
    c = run.curves.iloc[1:]
    c = c[(c["test_loss"] >= above) & (c[LE] > 0)]
    return float(np.median(c[HE] / c[LE])) if len(c) else float("nan")


def _pair(datas, fid: str):
    adam, hig = datas[fid].runs("adam"), datas[fid].runs("hig")
    require(adam, hig, what=fid)
    return adam, hig


@claim(
    "dip-1",
    "fig4c",
    "plateau at 0.5",
    min_seconds=60,
    min_seeds=3,
    cause=Cause(
        "hardware",
        "Adam stagnates as the paper says, {adam_plateau_updates:.0f} updates on the plateau against HIG's "
        "{hig_plateau_updates:.0f}, then ends at {adam_final:e}; but this CPU makes an Adam update (b={adam_b}) in "
        "{adam_update_ms:.1f} ms, so those updates last {adam_plateau_s:.1f} s, under the rule's ten seconds of the "
        "paper's clock",
        {
            "Adam stagnates longer than HIG, in updates": lambda v: v["adam_plateau_updates"] >= 2 * v["hig_plateau_updates"],
            "shorter than ten seconds here": lambda v: v["adam_plateau_s"] < 10,
        },
    ),
)
def plateau(datas):
    """Dipole: Adam (η=1e-4) first stagnates at a loss of 0.5. Rule: Adam spends >= 10 s of training time near 0.5, at
    least twice as long as HIG, and ends below it (partly: longer than HIG)"""
    adam, hig = _pair(datas, "fig4c")
    ta, th = median(map(plateau_seconds, adam)), median(map(plateau_seconds, hig))
    measured = f"training time with loss in [{PLATEAU[0]}, {PLATEAU[1]}]: Adam {ta:.0f} s, HIG {th:.0f} s; Adam final "
    measured += sci(final(adam))
    values = {"adam_b": adam[0].cfg("batch_size"), "adam_plateau_s": ta, "adam_final": final(adam)}
    values["adam_plateau_updates"] = median(plateau_seconds(r, x="step") for r in adam)
    values["hig_plateau_updates"] = median(plateau_seconds(r, x="step") for r in hig)
    values["adam_update_ms"] = 1e3 * median(end_time(r) / max(updates_of(r), 1) for r in adam)
    full = ta >= 10 and ta >= 2 * th and final(adam) < PLATEAU[0]  # a stall is one once Adam has left it
    return measured, full, ta > th, values


@claim(
    "dip-2",
    "fig4c",
    "LE before HE for Adam",
    min_seconds=60,
    min_seeds=3,
    cause=Cause(
        "bug",
        "Adam's HE/LE ratio in the initial stage is {adam_ratio:.1f}, HIG's {hig_ratio:.1f} from {hig_stage_evals} "
        "evaluation(s): HIG leaves that stage within a few evaluations of our own interval (the figure now evaluates by "
        "updates)",
        {
            "Adam's ratio at the rule's level": lambda v: v["adam_ratio"] >= 3,
            "HIG's ratio above a third of Adam's": lambda v: v["hig_ratio"] > v["adam_ratio"] / 3,
        },
    ),
)
def energy(datas):
    """Dipole: Adam fits the low-energy component first; HIG minimises both uniformly. Rule: in the initial stage (test
    loss >= 0.4) Adam's high-energy loss >= 3x its low-energy loss, and HIG's ratio there <= a third of Adam's; HIG
    has at least three evaluations in that stage (partly: Adam's ratio >= 3, or above HIG's)"""
    adam, hig = _pair(datas, "fig4c")
    ra, rh = median(map(energy_ratio, adam)), median(map(energy_ratio, hig))
    evals = min(stage_evaluations(r) for r in hig)
    if evals < 3:
        measured = f"Adam's median HE/LE ratio {ra:.1f}; HIG has {evals} evaluation(s) in the initial stage"
        return measured, None, "needs >= 3 HIG evaluations while the loss is >= 0.4 (fig4c evaluates HIG by updates)"
    values = {"adam_ratio": ra, "hig_ratio": rh, "hig_stage_evals": evals}
    measured = f"median HE/LE loss ratio while the loss is >= {PLATEAU[0]}: Adam {ra:.1f}, HIG {rh:.1f} ({evals} evaluations)"
    return measured, ra >= 3 and rh <= ra / 3, (ra >= 3 or ra > rh), values


def stage_evaluations(run: RunData, above: float = PLATEAU[0]) -> int:
    """Evaluations after the first with the test loss >= ``above`` (the initial stage)."""
    return int((run.curves["test_loss"].iloc[1:] >= above).sum())


@claim("dip-3", "fig4c", "HIG below Adam", min_seconds=60, min_seeds=3)
def hig_below(datas):
    """Dipole: HIG minimises the loss faster and to a lower level than Adam. Rule: over fig. 4c's seeds (the paper's
    settings), HIG's median final loss <= half of Adam's, and HIG below Adam at a tenth of the budget (partly: below
    it at the end)"""
    adam, hig = _pair(datas, "fig4c")
    fa, fh = final(adam), final(hig)
    t10 = 0.1 * min(end_time(r) for r in adam + hig)
    ea, eh = median(loss_at(r, t10) for r in adam), median(loss_at(r, t10) for r in hig)
    measured = f"median over {len(hig)} seeds: final HIG {sci(fh)} vs Adam {sci(fa)} ({fa / fh:.2g}x); at {t10:.0f} s HIG "
    measured += f"{sci(eh)} vs Adam {sci(ea)}"
    return measured, fh <= 0.5 * fa and eh < ea, fh < fa, {"hig": fh, "adam": fa}


@claim(
    "dip-4",
    "fig4b",
    "~1e-6",
    min_seconds=DIPOLE_HIG_HOUR,
    cause=Cause(
        "hardware",
        "the best run reaches {low:e}, below {float32_floor:e} (where a float32 evaluation rounds) and far below the "
        "paper's {paper_dipole_limit:e}: the paper's limit is its solver's precision (the authors' dipole solver is "
        "complex64 throughout and its norm drifts over an episode; ours computes in float64 inside)",
        {"the best run below the float32 floor": lambda v: v["low"] < v["float32_floor"]},
    ),
)
def limit(datas):
    """Dipole: the attainable accuracy (pure physics optimisation) is about 1e-6. Rule: the best run reaches [1e-7,
    1e-5] (partly: below 1e-7, where the limit is the solver's precision, or (1e-5, 1e-4]); higher means the budget
    was too short to approach the limit"""
    require(runs := datas["fig4b"].runs(), what="fig4b")
    low = min(best([r]) for r in runs)
    shown = "below 1e-7 (float32 evaluation)" if low < 1e-7 else sci(low)
    return f"lowest test loss of any fig4b run: {shown}", 1e-7 <= low <= 1e-5, low <= 1e-4, {"low": low, "decisive": low < 1e-7}


@claim(
    "dip-5",
    "fig4b",
    "fast start, worst end",
    min_seconds=60,
    cause=Cause(
        "seeds",
        "the ordering of the η grid rests on {seeds} run per η; Adam's largest η lowest early: {fastest}, worst at the "
        "end: {worst}",
        {"one seed per setting": lambda v: v["seeds"] < 3},
    ),
)
def adam_large_lr(datas):
    """Dipole: the largest-η Adam run drops fastest initially but ends worst. Rule: the largest-η Adam run is the lowest
    at 10% of the budget and the highest at the end (partly: one of the two)"""
    adam = datas["fig4b"].runs("adam")
    require(len(adam) >= 2, what="fig4b Adam")
    lr = max(adam, key=lambda r: r.cfg("optimizer.lr")).cfg("optimizer.lr")
    t10 = 0.1 * min(float(r.curves["wall_time"].iloc[-1]) for r in adam)
    early, late = ({r.cfg("optimizer.lr"): f(r) for r in adam} for f in (lambda r: loss_at(r, t10), lambda r: final([r])))
    fastest, worst = min(early, key=early.get) == lr, max(late, key=late.get) == lr
    return (
        f"Adam η={num(lr)}: lowest at 10% of the budget: {fastest}; worst at the end: {worst}",
        fastest and worst,
        fastest or worst,
        {"fastest": fastest, "worst": worst},
    )


@claim("dip-6", "fig9", "stable 1e-5..1e-3, 1e-2 worse", min_seconds=120)
def tau(datas):
    """Dipole: HIG trains stably for τ from 1e-5 to 1e-3; τ=1e-2 cuts off information. Rule: τ in 1e-5..1e-3 within 10x
    of the best τ and τ=1e-2 worse than all of them (partly: one of the two)"""
    require(runs := datas["fig9"].runs("hig"), what="fig9")
    lr_b = {(r.cfg("optimizer.lr"), r.cfg("batch_size")) for r in runs}
    key = (0.5, 16) if (0.5, 16) in lr_b else sorted(lr_b)[0]
    per_tau = {r.cfg("optimizer.tau"): final([r]) for r in runs if (r.cfg("optimizer.lr"), r.cfg("batch_size")) == key}
    mid = [per_tau[t] for t in (1e-5, 1e-4, 1e-3) if t in per_tau]
    if not mid or 1e-2 not in per_tau:
        return "taus run: " + ", ".join(num(t) for t in sorted(per_tau)), None, "needs tau in {1e-5, 1e-4, 1e-3} and 1e-2"
    stable, cut = max(mid) <= 10 * min(per_tau.values()), per_tau[1e-2] > max(mid)
    return (
        f"η={num(key[0])} b={key[1]}: " + ", ".join(f"τ={num(t)}: {sci(v)}" for t, v in sorted(per_tau.items())),
        stable and cut,
        stable or cut,
    )


@claim(
    "cnn-1",
    "fig10 fig11",
    "HIG (η=0.7,b=16,τ=1e-4) below Adam (η=2e-4,b=256)",
    min_seconds=120,
    min_seeds=3,
    cause=Cause(
        "budget",
        "best HIG {hig:e} against the best Adam {adam:e}, HIG still falling ({hig_half:e} half-way)",
        {"HIG still falling": below("hig", "hig_half")},
    ),
)
def cnn(datas):
    """Dipole CNN: the best HIG run beats the best Adam run. Rule: best HIG CNN run's final loss <= half of the best Adam
    CNN run's (partly: below it)"""
    adam, hig = datas["fig10"].runs("adam"), datas["fig11"].runs("hig")
    require(adam, hig, what="fig10/fig11")
    a, h = min(adam, key=lambda r: final([r])), min(hig, key=lambda r: final([r]))
    fa, fh = final([a]), final([h])
    paper = [final([r]) for r in adam if r.cfg("optimizer.lr") == 2e-4 and r.cfg("batch_size") == 256]
    vs_paper = f"; Adam at the paper's η=2e-4 b=256 {sci(paper[0])} ({paper[0] / fh:.2g}x)" if paper else ""
    measured = f"best HIG {sci(fh)} ({h.label()}), best Adam of the grid {sci(fa)} ({a.label()}; HIG's advantage {fa / fh:.2g}x)"
    return measured + vs_paper, fh <= 0.5 * fa, fh < fa, {"hig": fh, "adam": fa, "hig_half": half_way([h])}


@claim(
    "dip-7",
    "fig8",
    "Adam: slow convergence or oscillation",
    min_seconds=20,
    cause=Cause(
        "seeds",
        "at all {slow_b} of {n_b} batch sizes the smallest η is the slowest at a tenth of the budget, as the paper says; "
        "the largest η oscillates most at {shaky_b} of them and a middle η at the others, each from a single seed per "
        "setting (a median needs three)",
        {"the smallest η slow at every b": lambda v: v["slow_b"] == v["n_b"], "one seed": lambda v: v["seeds"] < 3},
    ),
)
def adam_trade_off(datas):
    """Dipole (fig. 8): Adam trades slow convergence against oscillation. Rule: at every b the smallest-η Adam run is
    the highest at 10% of the budget (slow) and the largest-η run oscillates most over the last half (partly: at some
    b)"""
    require(runs := datas["fig8"].runs("adam"), what="fig8")
    per_b, slow, shaky, text = [], [], [], []
    for b in sorted({r.cfg("batch_size") for r in runs}):
        rs = sorted((r for r in runs if r.cfg("batch_size") == b), key=lambda r: r.cfg("optimizer.lr"))
        if len(rs) < 2:
            continue
        t10 = 0.1 * min(end_time(r) for r in rs)
        early, wobble = [loss_at(r, t10) for r in rs], [oscillation(r) for r in rs]
        slow.append(early[0] == max(early))
        shaky.append(wobble[-1] == max(wobble))
        per_b.append(slow[-1] and shaky[-1])
        lo, hi = (num(r.cfg("optimizer.lr")) for r in (rs[0], rs[-1]))
        text.append(
            f"b={b}: at 10% of the budget η={lo} {sci(early[0])}, η={hi} {sci(early[-1])} (lowest: "
            f"η={num(rs[int(np.argmin(early))].cfg('optimizer.lr'))}); oscillation "
            + ", ".join(f"η={num(r.cfg('optimizer.lr'))} {w:.2g}" for r, w in zip(rs, wobble))
        )
    require(per_b, what="fig8 (two η at one b)")
    values = {"n_b": len(per_b), "slow_b": sum(slow), "shaky_b": sum(shaky)}
    return "; ".join(text), all(per_b), any(per_b), values


@claim(
    "dip-8",
    "fig9",
    "τ above ~1e-6",
    min_seconds=120,
    cause=Cause(
        "hardware",
        "with our double-precision inversion τ={probe_tau_small:e} trains as well as the stable range ({tau6:e} against "
        "{best_mid:e}); with the inversion in single precision, as in the authors' code, it ends at "
        "{probe_small_float32:e} after {probe_updates} updates, {probe_float32_small_over_large:.0f}x above "
        "τ={probe_tau_large:e} ({probe_large_float32:e}), where in double precision the first ends at "
        "{probe_float64_small_over_large:.1f} times the second (precision probe): the paper's lower limit on τ is its "
        "inversion's precision",
        {
            "fine in double precision here": lambda v: v["tau6"] <= 2 * v["best_mid"],
            "far worse in single precision": lambda v: v["probe_float32_small_over_large"] >= 10,
            "alike in double precision": lambda v: v["probe_float64_small_over_large"] < 3,
        },
        probe=probe_values("precision.csv", precision_probe("dipole")),
    ),
)
def tau_floor(datas):
    """Dipole (fig. 9): τ must be above about 1e-6. Rule: at η=0.5, b=16 the τ=1e-6 run ends >= 2x above the best of
    τ in 1e-5..1e-3 (partly: above it)"""
    require(runs := datas["fig9"].runs("hig"), what="fig9")
    per_tau = {r.cfg("optimizer.tau"): final([r]) for r in runs if (r.cfg("optimizer.lr"), r.cfg("batch_size")) == (0.5, 16)}
    mid = [per_tau[t] for t in (1e-5, 1e-4, 1e-3) if t in per_tau]
    require(mid and 1e-6 in per_tau, what="fig9 τ=1e-6 and 1e-5..1e-3 at η=0.5 b=16")
    low = per_tau[1e-6]
    values = {"tau6": low, "best_mid": min(mid)}
    return f"τ=1e-6 {sci(low)} vs best of 1e-5..1e-3 {sci(min(mid))}", low >= 2 * min(mid), low > min(mid), values


@claim("cnn-2", "fig11", "stable for τ 1e-5..1e-3", min_seconds=20)
def cnn_tau(datas):
    """Dipole CNN (fig. 11): HIG trains stably for τ from 1e-5 to 1e-3. Rule: every HIG CNN run with τ in 1e-5..1e-3
    completes and ends below its initial loss (partly: all but one)"""
    runs = [r for r in datas["fig11"].runs("hig") if 1e-5 <= r.cfg("optimizer.tau") <= 1e-3]
    require(runs, what="fig11 τ in 1e-5..1e-3")
    bad = [r.label() for r in runs if not (r.status == "completed" and r.final_loss < r.initial_loss)]
    return f"{len(runs) - len(bad)}/{len(runs)} stable" + (f"; unstable: {', '.join(bad)}" if bad else ""), not bad, len(bad) <= 1
