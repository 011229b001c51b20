"""Figures 2a-c, 5, 6: control of two coupled nonlinear oscillators (paper 3.1, appendix B.2).

fig2b's runs use the per-pair paper defaults (conf/problem_optimizer/oscillator_*.yaml, the
hyper-parameters of table 2); the grids of figures 5 and 6 are conf/experiment/fig5_*.yaml
and fig6_adam.yaml.
"""

from __future__ import annotations

import math

import numpy as np

from higbench.figures.claims import (
    OSC_ADAM_HOUR,
    OSC_HIG_HOUR,
    Cause,
    at_update,
    below,
    budget_of,
    claim,
    crossing_time,
    end_time,
    final,
    half_way,
    loss_at,
    median,
    oscillation,
    probe_values,
    require,
    sci,
    updates_of,
)
from higbench.figures.data import COLORS, OPTIMIZER_NAMES, FigureData, num
from higbench.figures.plot import Curves, Custom, Facets, Series, legend
from higbench.figures.spec import Budget, Figure, PerPreset, SeedSearch, Sweep, paper_grid

FIG2B_OPTIMIZERS = ("adadelta", "adagrad", "adam", "gn", "hig", "rmsprop", "sgd")
GD_FAMILY = ("adadelta", "adagrad", "adam", "rmsprop", "sgd")
MAIN = Budget(seconds={"paper": 3600, "quick": 120, "standard": 240, "long": 900})
GRID = Budget(seconds={"paper": 3600, "quick": 12, "standard": 15})
FIG2C_BATCHES = {"adam": [256, 512, 1024], "gn": [32, 64, 128], "hig": [32, 64, 128]}
FIG5_LRS = {opt: paper_grid(f"fig5_{opt}", "optimizer.lr") for opt in ("adadelta", "adagrad", "sgd", "rmsprop")}
FIG6_LRS = paper_grid("fig6_adam", "optimizer.lr")
GRID_BATCHES = paper_grid("fig6_adam", "batch_size")
# GN from a fresh initialisation takes a first step far larger than the weights for most
# seeds (NaN or a loss 14-600x higher); the authors show GN's "best stable run" of one
# fixed seed, so GN's runs here use the best stable seed of a short search.
GN_SEARCH_BUDGET = Budget(seconds={"paper": 60, "quick": 15, "standard": 15})


def gn_search(**overrides) -> SeedSearch:
    return SeedSearch(PerPreset(list(range(8)), smoke=[0, 1]), GN_SEARCH_BUDGET, dict(overrides))


def osc(name: str, opt: str | None = None, budget: Budget = MAIN, **kw) -> Sweep:
    """A sweep of oscillator runs (GN: after a seed search)."""
    search = {"seed_search": gn_search()} if opt == "gn" and "seed_search" not in kw else {}
    return Sweep(name, {"problem": "oscillator", **({"optimizer": opt} if opt else {})}, budget, **search, **kw)


FIG2B = [
    osc("best", grid={"optimizer": [o for o in FIG2B_OPTIMIZERS if o != "gn"]}),
    osc("best", "gn"),
    # Fair baseline: Adam re-tuned at the same budget (its cost per update hardly grows with b).
    osc(
        "adam_tuned",
        "adam",
        grid={"optimizer.lr": PerPreset([1e-4, 1e-3, 3e-3], [1e-3, 3e-3], [1e-3]), "batch_size": PerPreset([512, 2048], [2048])},
    ),
]


def _grid(opt: str, lrs: list) -> Sweep:
    return osc(
        opt,
        opt,
        GRID,
        grid={
            "optimizer.lr": PerPreset(lrs, smoke=lrs[1:2] if opt != "adam" else lrs[:2]),
            "batch_size": PerPreset(GRID_BATCHES, [256, 1024], [512]),
        },
    )


