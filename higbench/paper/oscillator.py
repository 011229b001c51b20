"""Figures 2a-c, 5, 6 and ref_oscillator, and their claims (osc-*): control of two coupled
nonlinear oscillators (paper 3.1, appendix B.2).

fig2b's runs use the per-pair paper defaults (conf/problem_optimizer/oscillator_*.yaml, the
hyper-parameters of table 2); the grids of figures 5 and 6 are conf/experiment/fig5_*.yaml
and fig6_adam.yaml.
"""

from __future__ import annotations

import math

import numpy as np

from higbench.bench.paper import PAPER_COSTS
from higbench.claims.reference import OSCILLATOR_CURVES
from higbench.claims.rules import (
    OSC_ADAM_RUN,
    OSC_HIG_RUN,
    PAPER,
    Cause,
    at_update,
    below,
    budget_of,
    claim,
    crossing_time,
    falling,
    final,
    half_way,
    last_half_trend,
    median,
    oscillation,
    probe_values,
    require,
    updates_of,
)
from higbench.display import COLORS, OPTIMIZER_NAMES, num, sci
from higbench.figures.data import FigureData
from higbench.figures.plot import Curves, Custom, Facets, Series, legend
from higbench.figures.report import reference_entry
from higbench.figures.spec import Budget, Figure, PerPreset, SeedSearch, Sweep, paper_grid

FIG2B_OPTIMIZERS = ("adadelta", "adagrad", "adam", "gn", "hig", "rmsprop", "sgd")
GD_FAMILY = ("adadelta", "adagrad", "adam", "rmsprop", "sgd")
FIG2C_BATCHES = {"adam": [256, 512, 1024], "gn": [32, 64, 128], "hig": [32, 64, 128]}
GD_GRIDS = {"fig5": ("adadelta", "adagrad", "sgd", "rmsprop"), "fig6": ("adam",)}  # figure -> its optimizers' grids
MAIN = Budget(seconds={"paper": 3600, "quick": 120, "standard": 240, "long": 900})
GRID = Budget(seconds={"paper": 3600, "quick": 12, "standard": 15, "long": 120})  # long: osc-6 past its 15 s
FIG5_LRS = {opt: paper_grid(f"fig5_{opt}", "optimizer.lr") for opt in GD_GRIDS["fig5"]}
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
            # long: b=512 too, the paper's best Adam setting (eta=3e-4, b=512)
            "batch_size": PerPreset(GRID_BATCHES, [256, 1024], [512], long=GRID_BATCHES),
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
    # below the axes: the states fill the whole panel (inside, the legend hid x2's first peak)
    legend(ax, **({"loc": "upper center", "bbox_to_anchor": (0.5, -0.17), "ncol": 3} if found else {}))
    ax.set(xlabel="time t", ylabel="oscillator position")


def reference(d: FigureData, ax) -> None:
    """The authors' points on the axes; their loss points and update times beside ours in the sidecar."""
    for opt, ref in OSCILLATOR_CURVES.items():
        t, y = zip(*ref["points"])
        ax.plot(t, y, "o--", color=COLORS[opt], mfc="none", label=f"authors' TF code {OPTIMIZER_NAMES[opt]} ({ref['note']})")
        d.record("loss", f"reference {opt}", None, "wall_time", t, "test_loss", y)
    d.sidecar["reference"] = reference_entry(d.runs)


def _ref_panel() -> Curves:
    title = "oscillators: higbench beside the authors' TensorFlow code (same settings, 2 CPU cores)"
    return Curves(title, [Series(o, label="higbench {label}") for o in OSCILLATOR_CURVES], extra=reference)


# fig. 2c: each optimizer's batch sizes in shades of its colour (light: the smallest b), and by line style.
SHADES = {
    "adam": ("#9ecae1", "#4292c6", "#08306b"),
    "gn": ("#fc9272", "#ef3b2c", "#99000d"),
    "hig": ("#a1d99b", "#41ab5d", "#00441b"),
}