def fig2a(d: FigureData, ax) -> None:
    import torch

    if found := d.trajectory("hig"):
        run, problem, batch, states, u = found
        states, u = states[0].double().numpy(), u[0].double().numpy()
        dt = float(problem.cfg.dt)
        t, tu = np.arange(states.shape[0]) * dt, (np.arange(len(u)) + 0.5) * dt
        ax2 = ax.twinx()
        ax2.fill_between(tu, 0, u, step="mid", color="tab:blue", alpha=0.15, lw=0)
        ax2.plot(tu, u, color="tab:blue", alpha=0.4, lw=1, label="control u(t)")
        ax2.set_ylabel("network output u(t)", color="tab:blue")
        ax.set_zorder(ax2.get_zorder() + 1)
        ax.patch.set_visible(False)
        for i, (name, color) in enumerate((("x₁", "tab:orange"), ("x₂", "tab:red"))):
            ax.plot(t, states[:, i], color=color, lw=2, label=f"{name}(t)")
            ax.plot(t[-1], batch.targets[0, i].item(), "o", color=color, mfc="none", ms=9)
            d.record("state", name, run, "t", t, name, states[:, i])
        d.record("control", "u", run, "t", tu, "u", u)
        err = float(((torch.as_tensor(states[-1]) - batch.targets[0].double()) ** 2).sum())
        ax.set_title(f"a) oscillators under the HIG-trained network ({run.label()}); final squared error {sci(err)}", fontsize=8)
        ax.plot([], [], "o", color="k", mfc="none", label="targets (= initial state)")
    legend(ax, **({"loc": "upper left"} if found else {}))
    ax.set(xlabel="time t", ylabel="oscillator position")


def reference(d: FigureData, ax) -> None:
    """The authors' points on the axes; their loss points and update times beside ours in the sidecar."""
    from higbench.figures.reference import OSCILLATOR_CURVES, SOURCE, UPDATE_SECONDS

    points = []
    for opt, ref in OSCILLATOR_CURVES.items():
        t, y = zip(*ref["points"])
        ax.plot(t, y, "o--", color=COLORS[opt], mfc="none", label=f"authors' TF code {OPTIMIZER_NAMES[opt]} ({ref['note']})")
        d.record("loss", f"reference {opt}", None, "wall_time", t, "test_loss", y)
        runs = d.runs(opt)
        for t, loss in ref["points"]:
            ours = median(loss_at(r, t) for r in runs) if runs and all(t <= end_time(r) for r in runs) else None
            points.append({"optimizer": opt, "t": t, "reference": loss, "higbench": ours})
    ours = {
        o: median(float(r.updates["update_s"].iloc[1:].median()) for r in rs)
        for o in ("adam", "hig", "gn")
        if (rs := d.runs(o)) and "update_s" in rs[0].updates
    }
    rows = [
        {**r, "higbench_update_s": ours.get(r["optimizer"]) if r["problem"] == "oscillator" else None} for r in UPDATE_SECONDS
    ]
    d.sidecar["reference"] = {"source": SOURCE, "loss_points": points, "update_seconds": rows}


def _ref_panel() -> Curves:
    from higbench.figures.reference import OSCILLATOR_CURVES

    title = "oscillators: higbench beside the authors' TensorFlow code (same settings, 2 CPU cores)"
    return Curves(title, [Series(o, label="higbench {label}") for o in OSCILLATOR_CURVES], extra=reference)


FIGURES = [
    Figure(
        "fig2a",
        "Oscillators: time evolution under a HIG-trained network, control signal behind it",
        [osc("hig", "hig")],
        panels=[Custom(fig2a)],
        size=(1, 1, 6.5, 3.6),
    ),
    Figure(
        "fig2b",
        "Oscillators: loss over wall-clock time, best run of each optimizer",
        FIG2B,
        panels=[Curves("b) oscillators: best run per optimizer (table 2 settings)", [Series("best", "optimizer.name")], ncol=2)],
    ),
    Figure(
        "fig2c",
        "Oscillators: Adam, GN and HIG for several batch sizes",
        [osc(o, o, grid={"batch_size": PerPreset(bs, bs[::2] if o == "gn" else bs, bs[:2])}) for o, bs in FIG2C_BATCHES.items()],
        panels=[
            Curves(
                "c) oscillators: Adam, GN, HIG for several batch sizes b",
                [Series(o, "batch_size", ls=["-", "--", ":"]) for o in FIG2C_BATCHES],
                ncol=3,
            )
        ],
    ),
    Figure(
        "fig5",
        "Oscillators: Adadelta, Adagrad, SGD, RMSprop for several learning rates and batch sizes",
        [_grid(o, lrs) for o, lrs in FIG5_LRS.items()],
        panels=[Facets(list(FIG5_LRS), "optimizer.lr", "batch_size", rows="sweep", size=(3.6, 2.7))],
    ),
    Figure(
        "fig6",
        "Oscillators: Adam for several learning rates and batch sizes",
        [_grid("adam", FIG6_LRS)],
        panels=[Facets(["adam"], "optimizer.lr", "batch_size", rows="sweep", size=(3.6, 2.7))],
    ),
    # = fig2b's Adam, HIG and GN runs (table-2 settings, the reference's settings)
    Figure(
        "ref_oscillator",
        "Oscillators: higbench's Adam and HIG curves beside the authors' TensorFlow code on the same CPU kind",
        [osc("adam", "adam"), osc("hig", "hig"), osc("gn", "gn")],
        panels=[_ref_panel()],
    ),
]


# -- claims ---------------------------------------------------------------------------------


def _finals(d: FigureData) -> dict[str, float]:
    return {o: final(rs) for o in FIG2B_OPTIMIZERS if (rs := d.runs("best", optimizer__name=o))}


def tuned_adam(d: FigureData) -> tuple[float, str]:
    """(final loss, label) of the best re-tuned Adam run of fig2b (median over seeds per setting)."""
    settings = [(lr, b) for lr in d.values("adam_tuned", "optimizer.lr") for b in d.values("adam_tuned", "batch_size")]
    found = [
        (final(rs), f"η={num(lr)} b={b}") for lr, b in settings if (rs := d.runs("adam_tuned", optimizer__lr=lr, batch_size=b))
    ]
    return min(found, key=lambda x: x[0], default=(float("inf"), "not run"))


def gn_search_summary(d: FigureData, sweep: str) -> str:
    """Share of the searched seeds whose GN run diverged (NaN) or ended above its initial loss."""
    if not (runs := d.runs(sweep)):
        return "not run"
    n, diverged = len(runs), sum(r.status == "diverged" for r in runs)
    rose = sum(r.status == "completed" and not (r.final_loss < r.initial_loss) for r in runs)
    return (
        f"{n} seeds x {budget_of(runs[0])}: {diverged}/{n} diverged ({diverged / n:.0%}), {rose} ended above "
        f"their initial loss, {n - diverged - rose} stable"
    )


@claim(
    "osc-1",
    "fig2b",
    "Adam ~1e-4",
    min_seconds=OSC_ADAM_HOUR,
    cause=Cause(
        "budget",
        "Adam {adam:e} after {budget:g} s, still falling ({adam_half:e} half-way); the paper's level is its hour of "
        "updates at {paper_osc_adam_update_s:g} s each",
        {"Adam above the paper's level": lambda v: v["adam"] > 1e-3, "Adam still falling": below("adam", "adam_half")},
    ),
)
def adam_best(datas):
    """Oscillators: Adam is the best of the gradient-descent family, final loss ~1e-4. Rule: Adam best of
    SGD/Adagrad/Adadelta/RMSprop/Adam and final loss in [1e-5, 1e-3] (partly: one of the two)"""
    gd = {o: v for o, v in _finals(datas["fig2b"]).items() if o in GD_FAMILY}
    require("adam" in gd, what="fig2b Adam")
    best = min(gd, key=gd.get)
    level = 1e-5 <= gd["adam"] <= 1e-3
    half = half_way(datas["fig2b"].runs("best", optimizer__name="adam"))
    return (
        f"Adam {sci(gd['adam'])}; best of the GD family: {OPTIMIZER_NAMES[best]} ({sci(gd[best])})",
        best == "adam" and level,
        best == "adam" or level,
        {"adam": gd["adam"], "adam_half": half},
    )


@claim(
    "osc-2",
    "fig2b",
    "GN ~1e-6",
    min_seconds=OSC_HIG_HOUR,
    cause=Cause(
        "budget",
        "GN {gn:e} after {gn_updates} updates, fewer than the paper's hour ({osc_hig_hour_updates})",
        {"GN above the paper's level": lambda v: v["gn"] > 1e-5, "fewer updates": below("gn_updates", "osc_hig_hour_updates")},
    ),
)
def gn_level(datas):
    """Oscillators: GN's best stable run reaches ~1e-6. Rule: GN's best stable run (best seed of the search) ends in
    [1e-7, 1e-5] without diverging (partly: below Adam's)"""
    f, runs = _finals(datas["fig2b"]), datas["fig2b"].runs("best", optimizer__name="gn")
    require("gn" in f and "adam" in f, what="fig2b GN/Adam")
    search = gn_search_summary(datas["fig2b"], "best/search")
    measured = f"GN {sci(f['gn'])} ({runs[0].status}, seed {runs[0].seed}); Adam {sci(f['adam'])}; seed search: {search}"
    values = {"gn": f["gn"], "gn_updates": updates_of(runs[0])}
    return measured, 1e-7 <= f["gn"] <= 1e-5 and runs[0].status == "completed", f["gn"] < f["adam"], values