FIGURES = [
    Figure(
        "fig2a",
        "Oscillators: time evolution under a HIG-trained network, control signal behind it",
        [osc("hig", "hig")],
        panels=[Custom(fig2a)],
        size=(1, 6.5, 3.6),
    ),
    Figure(
        "fig2b",
        "Oscillators: loss over wall-clock time, best run of each optimizer",
        FIG2B,
        redrawable=True,
        panels=[Curves("b) oscillators: best run per optimizer (table 2 settings)", [Series("best", "optimizer.name")], ncol=2)],
    ),
    Figure(
        "fig2c",
        "Oscillators: Adam, GN and HIG for several batch sizes",
        [osc(o, o, grid={"batch_size": PerPreset(bs, bs[::2] if o == "gn" else bs, bs[:2])}) for o, bs in FIG2C_BATCHES.items()],
        redrawable=True,
        panels=[
            Curves(
                "c) oscillators: Adam, GN, HIG for several batch sizes b",
                [Series(o, "batch_size", color=list(SHADES[o]), ls=["-", "--", ":"]) for o in FIG2C_BATCHES],
                ncol=3,
            )
        ],
    ),
    Figure(
        "fig5",
        "Oscillators: Adadelta, Adagrad, SGD, RMSprop for several learning rates and batch sizes",
        [_grid(o, lrs) for o, lrs in FIG5_LRS.items()],
        redrawable=True,
        panels=[Facets(list(FIG5_LRS), "optimizer.lr", "batch_size", rows="sweep", size=(3.6, 2.7))],
    ),
    Figure(
        "fig6",
        "Oscillators: Adam for several learning rates and batch sizes",
        [_grid("adam", FIG6_LRS)],
        redrawable=True,
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


# -- the claims on figures 2b, 2c, 5 and 6 ---------------------------------------------------
# fig2b: sweeps "best" (table 2's settings) and "adam_tuned"; fig2c, 5, 6: one sweep per
# optimizer; GN's runs use the best stable seed of a search ("<sweep>/search").


def _finals(d) -> dict[str, float]:
    return {o: final(rs) for o in FIG2B_OPTIMIZERS if (rs := d.runs("best", optimizer__name=o))}


def tuned_adam(d) -> tuple[float, str]:
    """(final loss, label) of the best re-tuned Adam run of fig2b (median over seeds per setting)."""
    settings = [(lr, b) for lr in d.values("adam_tuned", "optimizer.lr") for b in d.values("adam_tuned", "batch_size")]
    found = [
        (final(rs), f"η={num(lr)} b={b}") for lr, b in settings if (rs := d.runs("adam_tuned", optimizer__lr=lr, batch_size=b))
    ]
    return min(found, key=lambda x: x[0], default=(float("inf"), "not run"))


def gn_search_summary(d, sweep: str) -> str:
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
    min_seconds=OSC_ADAM_RUN,
    cause=Cause(
        "budget",
        "Adam {adam:e} after {budget:g} s, still falling ({adam_half:e} half-way); the paper's level is the end of its "
        "documented run of updates at {paper_osc_adam_update_s:g} s each",
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
    min_seconds=OSC_HIG_RUN,
    cause=Cause(
        "budget",
        "GN {gn:e} after {gn_updates} updates, fewer than the paper's GPU makes in the oscillators' documented run "
        "({osc_hig_run_updates})",
        {"GN above the paper's level": lambda v: v["gn"] > 1e-5, "fewer updates": below("gn_updates", "osc_hig_run_updates")},
    ),
    reads=("fig2b:best optimizer=gn",),  # GN's searched seed: settled (its "partly" compares with Adam)
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


def draws_probe(table) -> dict:
    """The oscillator draws probe (scripts/probe_oscillator_draws.py): HIG and GN at table 2's settings
    over (data draw, seed) pairs, each for the updates of the authors' documented hour on the paper's GPU at
    its b. HIG at b=128 (osc-3): the range over pairs of the paper's metric (the mean over the 4,096 test
    samples), of the per-sample median, of the mean over 32,768 fresh samples, and the share of the mean
    the worst samples carry. Per optimizer and b (osc-5): the median over pairs of the mean test
    loss, and how many pairs diverged."""
    done = table[table["status"] == "completed"]
    head = done[(done["optimizer"] == "hig") & (done["batch_size"] == 128)]
    out = {
        "pairs": int(len(head)),
        "draws": int(head["data_seed"].nunique()),
        "seeds": int(head["seed"].nunique()),
        "updates": int(head["updates"].min()),
        "samples": int(head["samples"].min()),
        "fresh_samples": int(head["fresh_samples"].min()),
        "worst": WORST_SAMPLES,
        "mean_min": float(head["mean"].min()),
        "mean_max": float(head["mean"].max()),
        "mean_median": float(head["mean"].median()),
        "gap": float(head["mean"].median()) / PAPER["paper_osc_hig_level"],
        "median_min": float(head["median"].min()),
        "median_max": float(head["median"].max()),
        "fresh_min": float(head["fresh_mean"].min()),
        "fresh_max": float(head["fresh_mean"].max()),
        "decades": float(np.log10(head["mean"] / head["median"]).min()),
        "share_min": round(100 * float(head["worst_share"].min())),
        "share_max": round(100 * float(head["worst_share"].max())),
        "level": LEVEL,
    }
    sizes = sorted(table["batch_size"].unique())
    size_names = dict(zip(sizes, ("small", "mid", "large") if len(sizes) == 3 else ("small", "large")))
    # Per b, the pairs every setting ran (HIG at b=128 has more, for osc-3): medians over the same draws and seeds.
    common = set.intersection(*(set(zip(r["data_seed"], r["seed"])) for _, r in table.groupby(["optimizer", "batch_size"])))
    shared = table[[pair in common for pair in zip(table["data_seed"], table["seed"])]]
    for (opt, b), rows in shared.groupby(["optimizer", "batch_size"]):
        finished, key = rows[rows["status"] == "completed"], f"{opt}_{size_names[b]}"
        out[f"b_{size_names[b]}"] = int(b)
        out[f"{key}_pairs"] = int(len(rows))
        out[f"{key}_diverged"] = int((rows["status"] == "diverged").sum())
        out[key] = float(finished["mean"].median()) if len(finished) else math.inf
        out[f"{key}_fresh"] = float(finished["fresh_mean"].median()) if len(finished) else math.inf
    return out


WORST_SAMPLES = 10  # scripts/probe_oscillator_draws.py's WORST


@claim(
    "osc-3",
    "fig2b",
    "HIG ~1e-7",
    min_seconds=OSC_HIG_RUN,
    cause=Cause(
        "disagreement",
        "the level: here HIG ends at {hig:e} after {hig_updates} updates (one seed); over {probe_pairs} (data draw, seed) "
        "pairs ({probe_draws} draws, {probe_seeds} seeds; the draws probe) after the {probe_updates} updates the paper's "
        "GPU makes in the oscillators' documented run, the paper's metric (the mean over {probe_samples} test samples) "
        "has a median of {probe_mean_median:e} and spans {probe_mean_min:e} to {probe_mean_max:e}: more seeds reproduce "
        "this level, about {probe_gap:.0f}x the paper's {paper_osc_hig_level:e}, not the paper's, a systematic gap rather "
        "than a seed's; the mean over {probe_fresh_samples} fresh samples lies higher still ({probe_fresh_min:e} to "
        "{probe_fresh_max:e}). Its cause is the draw and initialisation: in the committed authors' probe our HIG follows "
        "the authors' code per update ({probe_same_first:e} against their {probe_authors_first:e} after "
        "{probe_first_updates} updates) and, from the authors' data draw and initial weights, ends at {probe_same_hour:e} "
        "after {probe_hour_updates} updates ({probe_reshuffled_hour:e} with the batches reshuffled), against "
        "{probe_ours_hour:e} from ours at training losses alike ({probe_ours_hour_train:e} against "
        "{probe_same_hour_train:e}): the paper's level is that of the authors' draw, below every draw of ours",
        {
            "more seeds reproduce the gap": lambda v: v["probe_gap"] >= 3 and v["probe_pairs"] >= 3,
            "HIG here within the spread of draws and seeds": lambda v: v["probe_mean_min"] <= v["hig"] <= v["probe_mean_max"],
            "ours follows the authors' code per update": lambda v: 0.5 < v["probe_same_first"] / v["probe_authors_first"] < 2,
            "the authors' draw below every draw of ours": lambda v: v["probe_same_hour"] < v["probe_mean_min"],
            "training losses alike": lambda v: v["probe_ours_hour_train"] < 2 * v["probe_same_hour_train"],
        },
        probe=lambda: {
            **probe_values("oscillator_authors_summary.csv", authors_probe)(),
            **probe_values("oscillator_draws.csv", draws_probe)(),
        },
    ),
)
def osc_hig_best(datas):
    """Oscillators: HIG gives the best result, ~1e-7. Rule: HIG's final loss in [1e-8, 1e-6], and the lowest of the seven
    and of re-tuned Adam compared like with like: each optimizer's run at a fixed seed, as HIG's; GN's seed-searched run
    (the best of its search) stands in for GN only where its typical seed does not diverge, since most searched seeds
    diverging makes GN's typical run a diverged one (partly: one of the two)"""
    d, f = datas["fig2b"], _finals(datas["fig2b"])
    require("hig" in f, what="fig2b HIG")
    search = d.runs("best/search")
    gn_typical_diverges = bool(search) and 2 * sum(r.status == "diverged" for r in search) > len(search)
    if gn_typical_diverges:
        f["gn"] = math.inf  # the typical GN run: diverged (its searched seed is the best of the search, not typical)
    ft, tlabel = tuned_adam(d)
    if ft < float("inf"):
        f["adam (re-tuned)"] = ft
    best = min(f, key=f.get)
    level = 1e-8 <= f["hig"] <= 1e-6
    adv = f"HIG's advantage: {f['adam'] / f['hig']:.1f}x over Adam (paper setting)" if "adam" in f else ""
    if ft < float("inf"):
        adv += f", {ft / f['hig']:.1f}x over re-tuned Adam ({tlabel}: {sci(ft)})"
    elif d.runs("adam_tuned"):
        adv += "; re-tuned Adam: no curve in the data read (the committed plotted data keep fig. 2b's best runs)"
    diverged = sum(r.status == "diverged" for r in search)
    gn_text = f"; GN's typical run diverges ({diverged} of {len(search)} searched seeds)" if gn_typical_diverges else ""
    hig = d.runs("best", optimizer__name="hig")
    values = {"hig": f["hig"], "hig_half": half_way(hig), "hig_updates": min(map(updates_of, hig))}
    values |= {"lowest": f[best], "lowest_name": OPTIMIZER_NAMES.get(best, best), "gn_typical_diverges": gn_typical_diverges}
    return (
        f"HIG {sci(f['hig'])}; lowest at a fixed seed: {OPTIMIZER_NAMES.get(best, best)} ({sci(f[best])}){gn_text}; {adv}",
        level and best == "hig",
        level or best == "hig",
        values,
    )


@claim(
    "osc-4",
    "fig2b",
    "~180 s",
    min_seconds=180,  # past the paper's ~3 minutes
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
    "osc-7",
    "fig2b",
    "~180 s",
    min_seconds=180,
    cause=Cause(
        "hardware",
        "GN stays below Adam from t = {t_cross:.0f} s, before the paper's window: a crossing time is the implementation's "
        "and the machine's (osc-4)",
        {"the crossing before the paper's window": lambda v: v["t_cross"] < 60},
    ),
)
def gn_crossing(datas):
    """Oscillators (§3.1): GN also passes Adam after about three minutes. Rule: GN (its best stable seed) stays below
    Adam from a time in [60, 540] s on (partly: from any time on)"""
    d = datas["fig2b"]
    gn, adam = d.runs("best", optimizer__name="gn"), d.runs("best", optimizer__name="adam")
    require(gn, adam, what="fig2b GN/Adam")
    if (t := crossing_time(gn[0], adam[0])) is None:
        return "GN does not pass Adam within the budget", False, False
    return f"GN below Adam (paper setting) from t = {t:.0f} s on", 60 <= t <= 540, True, {"t_cross": t}


# osc-5: the paper compares batch sizes at equal time on its GPU, where an update's cost grows less with b than here.
LEVEL = 2.0  # a ratio of final losses within this is a level one seed and test draw can move (osc-3's authors' probe)


def paper_cost_ratio(b_lo: int, b_hi: int) -> float:
    """How many more updates the paper's GPU makes at b_lo than at b_hi in the same time (table 3's HIG)."""
    return PAPER_COSTS[("oscillator", "hig", b_hi)][1] / PAPER_COSTS[("oscillator", "hig", b_lo)][1]


@claim(
    "osc-5",
    "fig2c",
    "Adam ~b-independent; HIG/GN better at larger b",
    min_seconds=120,
    cause=Cause(
        "hardware",
        "the cost ratio between batch sizes: in the same training time HIG made {hig_lo_updates} updates at b={b_lo} and "
        "{hig_hi_updates} at b={b_hi} here, where the paper's GPU makes {paper_ratio:.2f} times as many at b={b_lo} (its "
        "update times); read at the paper's ratio, the same runs show the paper's ordering: HIG {hig_lo_paper:e} at "
        "b={b_lo} against {hig_hi:e} at b={b_hi}, GN {gn_lo_paper:e} against {gn_hi:e}. Over {probe_hig_large_pairs} "
        "(data draw, seed) pairs at the paper's update counts (the draws probe) HIG's mean test loss falls with b "
        "({probe_hig_small:e}, {probe_hig_mid:e}, {probe_hig_large:e} at b={probe_b_small}, {probe_b_mid}, "
        "{probe_b_large}), but on {probe_fresh_samples} fresh samples the ordering shrinks to {probe_hig_small_fresh:e} "
        "against {probe_hig_large_fresh:e}, within the factor {probe_level:g} a draw moves; GN diverged in "
        "{probe_gn_large_diverged} of {probe_gn_large_pairs} pairs at b={probe_b_large}, so its levels are the searched "
        "seed's",
        {
            "this CPU's update ratio far from the paper's": lambda v: (
                v["hig_lo_updates"] / v["hig_hi_updates"] > 2 * v["paper_ratio"]
            ),
            "the paper's ordering at the paper's ratio": lambda v: (
                v["hig_lo_paper"] > v["hig_hi"] and v["gn_lo_paper"] > v["gn_hi"]
            ),
            "the fresh-sample ordering within a draw's factor": lambda v: (
                v["probe_hig_small_fresh"] / v["probe_hig_large_fresh"] < LEVEL
            ),
        },
        probe=probe_values("oscillator_draws.csv", draws_probe),
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


def _per_update(d, ends: dict, fin: dict) -> dict:
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
    ratio = paper_cost_ratio(lo, hi)
    for o in ("hig", "gn"):  # the smaller b after the updates the paper's GPU makes there while the larger b runs
        values[f"{o}_lo_paper"] = median(at_update(r, ratio * values[f"{o}_hi_updates"]) for r in runs[(o, lo)])
    return values | {"n_eq": n_eq, "paper_ratio": ratio}


GD_ALIKE = "over b the five behave alike (best-η spreads {spread_min:.1f}x-{spread_max:.1f}x); at the largest η "
GD_ALIKE_FACT = {"alike over b": lambda v: v["spread_max"] <= 10}


@claim(
    "osc-6",
    "fig5 fig6",
    "GD family alike over b, unstable at large η",
    min_seconds=12,  # divergence shows early
    cause=Cause(
        "budget",
        GD_ALIKE + "{diverged} of {cells} optimizer-b runs diverge, and {calm_falling} of the {calm} that neither "
        "diverge nor oscillate most are still falling over the second half of their {budget:g} s (a fitted fall beyond "
        "twice its noise), where the authors' oscillator scripts run an hour",
        GD_ALIKE_FACT | {"the calm largest-η runs still falling": lambda v: v["calm"] > 0 and v["calm_falling"] == v["calm"]},
        otherwise=Cause(
            "disagreement",
            GD_ALIKE + "{diverged} of {cells} optimizer-b runs diverge, but {calm_run} neither diverges nor oscillates "
            "most, and not for want of time: over the second half of its {budget:g} s it has stopped falling "
            "({calm_change:+.2f} decades, noise {calm_noise:.2f}) on a plateau {calm_above:.1f}x above the next-smaller "
            "η's final, while η={wobble_most_lr} oscillates more ({wobble_most:.3f} against {calm_wobble:.3f} decades "
            "per evaluation). The rule counts divergence or the largest oscillation as unstable; this run stagnates",
            GD_ALIKE_FACT
            | {
                "the calm run stopped falling": lambda v: not falling(v["calm_change"], v["calm_noise"]),
                "its plateau above the next-smaller η": lambda v: v["calm_above"] > 1,
                "another η oscillating more": lambda v: v["wobble_most"] > v["calm_wobble"],
            },
        ),
    ),
)
def gd_family(datas):
    """Oscillators (figs 5-6): the gradient-descent family behaves alike over batch sizes and becomes unstable at large
    η. Rule: at every b each optimizer's largest-η run diverges or oscillates most over its last half (of its η), and
    at its best η the final losses over b lie within 10x (partly: one of the two)"""
    unstable, spreads, calm, text = [], [], [], []
    for fid, opts in GD_GRIDS.items():
        for opt in opts:
            require(runs := datas[fid].runs(opt), what=f"{fid} {opt}")
            bs = sorted({r.cfg("batch_size") for r in runs})
            at_b = {b: sorted((r for r in runs if r.cfg("batch_size") == b), key=lambda r: r.cfg("optimizer.lr")) for b in bs}
            shaky = [_largest_lr_unstable(at_b[b]) for b in bs]
            unstable += shaky
            calm += [_calm(at_b[b], f"{OPTIMIZER_NAMES[opt]} at b={b}") for b, u in zip(bs, shaky) if not u]
            fin = {(r.cfg("optimizer.lr"), r.cfg("batch_size")): final([r]) for r in runs}
            best_lr = min({k[0] for k in fin}, key=lambda lr: median(fin.get((lr, b), math.inf) for b in bs))
            at = [fin[(best_lr, b)] for b in bs if (best_lr, b) in fin]
            spreads.append(max(at) / min(at) if at and min(at) > 0 else math.inf)
            text.append(
                f"{OPTIMIZER_NAMES[opt]}: largest η unstable at {sum(map(bool, shaky))}/{len(bs)} b, spread over b at "
                f"η={num(best_lr)} {spreads[-1]:.1f}x"
            )
    diverged = sum(u == "diverged" for u in unstable)
    values = {"cells": len(unstable), "diverged": diverged, "calm": len(calm)}
    values["calm_falling"] = sum(falling(c["calm_change"], c["calm_noise"]) for c in calm)
    values |= {"spread_min": min(spreads), "spread_max": max(spreads)}
    values |= max(calm, key=lambda c: c["calm_change"] + 2 * c["calm_noise"], default={})  # the least falling
    alike = all(s <= 10 for s in spreads)
    return "; ".join(text), all(unstable) and alike, all(unstable) or alike, values


def _calm(runs: list, label: str) -> dict:
    """What the largest-η run at one b (``runs`` sorted by η) does when it neither diverges nor oscillates most: its
    last half's trend, its level against the next-smaller η's, its oscillation against the most oscillating η's."""
    top, wobble = runs[-1], [oscillation(r) for r in runs]
    change, noise = last_half_trend(top)
    most = int(np.nanargmax(wobble)) if np.isfinite(wobble).any() else -1  # too few evaluations: itself
    return {
        "calm_run": f"{label} η={num(top.cfg('optimizer.lr'))}",
        "calm_change": change,
        "calm_noise": noise,
        "calm_above": final([top]) / final(runs[-2:-1]) if len(runs) > 1 else math.nan,
        "calm_wobble": wobble[-1],
        "wobble_most": wobble[most],
        "wobble_most_lr": num(runs[most].cfg("optimizer.lr")),
    }


def _largest_lr_unstable(runs: list) -> str:
    """ "diverged", "oscillates" (most of the η at this b over the last half) or "" (neither); ``runs`` sorted by η."""
    if runs[-1].status == "diverged" or not math.isfinite(final(runs[-1:])):
        return "diverged"
    return "oscillates" if largest_oscillates_most([oscillation(r) for r in runs]) else ""


def largest_oscillates_most(wobble: list) -> bool:
    """Whether the last (largest-η) oscillation of ``wobble`` is the largest; NaN (too few evaluations) shows none."""
    return bool(np.isfinite(wobble).any() and wobble[-1] >= np.nanmax(wobble))  # a plain bool: values are JSON


@claim(
    "osc-9",
    "fig2b",
    "the GD family stagnates early",
    min_seconds=OSC_ADAM_RUN,
    cause=Cause(
        "budget",
        "the closest of the family to HIG is {closest} at {closest_ratio:.0f}x HIG's final, and {falling} of {family} "
        "are still falling over the second half of their {budget:g} s (a fitted fall beyond twice its noise), where the "
        "paper's run is an hour of its GPU's updates",
        {"all still falling": lambda v: v["falling"] == v["family"], "short of the contrast": lambda v: v["closest_ratio"] < 100},
    ),
)
def gd_family_stagnates(datas):
    """Oscillators (§3.1): the state-of-the-art optimizers (the gradient-descent family) stagnate early, orders of magnitude
    above HIG and GN. Rule: each of SGD, Adagrad, Adadelta, RMSprop and Adam (table 2's settings) ends at least 100x
    above HIG's final loss, the paper's contrast (Adam's 1e-4 against HIG's 1e-7) (partly: at least 10x)"""
    d, f = datas["fig2b"], _finals(datas["fig2b"])
    require("hig" in f and all(o in f for o in GD_FAMILY), what="fig2b HIG and the GD family")
    ratios = {o: f[o] / f["hig"] for o in GD_FAMILY}
    closest = min(ratios, key=ratios.get)
    trends = [last_half_trend(r) for o in GD_FAMILY for r in d.runs("best", optimizer__name=o)]
    measured = "final over HIG's: " + ", ".join(f"{OPTIMIZER_NAMES[o]} {v:.0f}x" for o, v in ratios.items())
    values = {"closest": OPTIMIZER_NAMES[closest], "closest_ratio": ratios[closest], "family": len(GD_FAMILY)}
    values |= {"falling": sum(falling(*t) for t in trends), "margin": ratios[closest] / 100}
    return measured, ratios[closest] >= 100, ratios[closest] >= 10, values


@claim(
    "osc-10",
    "fig2b fig5 fig6",
    "table 2: each the best of its search",
    min_seconds=12,
    cause=Cause(
        "seeds",
        "{misses} of {family} miss: {missed}; the largest miss is {worst_ratio:.2f}x, within the factor {level:g} a data "
        "draw and seed move (osc-5), on one seed per setting",
        {"the misses within a draw's factor": lambda v: v["worst_ratio"] < v["level"], "one seed": lambda v: v["seeds"] < 3},
    ),
)
def table2_best(datas):
    """Oscillators (table 2, appendix B.2): each optimizer's setting in table 2 is the best run of its hyperparameter
    search. Rule: at table 2's batch size, table 2's η ends lowest of figs. 5-6's η grid for each of the five
    gradient-descent optimizers (partly: for most of them)"""
    table2 = {r.cfg("optimizer.name"): r for r in datas["fig2b"].runs("best")}
    misses, ratios, text = [], [], []
    for fid, opts in GD_GRIDS.items():
        for o in opts:
            require(o in table2, what=f"fig2b {o}")
            lr, b = table2[o].cfg("optimizer.lr"), table2[o].cfg("batch_size")
            grid = {r.cfg("optimizer.lr"): final([r]) for r in datas[fid].runs(o) if r.cfg("batch_size") == b}
            require(lr in grid, what=f"{fid} {o} η={num(lr)} b={b}")
            best_lr = min(grid, key=grid.get)
            text.append(f"{OPTIMIZER_NAMES[o]} b={b}: table 2 η={num(lr)}, best η={num(best_lr)}")
            if best_lr != lr:
                misses.append(f"{OPTIMIZER_NAMES[o]} (η={num(lr)} ends {grid[lr] / grid[best_lr]:.2f}x above η={num(best_lr)})")
                ratios.append(grid[lr] / grid[best_lr])
    values = {"misses": len(misses), "family": len(text), "missed": "; ".join(misses) or "none"}
    values |= {"worst_ratio": max(ratios, default=1.0), "level": LEVEL}
    return "; ".join(text), not misses, 2 * len(misses) < len(text), values