def authors_probe(table) -> dict:
    """The authors' oscillator probe (scripts/probe_oscillator_authors.py): their code's and ours' test loss after
    their run's updates, and ours after the paper's hour of updates, per variant."""
    rows = table.set_index("variant")
    first, hour = 1024, 24_576
    out = {"first_updates": first, "hour_updates": hour, "authors_first": rows.loc["authors' TF code", f"test_at_{first}"]}
    for name, variant in (("same", "float64 inversion"), ("reshuffled", "reshuffled"), ("ours", "ours")):
        out[f"{name}_first"] = rows.loc[variant, f"test_at_{first}"]
        out[f"{name}_hour"], out[f"{name}_hour_train"] = (
            rows.loc[variant, f"test_at_{hour}"],
            rows.loc[variant, f"train_at_{hour}"],
        )
    return {k: float(v) if not isinstance(v, int) else v for k, v in out.items()}


@claim(
    "osc-3",
    "fig2b",
    "HIG ~1e-7",
    min_seconds=OSC_HIG_HOUR,
    min_seeds=3,
    cause=Cause(
        "unspecified",
        "the data draw, which the paper does not give: per update our HIG follows the authors' code from their data and "
        "initial weights (after {probe_first_updates} updates {probe_same_first:e} against their {probe_authors_first:e}) "
        "and reaches {probe_same_hour:e} after the paper's hour of updates ({probe_hour_updates}), reshuffled "
        "{probe_reshuffled_hour:e}; from our data draw and initialisation {probe_ours_hour:e}, at a training loss alike "
        "({probe_ours_hour_train:e} against {probe_same_hour_train:e}): our test set is fitted worse (authors' probe); "
        "here HIG {hig:e} after {hig_updates} updates",
        {
            "ours follows the authors' code per update": lambda v: 0.5 < v["probe_same_first"] / v["probe_authors_first"] < 2,
            "the authors' draw near the paper's level": lambda v: v["probe_same_hour"] < 3e-7,
            "our draw far above it": lambda v: v["probe_ours_hour"] >= 3 * v["probe_same_hour"],
            "training losses alike": lambda v: v["probe_ours_hour_train"] < 2 * v["probe_same_hour_train"],
            "HIG here above the authors' draw's level": lambda v: v["hig"] > v["probe_same_hour"],
        },
        probe=probe_values("oscillator_authors_summary.csv", authors_probe),
    ),
)
def hig_best(datas):
    """Oscillators: HIG gives the best result, ~1e-7. Rule: HIG's final loss in [1e-8, 1e-6] and the lowest of the seven
    and of re-tuned Adam (partly: one of the two)"""
    d, f = datas["fig2b"], _finals(datas["fig2b"])
    require("hig" in f, what="fig2b HIG")
    ft, tlabel = tuned_adam(d)
    if ft < float("inf"):
        f["adam (re-tuned)"] = ft
    best = min(f, key=f.get)
    level = 1e-8 <= f["hig"] <= 1e-6
    adv = f"HIG's advantage: {f['adam'] / f['hig']:.1f}x over Adam (paper setting)" if "adam" in f else ""
    if ft < float("inf"):
        adv += f", {ft / f['hig']:.1f}x over re-tuned Adam ({tlabel}: {sci(ft)})"
    hig = d.runs("best", optimizer__name="hig")
    values = {"hig": f["hig"], "hig_half": half_way(hig), "hig_updates": min(map(updates_of, hig))}
    return (
        f"HIG {sci(f['hig'])}; lowest of all: {OPTIMIZER_NAMES.get(best, best)} ({sci(f[best])}); {adv}",
        level and best == "hig",
        level or best == "hig",
        values,
    )


@claim(
    "osc-4",
    "fig2b",
    "~180 s",
    min_seconds=180,  # past the paper's ~3 minutes
    min_seeds=3,
    cause=Cause(
        "hardware",
        "HIG stays below Adam from t = {t_cross:.0f} s, before the paper's window: a crossing time is the implementation's "
        "and the machine's; the paper's clock includes its set-up, and on this machine kind the authors' code spends its "
        "first {ref_hig_trace_s:.0f} s tracing its graph, before its first HIG update (reference.py)",
        {
            "the crossing before the paper's window": lambda v: v["t_cross"] < 60,
            "the crossing before the authors' code's first HIG update": below("t_cross", "ref_hig_trace_s"),
        },
    ),
)
def crossing(datas):
    """Oscillators: HIG passes Adam after about three minutes. Rule: HIG stays below Adam from a time in [60, 540] s on
    (partly: from any time on)"""
    d = datas["fig2b"]
    hig, adam, tuned = d.runs("best", optimizer__name="hig"), d.runs("best", optimizer__name="adam"), d.runs("adam_tuned")
    require(hig, adam, what="fig2b HIG/Adam")
    t_tuned = [crossing_time(hig[0], r) for r in tuned]
    late = max((x for x in t_tuned if x is not None), default=None)
    never = sum(x is None for x in t_tuned)
    parts = ([f"never passes {never} of them"] if never else []) + (
        [f"passes {'the others' if never else 'all'} by t = {late:.0f} s"] if late is not None else []
    )
    tuned_text = f"; against re-tuned Adam ({len(tuned)} settings): HIG " + ", ".join(parts) if tuned else ""
    if (t := crossing_time(hig[0], adam[0])) is None:
        return "HIG does not pass Adam within the budget" + tuned_text, False, False
    return f"HIG below Adam (paper setting) from t = {t:.0f} s on" + tuned_text, 60 <= t <= 540, True, {"t_cross": t}


@claim(
    "osc-5",
    "fig2c",
    "Adam ~b-independent; HIG/GN better at larger b",
    min_seconds=120,
    cause=Cause(
        "hardware",
        "at equal time a smaller batch buys more updates on this CPU (HIG: {hig_lo_updates} updates at b={b_lo}, "
        "{hig_hi_updates} at b={b_hi}), so HIG b={b_lo}->{b_hi} ends {hig_lo:e}->{hig_hi:e} and GN {gn_lo:e}->{gn_hi:e}; "
        "at equal update counts ({n_eq} updates) HIG follows the paper, {hig_lo_eq:e}->{hig_hi_eq:e}, and GN does not, "
        "{gn_lo_eq:e}->{gn_hi_eq:e} (each b's GN run is the best stable seed of its own search)",
        {
            "a smaller b lower at equal time": lambda v: v["hig_lo"] < v["hig_hi"] or v["gn_lo"] < v["gn_hi"],
            "more updates at the smaller b": below("hig_hi_updates", "hig_lo_updates"),
            "HIG's larger b lower per update": below("hig_hi_eq", "hig_lo_eq"),
            "GN's larger b not lower per update": lambda v: v["gn_hi_eq"] >= v["gn_lo_eq"],
        },
    ),
)
def batch_sizes(datas):
    """Oscillators: Adam's runs converge alike for all b; HIG and GN improve with larger b. Rule: Adam's final losses
    within 3x over b, and HIG and GN lower at the largest b than at the smallest (partly: one of these)"""
    d = datas["fig2c"]
    fin = {(o, b): final(rs) for o, bs in FIG2C_BATCHES.items() for b in bs if (rs := d.runs(o, batch_size=b))}
    adam = [fin[("adam", b)] for b in FIG2C_BATCHES["adam"] if ("adam", b) in fin]
    require(len(adam) >= 2 and any(k[0] == "hig" for k in fin), what="fig2c")
    spread = max(adam) / min(adam)
    ends = {o: (bs[0], bs[-1]) for o in ("hig", "gn") if len(bs := [b for b in FIG2C_BATCHES[o] if (o, b) in fin]) >= 2}
    improves = {o: fin[(o, hi)] < fin[(o, lo)] for o, (lo, hi) in ends.items()}
    measured = f"Adam max/min over b: {spread:.1f}x; " + ", ".join(
        f"{OPTIMIZER_NAMES[o]} b={lo}->{hi}: {sci(fin[(o, lo)])}->{sci(fin[(o, hi)])}" for o, (lo, hi) in ends.items()
    )
    full = spread < 3 and all(improves.values()) and len(improves) == 2
    return measured, full, spread < 3 or any(improves.values()), _per_update(d, ends, fin)


def _per_update(d: FigureData, ends: dict, fin: dict) -> dict:
    """HIG's and GN's final losses at the smallest and largest b, and at an equal update count."""
    if set(ends) != {"hig", "gn"} or ends["hig"] != ends["gn"]:
        return {}
    (lo, hi), values = ends["hig"], {"b_lo": ends["hig"][0], "b_hi": ends["hig"][1]}
    runs = {(o, b): d.runs(o, batch_size=b) for o in ("hig", "gn") for b in (lo, hi)}
    n_eq = min(updates_of(rs[0]) for rs in runs.values())
    for (o, b), rs in runs.items():
        side = "lo" if b == lo else "hi"
        values[f"{o}_{side}"], values[f"{o}_{side}_eq"] = fin[(o, b)], median(at_update(r, n_eq) for r in rs)
        values[f"{o}_{side}_updates"] = min(map(updates_of, rs))
    return values | {"n_eq": n_eq}


@claim(
    "osc-6",
    "fig5 fig6",
    "GD family alike over b, unstable at large η",
    min_seconds=12,  # divergence shows early
    cause=Cause(
        "budget",
        "over b the five behave alike (best-η spreads {spread_min:.1f}x-{spread_max:.1f}x); at the largest η "
        "{diverged} of {cells} optimizer-b runs diverge, and {calm_falling} of the {calm} that neither diverge nor "
        "oscillate most are still falling over the second half of their {budget:g} s, where the paper's grids ran an hour",
        {
            "alike over b": lambda v: v["spread_max"] <= 10,
            "the calm largest-η runs still falling": lambda v: v["calm"] > 0 and v["calm_falling"] == v["calm"],
        },
    ),
)
def gd_family(datas):
    """Oscillators (figs 5-6): the gradient-descent family behaves alike over batch sizes and becomes unstable at large
    η. Rule: at every b each optimizer's largest-η run diverges or oscillates most over its last half (of its η), and
    at its best η the final losses over b lie within 10x (partly: one of the two)"""
    unstable, spreads, calm_falling, text = [], [], [], []
    for fid, opts in (("fig5", FIG5_LRS), ("fig6", {"adam": FIG6_LRS})):
        for opt in opts:
            require(runs := datas[fid].runs(opt), what=f"{fid} {opt}")
            bs = sorted({r.cfg("batch_size") for r in runs})
            shaky = [_largest_lr_unstable([r for r in runs if r.cfg("batch_size") == b]) for b in bs]
            unstable += shaky
            largest = max(r.cfg("optimizer.lr") for r in runs)
            calm_falling += [final([r]) < half_way([r]) for r, u in _at_largest(runs, largest, bs, shaky) if not u]
            fin = {(r.cfg("optimizer.lr"), r.cfg("batch_size")): final([r]) for r in runs}
            best_lr = min({k[0] for k in fin}, key=lambda lr: median(fin.get((lr, b), math.inf) for b in bs))
            at = [fin[(best_lr, b)] for b in bs if (best_lr, b) in fin]
            spreads.append(max(at) / min(at) if at and min(at) > 0 else math.inf)
            text.append(
                f"{OPTIMIZER_NAMES[opt]}: largest η unstable at {sum(map(bool, shaky))}/{len(bs)} b, spread over b at "
                f"η={num(best_lr)} {spreads[-1]:.1f}x"
            )
    diverged = sum(u == "diverged" for u in unstable)
    values = {"cells": len(unstable), "diverged": diverged, "calm": sum(not u for u in unstable)}
    values["calm_falling"] = sum(calm_falling)
    values |= {"spread_min": min(spreads), "spread_max": max(spreads)}
    alike = all(s <= 10 for s in spreads)
    return "; ".join(text), all(unstable) and alike, all(unstable) or alike, values


def _at_largest(runs: list, lr: float, bs: list, shaky: list) -> list:
    """(the largest-η run at b, its instability) for each b."""
    at = {r.cfg("batch_size"): r for r in runs if r.cfg("optimizer.lr") == lr}
    return [(at[b], u) for b, u in zip(bs, shaky) if b in at]


def _largest_lr_unstable(runs: list) -> str:
    """ "diverged", "oscillates" (most of the η at this b over the last half) or "" (neither)."""
    runs = sorted(runs, key=lambda r: r.cfg("optimizer.lr"))
    if runs[-1].status == "diverged" or not math.isfinite(final(runs[-1:])):
        return "diverged"
    wobble = [oscillation(r) for r in runs]
    return "oscillates" if wobble[-1] >= np.nanmax(wobble) else ""  # NaN (too few evaluations): not shown
