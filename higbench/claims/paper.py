"""Every claim of the paper, in one place: its rule, its evidence (the measurement that
reads the runs) and its root cause, stated from the measured values (``higbench.claims.rules``
holds the vocabulary). Grouped by family in the report's order: toy, oscillator, Poisson,
dipole, ablation, tables. ``claims()`` lists them in that order.

A claim reads the figures' data duck-typed (``datas[figure id].runs(sweep, **where)``); the
few settings both a figure and its claims need (the optimizers and grids a claim iterates
over) are defined here, below the figures, which import them.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import torch

from higbench.bench.paper import PAPER_COSTS
from higbench.bench.tables import PAPER_TIMINGS, PROBLEMS, cell, timing_frame
from higbench.claims.reference import UPDATE_SECONDS
from higbench.claims.rules import (
    CLAIMS,
    DIPOLE_HIG_RUN,
    OSC_ADAM_RUN,
    OSC_HIG_RUN,
    PAPER,
    Cause,
    Claim,
    Missing,
    at_update,
    below,
    best,
    budget_of,
    by_id,
    by_setting,
    claim,
    crossing_time,
    end_time,
    falling,
    final,
    float32_loss,
    half_way,
    last_half_trend,
    loss_at,
    median,
    oscillation,
    precision_probe,
    probe_values,
    require,
    stable,
    updates_of,
)
from higbench.display import OPTIMIZER_NAMES, num, sci
from higbench.problems.toy import target_function
from higbench.results.targets import time_to

# -- toy (figure 1) -------------------------------------------------------------------------
# Paper 2.1, appendix B.1. fig1's sweeps: "toy" (γ x Adam, GN, HIG) and "adam_tuned".

# Settings figures/toy.py sweeps over too.
TOY_OPTIMIZERS = ("adam", "gn", "hig")
TOY_TUNED_LRS = [0.003, 0.03]  # fair baseline: Adam's learning rate re-tuned at the same budget (the paper's is 0.3)
# A tanh neuron whose output hardly varies over the data set and sits near +-1.
SATURATED_STD, SATURATED_MEAN = 0.1, 0.9


def saturated(run) -> int:
    """Hidden neurons saturated at the last evaluation (|mean| > 0.9 and std < 0.1)."""
    if "neuron_mean" not in run.logs:
        return 0
    mean, std = run.logs["neuron_mean"][-1], run.logs["neuron_std"][-1]
    return int(np.sum((np.abs(mean) > SATURATED_MEAN) & (std < SATURATED_STD)))


def _by_opt(datas, gamma: float, *needed: str) -> dict[str, list]:
    runs = {o: datas["fig1"].runs("toy", problem__gamma=gamma, optimizer__name=o) for o in TOY_OPTIMIZERS}
    require(*(runs[o] for o in needed or TOY_OPTIMIZERS), what=f"fig1 gamma={gamma:g}")
    return runs


TOY1_CAUSE = Cause(
    "disagreement",
    "at the paper's η Adam ends {adam_decades:.1f} decades below its start, GN {gn_decades:.1f} and HIG {hig_decades:.1f}; "
    "Adam's loss is flat over the second half ({adam_half:e} half-way, {adam_final:e} at the end): a noise floor of Adam "
    "at that η, not a budget (experiment toy_lr_grid re-tunes it)",
    {
        "Adam short of the rule's level": lambda v: v["adam_decades"] < 2.5,
        "GN and HIG at it": lambda v: min(v["gn_decades"], v["hig_decades"]) >= 2.5,
        "Adam flat over the second half": lambda v: v["adam_final"] >= v["adam_half"] / 1.5,
    },
)


@claim("toy-1", "fig1", "~3 decades", min_seconds=20, cause=TOY1_CAUSE)
def well_conditioned(datas):
    """Toy, gamma=1: Adam, GN and HIG all decrease the loss by about three orders of magnitude.
    Rule: every optimizer >= 2.5 decades below its initial loss (partly: >= 1.5)"""
    runs = _by_opt(datas, 1.0)
    orders = {o: median(np.log10(r.initial_loss / r.final_loss) for r in rs) for o, rs in runs.items()}
    measured = ", ".join(f"{OPTIMIZER_NAMES[o]} {v:.1f}" for o, v in orders.items()) + " decades"
    values = {f"{o}_decades": v for o, v in orders.items()}
    if runs.get("adam"):
        values |= {"adam_final": final(runs["adam"]), "adam_half": half_way(runs["adam"])}
    return measured, all(x >= 2.5 for x in orders.values()), all(x >= 1.5 for x in orders.values()), values


TOY2_CAUSE = Cause(
    "disagreement",
    "both stall as the paper says, but below its plateau of {paper_toy_plateau:g}: Adam {adam_final:e} (half-way "
    "{adam_half:e}), GN {gn_final:e} (half-way {gn_half:e})",
    {
        "both flat over the second half": lambda v: (
            v["adam_final"] >= v["adam_half"] / 1.5 and v["gn_final"] >= v["gn_half"] / 1.5
        ),
        "both below the paper's plateau": lambda v: max(v["adam_final"], v["gn_final"]) < v["paper_toy_plateau"] / 2,
    },
)


@claim("toy-2", "fig1", "plateau ~0.2 (figure 1b)", min_seconds=30, cause=TOY2_CAUSE)
def stall(datas):
    """Toy, gamma=0.01: Adam and GN stall (loss plateau near 0.2). Rule: both final losses in [0.1, 0.4] and flat over
    the second half of the run (partly: both flat above 0.05, or both in [0.1, 0.4])"""
    runs = _by_opt(datas, 0.01, "adam", "gn")
    fa, fg = final(runs["adam"]), final(runs["gn"])
    # A stall is a plateau: the final loss no lower than 1/1.5 of the loss at half the run.
    half = {o: half_way(runs[o]) for o in runs}
    flat = all(final(runs[o]) >= half[o] / 1.5 for o in ("adam", "gn"))
    level = all(0.1 <= x <= 0.4 for x in (fa, fg))
    measured = f"final loss Adam {sci(fa)} (half-way {sci(half['adam'])}), GN {sci(fg)} (half-way {sci(half['gn'])}) (medians)"
    values = {"adam_final": fa, "gn_final": fg, "adam_half": half["adam"], "gn_half": half["gn"]}
    return measured, level and flat, (flat and all(x >= 0.05 for x in (fa, fg))) or level, values


TOY3_CAUSE = Cause(
    "budget",
    "HIG {hig_final:e} against the best Adam {adam_best:e} and GN {gn_final:e}, and HIG still falling ({hig_half:e} half-way)",
    {"HIG still falling": lambda v: v["hig_final"] < v["hig_half"] / 1.5},
)


@claim("toy-3", "fig1", "HIG lowest", min_seconds=20, cause=TOY3_CAUSE)
def toy_hig_lowest(datas):
    """Toy, gamma=0.01: HIG reaches a better loss than Adam and GN. Rule: HIG below half of the better of GN and the
    best Adam (paper η or re-tuned) (partly: below it)"""
    d, runs = datas["fig1"], _by_opt(datas, 0.01)
    fh, fa, fg = final(runs["hig"]), final(runs["adam"]), final(runs["gn"])
    tuned = {lr: final(rs) for lr in TOY_TUNED_LRS if (rs := d.runs("adam_tuned", optimizer__lr=lr))}
    fa_best = min([fa, *tuned.values()])
    tuned_text = ", ".join(f"η={lr:g} {sci(v)}" for lr, v in tuned.items())
    measured = (
        f"final loss (median of seeds) HIG {sci(fh)} vs Adam η=0.3 (paper) {sci(fa)} ({fa / fh:.1f}x), GN {sci(fg)}; "
        f"re-tuned Adam: {tuned_text or 'not run'} (HIG's advantage against the best: {fa_best / fh:.1f}x)"
    )
    values = {"hig_final": fh, "hig_half": half_way(runs["hig"]), "adam_best": fa_best, "gn_final": fg}
    values["margin"] = min(fa_best, fg) / fh / 2  # how far the rule's "below half" holds (the seed gate's exception)
    return measured, fh < 0.5 * min(fa_best, fg), fh < min(fa_best, fg), values


@claim("toy-4", "fig1", "GN saturates, HIG not", min_seconds=20)
def saturation(datas):
    """Toy, gamma=0.01: GN oversaturates neurons, HIG does not. Rule: GN >= 1 and HIG 0 (partly: GN > HIG), saturated:
    |mean| > 0.9 and std < 0.1 over the data at the end"""
    runs = _by_opt(datas, 0.01, "gn", "hig")
    sg, sh = median(saturated(r) for r in runs["gn"]), median(saturated(r) for r in runs["hig"])
    sa = median(saturated(r) for r in runs["adam"]) if runs["adam"] else float("nan")
    return f"saturated neurons (of 7, median over seeds): GN {sg:g}, HIG {sh:g}, Adam {sa:g}", sg >= 1 and sh == 0, sg > sh


@claim(
    "toy-5",
    "fig1",
    "all neurons active at γ=1",
    min_seconds=20,
    cause=Cause(
        "disagreement",
        "in the well-conditioned case the median run saturates {adam:g} neuron(s) under Adam (the paper's η) and "
        "{gn:g} under GN, {hig:g} under HIG, where the paper's figure shows every neuron active for all three",
        {"Adam or GN saturates a neuron": lambda v: v["adam"] > 0 or v["gn"] > 0},
    ),
)
def all_active(datas):
    """Toy, gamma=1: with a well-conditioned problem all neurons process information. Rule: no saturated neuron for any
    optimizer at γ=1 (median over seeds; partly: none for GN and HIG)"""
    runs = _by_opt(datas, 1.0)
    sat = {o: median(saturated(r) for r in rs) for o, rs in runs.items()}
    measured = "saturated neurons at γ=1: " + ", ".join(f"{OPTIMIZER_NAMES[o]} {v:g}" for o, v in sat.items())
    return measured, all(v == 0 for v in sat.values()), sat["gn"] == 0 and sat["hig"] == 0, sat


@claim(
    "toy-7",
    "fig1",
    "Adam and GN alike at γ=1",
    min_seconds=20,
    cause=Cause(
        "disagreement",
        "in the well-conditioned case Adam at the paper's η ends at {adam_final:e} and GN at {gn_final:e} (medians of "
        "{seeds} seeds): Adam's noise floor at that η (toy-1), not the conditioning",
        {"Adam above GN": below("gn_final", "adam_final")},
    ),
)
def toy_alike(datas):
    """Toy, gamma=1: Adam and GN behave alike in the well-conditioned case. Rule: their final losses (medians over seeds)
    within 10x of each other (partly: within 100x)"""
    runs = _by_opt(datas, 1.0, "adam", "gn")
    fa, fg = final(runs["adam"]), final(runs["gn"])
    ratio = max(fa, fg) / min(fa, fg)
    measured = f"final loss at γ=1 (median of seeds): Adam {sci(fa)}, GN {sci(fg)} ({ratio:.0f}x apart)"
    return measured, ratio <= 10, ratio <= 100, {"adam_final": fa, "gn_final": fg, "ratio": ratio}


def probe_target(run) -> np.ndarray:
    """The y-space target of the toy's probe sample: the run's logged one, else the target function at
    the probe's x (the committed plotted data keep the trajectory, not the target)."""
    if "probe_target" in run.logs:
        return np.asarray(run.logs["probe_target"], dtype=float).reshape(-1, 2)[-1]
    x = torch.tensor([[float(run.cfg("problem.probe_x", 0.5))]], dtype=torch.float64)
    return target_function(x)[0].numpy()


def y2_gap_left(y: np.ndarray, target: np.ndarray) -> float:
    """Share of the initial distance to the target along y_2 still left at the end of a y-space
    trajectory (0: reached; 1: no progress; above 1: farther than at the start). Progress to the
    target, not displacement: a path that overshoots the target along y_2 has moved, not arrived."""
    start = abs(y[0, 1] - target[1])
    return float(abs(y[-1, 1] - target[1]) / start) if start > 0 else float("nan")


def initial_phase_end(y: np.ndarray, target: np.ndarray) -> int:
    """Where GN's initial phase (appendix A.2: "several steps in varying directions") ends: the
    evaluation at which the trajectory is farthest from the target; from there on it heads back."""
    return int(np.argmax(np.linalg.norm(y[:, :2] - target, axis=1)))


def aim_at_target(y: np.ndarray, target: np.ndarray, start: int = 0) -> float:
    """How directly a y-space trajectory heads for the target from evaluation ``start`` on: the mean
    cosine between each step and the direction from its start to the target, weighted by the step's
    length (1: a straight line to the target, as gradient descent in y on a uniform L2 loss moves)."""
    steps, to = np.diff(y[start:, :2], axis=0), target - y[start:-1, :2]
    size, dist = np.linalg.norm(steps, axis=1), np.linalg.norm(to, axis=1)
    keep = (size > 0) & (dist > 0)
    if not keep.any():
        return float("nan")
    cos = (steps[keep] * to[keep]).sum(axis=1) / (size[keep] * dist[keep])
    return float(np.sum(cos * size[keep]) / np.sum(size[keep]))


def _paths(runs: dict, opt: str) -> list:
    """(trajectory, target) of each seed of ``opt`` whose y-space trajectory is there."""
    found = [(r.logs["probe_output"], probe_target(r)) for r in runs[opt] if "probe_output" in r.logs]
    require(found, what=f"fig1 {opt} probe trajectory")
    return found


def toy_trajectories_probe(table) -> dict:
    """The toy trajectories probe (scripts/probe_toy_trajectories.py): toy-6's quantities per seed, their medians,
    and on how many seeds each half of the rule holds."""
    ill, well = table[table["gamma"] == 0.01].set_index(["optimizer", "seed"]), table[table["gamma"] == 1.0]
    well = well.set_index(["optimizer", "seed"])
    seeds = sorted(set(table["seed"]))
    behind = sum(ill.loc[("adam", s), "y2_left"] > ill.loc[("hig", s), "y2_left"] for s in seeds)
    aims = sum(well.loc[("gn", s), "aim"] > well.loc[("adam", s), "aim"] for s in seeds)
    out = {"seeds": len(seeds), "updates": int(table["updates"].min()), "behind": int(behind), "aims": int(aims)}
    out |= {f"{o}_y2_left": float(ill.loc[o]["y2_left"].median()) for o in ("adam", "hig")}
    return out | {f"{o}_aim": float(well.loc[o]["aim"].median()) for o in ("adam", "gn")}


def toy6_rule(v: dict) -> tuple:
    """toy-6's rule on its measured values: both of the paper's sentences as comparisons, no threshold of ours."""
    behind, aims = v["adam_y2_left"] > v["hig_y2_left"], v["gn_aim"] > v["adam_aim"]
    measured = (
        f"γ=0.01, share of the initial distance to the target along y_2 left at the end: Adam {v['adam_y2_left']:.2f}, HIG "
        f"{v['hig_y2_left']:.2f}; γ=1, steps' aim at the target after GN's initial phase (mean cosine): GN "
        f"{v['gn_aim']:.2f}, Adam {v['adam_aim']:.2f} (medians over the {v['seeds_read']} seed(s) with a trajectory)"
    )
    return measured, behind and aims, behind or aims


@claim(
    "toy-6",
    "fig1",
    "Adam makes no progress along y_2 at γ=0.01; GN's path straight at γ=1 after its initial phase",
    min_seconds=20,
    decide=toy6_rule,
    cause=Cause(
        "disagreement",
        "in the ill-conditioned case Adam, at the paper's η, leaves {adam_y2_left:.2f} of its distance to the target along "
        "y_2 against HIG's {hig_y2_left:.2f}; in the well-conditioned case GN's steps after its initial phase aim at the "
        "target {gn_aim:.2f} against Adam's {adam_aim:.2f} (mean cosines)",
        {
            "Adam not behind HIG along y_2, or GN aiming no better than Adam": lambda v: (
                not (v["adam_y2_left"] > v["hig_y2_left"] and v["gn_aim"] > v["adam_aim"])
            ),
        },
        otherwise=Cause(
            "seeds",
            "the figure's plotted data keep the first seed's trajectories only; over {probe_seeds} seeds at "
            "{probe_updates} updates each (the toy trajectories probe, an update budget) Adam leaves "
            "{probe_adam_y2_left:.2f} of its distance to the target along y_2 against HIG's {probe_hig_y2_left:.2f}, and "
            "GN's steps after its initial phase aim at the target {probe_gn_aim:.2f} against Adam's {probe_adam_aim:.2f} "
            "(medians over seeds): Adam is behind on {probe_behind} of {probe_seeds} seeds, GN aims better on "
            "{probe_aims} of them",
            {
                "the rule holds on the figure's seed": lambda v: (
                    v["adam_y2_left"] > v["hig_y2_left"] and v["gn_aim"] > v["adam_aim"]
                ),
                "three seeds in the probe": lambda v: v["probe_seeds"] >= 3,
            },
            probe=probe_values("toy_trajectories.csv", toy_trajectories_probe),
        ),
    ),
)
def trajectories(datas):
    """Toy (§2.1, appendix A.2): in y-space the updates neglect y_2 and keep Adam from moving efficiently along it in the
    ill-conditioned case (γ=0.01), where HIG progresses along it; in the well-conditioned case (γ=1) GN's path is a
    straight line to the target after its initial phase (gradient descent in y). Rule: on the probe sample's
    trajectories (median over the seeds that have one), Adam leaves a larger share of its initial distance to the target
    along y_2 than HIG at the end (γ=0.01), and GN's steps after its initial phase (up to its farthest point from the
    target) aim at the target more directly than Adam's (γ=1; length-weighted mean cosine to the target), as gradient
    descent in y does and Adam, a descent in θ, need not (partly: one of the two)"""
    ill, well = _by_opt(datas, 0.01, "adam", "hig"), _by_opt(datas, 1.0, "adam", "gn")
    paths = {("ill", o): _paths(ill, o) for o in ("adam", "hig")} | {("well", o): _paths(well, o) for o in ("adam", "gn")}
    values = {f"{o}_y2_left": median(y2_gap_left(y, t) for y, t in paths[("ill", o)]) for o in ("adam", "hig")}
    # Adam's aim from GN's initial phase's end on, the same stretch of training; each seed its own.
    for o in ("adam", "gn"):
        starts = [initial_phase_end(y, t) for y, t in paths[("well", "gn")]]
        values[f"{o}_aim"] = median(aim_at_target(y, t, s) for (y, t), s in zip(paths[("well", o)], starts))
    values["seeds_read"] = min(len(p) for p in paths.values())
    return values


# -- oscillators (figures 2b, 2c, 5, 6) -----------------------------------------------------
# Paper 3.1, appendix B.2. fig2b: sweeps "best" (table 2's settings) and "adam_tuned"; fig2c, 5, 6:
# one sweep per optimizer; GN's runs use the best stable seed of a search ("<sweep>/search").

# Settings figures/oscillator.py sweeps over too.
FIG2B_OPTIMIZERS = ("adadelta", "adagrad", "adam", "gn", "hig", "rmsprop", "sgd")
GD_FAMILY = ("adadelta", "adagrad", "adam", "rmsprop", "sgd")
FIG2C_BATCHES = {"adam": [256, 512, 1024], "gn": [32, 64, 128], "hig": [32, 64, 128]}
GD_GRIDS = {"fig5": ("adadelta", "adagrad", "sgd", "rmsprop"), "fig6": ("adam",)}  # figure -> its optimizers' grids


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
    return "oscillates" if _largest_oscillates_most([oscillation(r) for r in runs]) else ""


def _largest_oscillates_most(wobble: list) -> bool:
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


# -- Poisson (figures 3b, 3c, 7) ------------------------------------------------------------
POISSON_ADAM_LR = 1e-4  # figure 3c's Adam: pre-training and continued
AUTHORS_SETUP = "_authors"  # suffix of the sweeps of the authors' setup, beside ours in figures 3b, 3c and 7
# Paper 3.2, appendix B.3. fig3b: sweeps "adam" and "hig" over η; fig3c and fig7: the chain of runs
# continued from Adam's ("adam_pre" -> "adam_cont", "hig_cont" -> "adam_after_hig").


def _at_the_papers_batch(v) -> bool:
    return v["hig_b"] == v["paper_poisson_b"]


AT_PAPERS_BATCH = {"the paper's batch": _at_the_papers_batch}
TARGET_DECADES = 3  # "up to three orders of magnitude" (§3.2)


def per_update_trend(run) -> dict:
    """A line through log10(test loss) against log2(updates) over the run's last half of updates:
    its slope (decades per doubling of updates) and, at that rate, the updates at which the loss
    would be ``TARGET_DECADES`` below its initial one (inf while it does not fall)."""
    c = run.curves[run.curves["step"] > 0]
    n = float(c["step"].iloc[-1]) if len(c) else 0.0

    def line(lo: float, hi: float) -> tuple[float, float]:
        part = c[(c["step"] >= lo) & (c["step"] <= hi)]
        if len(part) < 4:
            return math.nan, math.nan
        x, y = np.log2(part["step"].to_numpy(dtype=float)), np.log10(part["test_loss"].to_numpy(dtype=float))
        slope, icpt = np.polyfit(x, y, 1)
        return float(slope), float(icpt)

    (slope, icpt), (earlier, _) = line(n / 2, n), line(n / 4, n / 2)
    if math.isnan(slope):
        return {}
    goal = math.log10(run.initial_loss) - TARGET_DECADES
    needed = 2 ** ((goal - icpt) / slope) if slope < 0 else math.inf
    return {"per_doubling": -slope, "per_doubling_before": -earlier, "updates_needed": float(needed)} | {
        "target_decades": TARGET_DECADES
    }


RUN_LENGTH_HEAD = (
    "the run length, which the paper does not give for Poisson (the oscillators' and the dipole's come from the authors' "
    "scripts; their Poisson script runs until stopped): at the paper's b={hig_b} HIG made {hig_updates} updates and fell "
    "{hig_decades:.1f} decades, still falling {hig_per_doubling:.2f} decades per doubling of updates over its last half "
    "({hig_per_doubling_before:.2f} over the quarter before); at that rate {target_decades} decades take about "
    "{hig_updates_needed:.0f} updates, {paper_hours_needed:.1f} h at the paper's {paper_poisson_hig_update_s:g} s per "
    "update (its table) and {cpu_hours_needed:.0f} h at this CPU's {hig_update_s:.1f} s"
)
RUN_LENGTH_FACTS = AT_PAPERS_BATCH | {
    "HIG short of the paper's decades": lambda v: v["hig_decades"] < 2.5,
    "HIG still falling per update": lambda v: v["hig_per_doubling"] > 0,
    "the trend reaching them beyond the updates made": lambda v: v["hig_updates"] < v["hig_updates_needed"] < math.inf,
}
POISSON_RUN_LENGTH = Cause(
    "unspecified",
    RUN_LENGTH_HEAD + "; the fall per doubling is slowing, so these are lower bounds: optimistic",
    RUN_LENGTH_FACTS | {"slowing": lambda v: v["hig_per_doubling"] < v["hig_per_doubling_before"]},
    otherwise=Cause(
        "unspecified",
        RUN_LENGTH_HEAD + "; the fall per doubling is not slowing over the last half (should it slow later, these are "
        "lower bounds)",
        RUN_LENGTH_FACTS | {"not slowing": lambda v: v["hig_per_doubling"] >= v["hig_per_doubling_before"]},
    ),
)


@claim(
    "poi-1",
    "fig3b",
    "~3 decades",
    cause=Cause(
        "deviation",
        "HIG ran at b={hig_b} (the paper: {paper_poisson_b}) and made {hig_updates} updates to {hig_decades:.1f} decades: "
        "a smaller batch than the paper's (the long preset runs HIG at the paper's)",
        {"a smaller batch than the paper's": lambda v: v["hig_b"] < v["paper_poisson_b"]},
        otherwise=POISSON_RUN_LENGTH,
    ),
)
def both_decrease(datas, setup=""):
    """Poisson: Adam and HIG both decrease the loss by up to three orders of magnitude. Rule: both optimizers' best runs
    >= 2.5 decades below the initial loss (partly: >= 1)"""
    fig = datas["fig3b"]
    adam, hig = fig.runs("adam" + setup), fig.runs("hig" + setup)
    require(adam, hig, what="fig3b")
    dec = {"Adam": max(map(decades, adam)), "HIG": max(map(decades, hig))}
    measured = ", ".join(f"{k} {v:.1f} decades (best run)" for k, v in dec.items())
    n = max(map(updates_of, hig))
    best_hig = max(hig, key=decades)
    values = {"hig_decades": dec["HIG"], "adam_decades": dec["Adam"], "hig_updates": n, "hig_b": hig[0].cfg("batch_size")}
    values["hig_slope"] = log_time_slope(best_hig)
    values["hig_update_s"] = end_time(best_hig) / max(updates_of(best_hig), 1)
    values |= {f"hig_{k}" if k != "target_decades" else k: v for k, v in per_update_trend(best_hig).items()}
    if "hig_per_doubling" in values:
        need = values["hig_updates_needed"]
        values["paper_hours_needed"] = need * PAPER["paper_poisson_hig_update_s"] / 3600  # the paper's GPU's time
        values["cpu_hours_needed"] = need * values["hig_update_s"] / 3600
        measured += (
            f"; HIG still falling {values['hig_per_doubling']:.2f} decades per doubling of its {n} updates (last half), "
            f"{TARGET_DECADES} decades at that rate after ~{values['hig_updates_needed']:.0f}"
        )
    if not setup and (theirs := fig.runs("hig" + AUTHORS_SETUP)):  # beside ours where declared
        values["authors_hig_decades"] = max(map(decades, theirs))
    values["decisive"] = False  # the paper gives no run length for Poisson: a longer run may always show more
    return measured, all(v >= 2.5 for v in dec.values()), all(v >= 1.0 for v in dec.values()), values


def decades(run) -> float:
    """How many decades a run's loss fell below its initial one, at its lowest evaluation."""
    return float(np.log10(run.initial_loss / best([run])))


def continued_from_adam(table, lr: float = 0.01) -> dict:
    """The data probe's rows (scripts/probe_poisson_data.py), per data: Adam's pre-training updates, then from its
    weights HIG at ``lr`` (start, after 10 updates, end, updates made) and Adam (after 300 updates, end)."""
    early, late = 10, 300  # updates: the probe's summary columns test_after_<n>
    out = {"lr": lr, "early": early, "late": late, "b": int(table["batch_size"].iloc[0])}
    for data, name in (("phiflow_noise", "phiflow"), ("fourier", "fourier")):
        mine = table[table["data"] == data]
        cont = mine[mine["from"] == "Adam-pretrained"]
        hig = cont[(cont["optimizer"] == "hig") & np.isclose(cont["lr"], lr)].iloc[0]
        adam = cont[cont["optimizer"] == "adam"].iloc[0]
        pre = mine[(mine["from"] == "scratch") & (mine["optimizer"] == "adam") & np.isclose(mine["lr"], POISSON_ADAM_LR)]
        out |= {f"{name}_start": hig["test_start"], f"{name}_hig_10": hig[f"test_after_{early}"], f"{name}_hig": hig["test_end"]}
        out |= {f"{name}_hig_updates": int(hig["updates"]), f"{name}_pre_updates": int(pre["updates"].iloc[0])}
        out |= {f"{name}_adam": adam["test_end"], f"{name}_adam_300": adam.get(f"test_after_{late}", np.nan)}
    return {k: float(v) if isinstance(v, np.floating) else v for k, v in out.items()}


# What the GPU data probe (docs/results/probes/gpu/) shows for poi-2, on either data choice.
GPU_DATA_PROBE = {
    "HIG rising first on both data": lambda v: (
        v["probe_phiflow_hig_10"] > v["probe_phiflow_start"] and v["probe_fourier_hig_10"] > v["probe_fourier_start"]
    ),
    "HIG above its start at the end on the authors' data": lambda v: v["probe_phiflow_hig"] > v["probe_phiflow_start"],
}
GPU_DATA_PROBE_TEXT = (
    "in the GPU data probe (the authors' network, b={probe_b}, one seed; Adam pre-trained for {probe_fourier_pre_updates} "
    "updates) HIG η={probe_lr:g} made {probe_phiflow_hig_updates} updates: on the authors' PhiFlow noise it rose from "
    "{probe_phiflow_start:.3g} to "
    "{probe_phiflow_hig_10:.3g} in {probe_early} updates and ended at {probe_phiflow_hig:.3g}, above its start (Adam "
    "continued {probe_phiflow_adam_300:.3g} after {probe_late} updates); on ours it rose from {probe_fourier_start:.3g} "
    "to {probe_fourier_hig_10:.3g} and came back to {probe_fourier_hig:.3g} (Adam {probe_fourier_adam_300:.3g} after "
    "{probe_late})"
)
GPU_DATA = probe_values("gpu/poisson_data.csv", continued_from_adam)

# poi-2 from a deep pre-training (fig. 3c at long: 3,000 s of Adam): HIG drops at once and ends below Adam.
DEEP_START = Cause(
    "disagreement",
    "from a deep Adam pre-training (start {start:.3g}) HIG's first update lowers the loss to {hig_first:.3g}, and HIG "
    "ends at {hig_final:.3g}, below the best Adam continued ({adam_final:.3g}), but after its first update it falls "
    "{hig_fall:.2f} decades against Adam's {adam_fall:.2f} over {hig_updates} updates at the paper's b={hig_b}, data "
    "{data}: the quick drop holds, the faster descent does not",
    {
        "HIG's first update lowers the loss": lambda v: v["hig_first"] < v["start"],
        "HIG ends below Adam": below("hig_final", "adam_final"),
        "HIG no faster than Adam after its first update": lambda v: v["hig_fall"] <= v["adam_fall"],
        "the paper's batch": _at_the_papers_batch,
    },
)


def _falls(v: dict) -> dict:
    """Decades HIG falls after its first update, and the best Adam continued over its whole run (same start)."""
    return {"hig_fall": math.log10(v["hig_first"] / v["hig_final"]), "adam_fall": math.log10(v["start"] / v["adam_final"])}


def pretrained_rule(v: dict) -> tuple:
    """poi-2's rule on its measured values: the paper's words (§3.2), each one a comparison of the
    two runs from the same weights, no factor of our own."""
    f = _falls(v)
    drop, faster, lower = v["hig_first"] < v["start"], f["hig_fall"] > f["adam_fall"], v["hig_final"] < v["adam_final"]
    measured = (
        f"start {v['start']:.3g}; HIG's first update -> {v['hig_first']:.3g}, then {f['hig_fall']:.2f} decades down to "
        f"{v['hig_final']:.3g} in {v['hig_updates']} updates; the best Adam continued falls {f['adam_fall']:.2f} decades "
        f"to {v['adam_final']:.3g} (HIG's advantage {v['advantage']:.2g}x; data {v['data']}, b={v['hig_b']})"
    )
    return measured, drop and faster and lower, lower, f


@claim(
    "poi-2",
    "fig3c",
    "quick drop, HIG below Adam",
    min_seconds=600,
    decide=pretrained_rule,
    cause=Cause(
        "disagreement",
        "here (b={hig_b}, data {data}) HIG {start:e} -> {hig_final:e}, Adam {adam_final:e}; not the data distribution "
        "and not the updates made: " + GPU_DATA_PROBE_TEXT,
        {"Adam below HIG here": lambda v: v["adam_final"] < v["hig_final"]} | GPU_DATA_PROBE,
        probe=GPU_DATA,
        otherwise=DEEP_START,
    ),
)
def pretrained(datas, setup=""):
    """Poisson: HIG after Adam pre-training drops the loss quickly and ends below Adam. Rule: from the same Adam
    pre-trained weights, HIG's first update lowers the loss, HIG then falls more decades than the best Adam continued
    (paper η or re-tuned) over its run, and ends below it (partly: it ends below it)"""
    d = datas["fig3c"]
    hig, conts = d.runs("hig_cont" + setup), d.runs("adam_cont" + setup) + d.runs("adam_cont_tuned" + setup)
    adam = [r for r in conts if r.cfg("optimizer.lr") == POISSON_ADAM_LR]
    require(hig, adam, what="fig3c continuations")
    h = min(hig, key=lambda r: final([r]))  # the best η, where a setup has several
    fh, fa = final([h]), final(adam)
    fa_best = min([fa, *(final([r]) for r in conts)])
    values = {"start": h.initial_loss, "hig_final": fh, "adam_final": fa_best, "hig_b": h.cfg("batch_size")}
    values |= {"hig_first": at_update(h, 1), "advantage": fa_best / fh, "hig_updates": updates_of(h)}
    values |= {"data": h.cfg("problem.data", "fourier"), "decisive": fh > h.initial_loss > fa_best}  # rising vs falling
    falls = _falls(values)
    ratios = (values["start"] / values["hig_first"], 10 ** (falls["hig_fall"] - falls["adam_fall"]), fa_best / fh)
    return values | {"margin": min(ratios)}  # the tightest of the rule's three comparisons, as a factor


TAIL = 20  # evaluations: where a run ends is the median of its last 20, not its last (noisy) value


def tail(run) -> float:
    """The median test loss of the run's last ``TAIL`` evaluations."""
    return float(np.median(run.curves["test_loss"].to_numpy(dtype=float)[-TAIL:]))


def given_back_rule(v: dict) -> tuple:
    """poi-3's rule on its measured values: where each run ends is its tail median; Adam's jump at
    its restart from HIG's weights counts net of the jump Adam makes restarting from its own."""
    lead = v["cont_tail"] / v["hig_tail"]
    own = math.log(v["cont_first"] / v["cont_start"])  # Adam continued from its own weights: the restart's jump
    first = (math.log(v["after_first"] / v["hig_tail"]) - own) / math.log(lead) if lead > 1 else math.nan
    end = math.log(v["after_tail"] / v["hig_tail"]) / math.log(lead) if lead > 1 else math.nan
    measured = (
        f"ends (median of the last {TAIL} evaluations): HIG {sci(v['hig_tail'])} (last value {sci(v['hig_final'])}), Adam "
        f"continued from the pre-training {sci(v['cont_tail'])} (HIG's lead {lead:.2f}x); Adam from HIG's weights "
        f"{sci(v['after_first'])} after {v['first_updates']} updates, ends at {sci(v['after_tail'])}; Adam's own restart "
        f"jumps {sci(v['cont_start'])} -> {sci(v['cont_first'])} ({math.exp(own) - 1:+.0%})"
    )
    if lead > 1:
        measured += f"; share of HIG's lead given back, net of that jump: {first:.0%} at once, {end:.0%} at the end"
    return measured, lead > 1 and min(first, end) >= 0.5, v["after_tail"] > v["hig_tail"]


@claim(
    "poi-3",
    "fig7",
    "loss goes back up",
    min_seconds=300,
    decide=given_back_rule,
    cause=Cause(
        "unspecified",
        "follows from poi-2: HIG ends at {hig_final:e}, above its start {start:e}, so there is no HIG progress for Adam to "
        "lose (Adam from it ends at {adam_after:e})",
        {"HIG above its start": lambda v: v["hig_final"] > v["start"]},
        otherwise=Cause(
            "disagreement",
            "net of the jump Adam makes restarting from its own weights ({cont_start:.3g} -> {cont_first:.3g}), Adam from "
            "HIG's weights ({hig_final:.3g}) does not give back half of HIG's lead at once ({after_first:.3g} against "
            "HIG's {hig_tail:.3g} and Adam continued's {cont_tail:.3g}), or not by its end ({after_tail:.3g})",
            {"HIG ends below Adam continued": below("hig_tail", "cont_tail")},
        ),
    ),
)
def adam_after_hig(datas, setup=""):
    """Poisson: Adam started from the HIG run quickly loses HIG's progress and goes on at the loss of the original Adam
    run. Rule: where runs end is the median of their last 20 evaluations; HIG ends below Adam continued from the same
    pre-training, and Adam from HIG's weights gives back at least half of that lead (on a log scale) at its first
    evaluation, net of the jump Adam makes restarting from its own weights, and at its end (partly: it ends above the
    HIG run)"""
    fig7 = datas["fig7"]
    after = fig7.runs("adam_after_hig" + setup)
    hig = [r for r in fig7.runs("hig_cont" + setup) if after and str(r.path) == str(after[0].cfg("init_from"))]
    cont = [r for r in fig7.runs("adam_cont" + setup) if r.cfg("optimizer.lr") == after[0].cfg("optimizer.lr")] if after else []
    require(hig, after, cont, what="fig7b")
    first = {"after": first_evaluation(after[0]), "cont": first_evaluation(cont[0])}
    values = {"hig_final": final(hig), "hig_tail": tail(hig[0]), "cont_tail": tail(cont[0]), "after_tail": tail(after[0])}
    values |= {"adam_after": final(after), "start": hig[0].initial_loss}
    values |= {"after_first": float(first["after"]["test_loss"]), "first_updates": int(first["after"]["step"])}
    values |= {"cont_start": cont[0].initial_loss, "cont_first": float(first["cont"]["test_loss"])}
    values["decisive"] = values["hig_final"] > values["start"]  # no progress to lose
    return values


def first_evaluation(run):
    """The run's evaluation after its first, or its only one."""
    return run.curves.iloc[min(1, len(run.curves) - 1)]


@claim("poi-4", "fig7", "HIG faster per iteration", min_seconds=60)
def per_update(datas, setup=""):
    """Poisson: per iteration, HIG converges faster than Adam. Rule: at every update count HIG evaluated (from Adam's
    first evaluation on) the best HIG run is below the best of the Adam runs at that count, whichever η that is
    (partly: at HIG's last update count)"""
    adam, hig = datas["fig7"].runs("adam" + setup), datas["fig7"].runs("hig" + setup)
    require(adam, hig, what="fig7a")
    h = min(hig, key=lambda r: r.final_loss)
    n = min(updates_of(h), min(map(updates_of, adam)))
    first = max(int(a.curves["step"].iloc[1]) if len(a.curves) > 1 else n + 1 for a in adam)
    if first > n:  # Adam's curve says nothing about its first n updates (evaluated by time)
        return f"Adam's first evaluation after {first} updates, HIG's run {n}", None, "needs Adam evaluated by updates"
    steps = [int(k) for k in h.curves["step"] if first <= k <= n]
    best_adam = {k: min(at_update(a, k) for a in adam) for k in steps}  # the lower envelope of the Adam grid
    below_at = [at_update(h, k) < best_adam[k] for k in steps]
    la, lh = best_adam[steps[-1]], at_update(h, steps[-1])
    values = {"n": steps[-1], "hig": lh, "adam": la, "counts": len(steps), "hig_below": sum(below_at)}
    values["margin"] = min(best_adam[k] / at_update(h, k) for k in steps)
    measured = (
        f"after {steps[-1]} updates: HIG {sci(lh)} vs the best Adam at that count {sci(la)} ({la / lh:.0f}x); HIG below "
        f"the best Adam at {sum(below_at)} of {len(steps)} update counts from {first} on"
    )
    return measured, all(below_at), below_at[-1], values


def log_time_slope(run, start: float = 0.5) -> float:
    """d log10(loss) / d log10(t) over the run's last half (least squares on its evaluations)."""
    c = run.curves[(run.curves["wall_time"] >= start * end_time(run)) & (run.curves["wall_time"] > 0)]
    if len(c) < 2:
        return float("nan")
    return float(np.polyfit(np.log10(c["wall_time"]), np.log10(c["test_loss"]), 1)[0])


# Slopes on a log-time axis need a run long enough for a last half (the paper gives no Poisson run length).
@claim("poi-5", "fig3b", "smallest-η Adam ahead per time; HIG steeper on log time", min_seconds=600)
def adam_lr_and_slope(datas):
    """Poisson (fig. 3b): in absolute convergence per time the Adam curve with the smallest η shows advantages over HIG,
    but on a log-time axis HIG's slope stays steeper than Adam's. Rule: the smallest-η Adam run ends below the best HIG
    run at the same training time, and that HIG run's log-log slope over the last half is steeper than the smallest-η
    Adam run's (partly: one of the two)"""
    adam, hig = datas["fig3b"].runs("adam"), datas["fig3b"].runs("hig")
    require(adam, hig, what="fig3b")
    small, best_hig = min(adam, key=lambda r: r.cfg("optimizer.lr")), min(hig, key=lambda r: final([r]))
    t = min(end_time(small), end_time(best_hig))
    la, lh = loss_at(small, t), loss_at(best_hig, t)
    sa, sh = log_time_slope(small), log_time_slope(best_hig)
    measured = (
        f"at {t:.0f} s: Adam η={num(small.cfg('optimizer.lr'))} {sci(la)}, best HIG (η={num(best_hig.cfg('optimizer.lr'))}) "
        f"{sci(lh)}; log-time slope over the last half: HIG {sh:.2f}, Adam {sa:.2f}"
    )
    values = {"adam_slope": sa, "hig_slope": sh, "adam_at": la, "hig_at": lh}
    return measured, la < lh and sh < sa, la < lh or sh < sa, values


@claim("poi-6", "fig3b", "larger-η Adam runs quickly slow down", min_seconds=600)
def adam_slows(datas):
    """Poisson (fig. 3b): Adam's two larger-η runs quickly slow down. Rule: each larger-η Adam run falls less over its
    last half on a log-time axis than the smallest-η run (a flatter slope) and ends above it (partly: the flatter
    slope)"""
    adam = sorted(datas["fig3b"].runs("adam"), key=lambda r: r.cfg("optimizer.lr"))
    require(len(adam) >= 3, what="fig3b Adam η grid")
    small, larger = adam[0], adam[1:]
    slope = {r.cfg("optimizer.lr"): log_time_slope(r) for r in adam}
    flatter = [slope[r.cfg("optimizer.lr")] > slope[small.cfg("optimizer.lr")] for r in larger]
    above = [final([r]) > final([small]) for r in larger]
    measured = "log-time slope over the last half: " + ", ".join(f"η={num(lr)} {v:.2f}" for lr, v in slope.items())
    measured += "; final: " + ", ".join(f"η={num(r.cfg('optimizer.lr'))} {sci(final([r]))}" for r in adam)
    return measured, all(flatter) and all(above), all(flatter), {"runs": len(adam)}


@claim("poi-7", "fig3b", "neither has fully converged", min_seconds=600)
def not_converged(datas):
    """Poisson (fig. 3b, §3.2): on a log-time axis both methods have not fully converged. Rule: the smallest-η Adam run
    and the best HIG run are both still falling over the last half of their run (a least-squares fall in log10 loss
    beyond twice its standard error) (partly: one of them)"""
    adam, hig = datas["fig3b"].runs("adam"), datas["fig3b"].runs("hig")
    require(adam, hig, what="fig3b")
    small, best_hig = min(adam, key=lambda r: r.cfg("optimizer.lr")), min(hig, key=lambda r: final([r]))
    (ca, na), (ch, nh) = last_half_trend(small), last_half_trend(best_hig)
    measured = (
        f"last half: Adam η={num(small.cfg('optimizer.lr'))} {ca:+.2f} decades (noise {na:.2f}), HIG "
        f"η={num(best_hig.cfg('optimizer.lr'))} {ch:+.2f} decades (noise {nh:.2f})"
    )
    values = {"adam_change": ca, "adam_noise": na, "hig_change": ch, "hig_noise": nh}
    return measured, falling(ca, na) and falling(ch, nh), falling(ca, na) or falling(ch, nh), values


def on_authors_setup(c: Claim, cause: Cause | None = None) -> Claim:
    """Claim ``c`` judged on the authors' script's setup (PhiFlow noise potentials, network [64, 128, 64], b=64): the
    same rule on the sweeps ``<sweep>_authors``, with a cause of its own (stated from their runs)."""

    def measure(datas):
        try:
            return c.measure(datas, AUTHORS_SETUP)
        except Missing as m:  # say where the setup is declared
            raise Missing(f"{m} for the authors' setup (declared at the presets that run HIG at b=64: long, paper)") from None

    statement = c.statement.replace("Poisson:", "Poisson, the authors' data and network:", 1)
    return dataclasses.replace(c, id=f"{c.id}a", statement=statement, measure=measure, cause=cause)


AUTHORS_DATA = "on the authors' data and network, "
# The causes on the authors' setup: nothing of ours differs from their script there (data, network, batch).
AUTHORS_CAUSES = {
    "poi-2": Cause(
        "disagreement",
        "the authors' data, network and b={hig_b}: HIG {start:e} -> {hig_final:e}, Adam {adam_final:e}; " + GPU_DATA_PROBE_TEXT,
        {"Adam below HIG": lambda v: v["adam_final"] < v["hig_final"]} | GPU_DATA_PROBE,
        probe=GPU_DATA,
        otherwise=DEEP_START,
    ),
    "poi-1": dataclasses.replace(
        POISSON_RUN_LENGTH,
        text="on the authors' data and network, " + POISSON_RUN_LENGTH.text,
        otherwise=dataclasses.replace(
            POISSON_RUN_LENGTH.otherwise, text="on the authors' data and network, " + POISSON_RUN_LENGTH.otherwise.text
        ),
    ),
}


CLAIMS.extend([on_authors_setup(c, AUTHORS_CAUSES.get(c.id)) for c in CLAIMS if c.id in ("poi-1", "poi-2", "poi-3", "poi-4")])


# -- dipole (figures 4b, 4c, 8-11) ----------------------------------------------------------
# Paper 3.3, appendix B.4. fig4b, fig4c: sweeps "adam" and "hig"; figs 8-11: the appendix's grids.

PLATEAU = (0.4, 0.6)  # "Adam stagnates at a loss value of 0.5"
LE, HE = "test_low_energy_loss", "test_high_energy_loss"  # figure 4c's curves (figures/dipole.py)


def plateau_seconds(run, band=PLATEAU, x: str = "wall_time") -> float:
    """Training seconds (``x="step"``: updates) with the test loss inside ``band`` (piecewise
    constant between evaluations).

    A duration, not a share of the run: the plateau lasts the same time in a longer run."""
    t, y = run.curves[x].to_numpy(dtype=float), run.curves["test_loss"].to_numpy(dtype=float)
    if len(t) < 2:
        return float("nan")
    inside = (y[:-1] >= band[0]) & (y[:-1] <= band[1])
    return float(np.sum(np.diff(t)[inside]))


def energy_ratio(run, above: float = PLATEAU[0]) -> float:
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


PLATEAU_UPDATES = 100  # a stall, not an evaluation or two passing through the band


def plateau_rule(v: dict) -> tuple:
    """dip-1's rule on its measured values, in updates (the paper's axis there is its training
    clock, whose seconds per update are its GPU's: counted in updates the stall is the optimizer's)."""
    ua, uh = v["adam_plateau_updates"], v["hig_plateau_updates"]
    measured = (
        f"updates with the test loss in [{PLATEAU[0]}, {PLATEAU[1]}]: Adam {ua:.0f}, HIG {uh:.0f} (medians over seeds; "
        f"Adam's {v['adam_plateau_s']:.0f} s at {v['adam_update_ms']:.1f} ms per update here); Adam final {sci(v['adam_final'])}"
    )
    full = ua >= PLATEAU_UPDATES and ua >= 2 * uh and v["adam_final"] < PLATEAU[0]  # a stall is one once Adam has left it
    return measured, full, ua > uh


@claim(
    "dip-1",
    "fig4c",
    "plateau at 0.5",
    min_seconds=60,
    decide=plateau_rule,
    cause=Cause(
        "budget",
        "Adam stalls {adam_plateau_updates:.0f} updates in the band against HIG's {hig_plateau_updates:.0f}, and has not "
        "left it by the end of the run ({adam_final:e})",
        {"Adam still in the band at the end": lambda v: v["adam_final"] >= PLATEAU[0]},
    ),
)
def plateau(datas):
    """Dipole: Adam (η=1e-4) first stagnates at a loss of 0.5. Rule: Adam spends >= 100 updates with the test loss in
    [0.4, 0.6], at least twice as many as HIG, and ends below the band (partly: more updates there than HIG); medians
    over seeds"""
    adam, hig = _pair(datas, "fig4c")
    values = {"adam_b": adam[0].cfg("batch_size"), "adam_plateau_s": median(map(plateau_seconds, adam))}
    values["adam_final"] = final(adam)
    values["adam_plateau_updates"] = median(plateau_seconds(r, x="step") for r in adam)
    values["hig_plateau_updates"] = median(plateau_seconds(r, x="step") for r in hig)
    values["adam_update_ms"] = 1e3 * median(end_time(r) / max(updates_of(r), 1) for r in adam)
    return values


@claim("dip-10", "fig4b", "the 0.5 plateau most pronounced at η=1e-4", min_seconds=60)
def plateau_by_lr(datas):
    """Dipole (§3.3, fig. 4b): Adam's plateau at 0.5 is most pronounced for η=1e-4 of its η grid. Rule: the η=1e-4 Adam run
    spends the most training time with the test loss in [0.4, 0.6] of fig. 4b's Adam runs, and more than any other
    (partly: at least as much as any other)"""
    adam = datas["fig4b"].runs("adam")
    require(len(adam) >= 2 and any(r.cfg("optimizer.lr") == 1e-4 for r in adam), what="fig4b Adam η=1e-4 and others")
    band = {r.cfg("optimizer.lr"): plateau_seconds(r) for r in adam}
    others = max(v for lr, v in band.items() if lr != 1e-4)
    measured = "seconds with the test loss in [0.4, 0.6]: " + ", ".join(f"η={num(lr)} {v:.1f}" for lr, v in sorted(band.items()))
    return measured, band[1e-4] > others, band[1e-4] >= others, {"plateau_1e-4": band[1e-4], "others": others}


@claim(
    "dip-2",
    "fig4c",
    "LE before HE for Adam",
    min_seconds=60,
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


def stage_evaluations(run, above: float = PLATEAU[0]) -> int:
    """Evaluations after the first with the test loss >= ``above`` (the initial stage)."""
    return int((run.curves["test_loss"].iloc[1:] >= above).sum())


def low_energy_rise(run, plateau: float = PLATEAU[0]) -> float:
    """How far the low-energy loss rises above its running minimum while the high-energy loss is still >= ``plateau``
    (its initial stage): 1 when it never rises there, NaN without such evaluations."""
    c = run.curves[run.curves[HE] >= plateau]
    if len(c) < 2:
        return float("nan")
    le = c[LE].to_numpy(dtype=float)
    return float(np.max(le / np.minimum.accumulate(le)))


@claim("dip-9", "fig4c", "Adam raises LE again before HE", min_seconds=60)
def le_again(datas):
    """Dipole (§3.3): Adam raises the low-energy loss again before it fits the high-energy one. Rule: in the median over
    fig. 4c's Adam seeds the low-energy loss rises more than 10% above its running minimum while the high-energy loss is
    still >= 0.4, and HIG's does not (partly: Adam's rises)"""
    adam, hig = _pair(datas, "fig4c")
    ra, rh = median(map(low_energy_rise, adam)), median(map(low_energy_rise, hig))
    measured = f"low-energy loss over its running minimum while the high-energy loss >= {PLATEAU[0]}: Adam {ra:.2f}x, HIG "
    measured += f"{rh:.2f}x (medians of {len(adam)} and {len(hig)} seeds)"
    return measured, ra > 1.1 and not rh > 1.1, ra > 1.1, {"adam_rise": ra, "hig_rise": rh}


@claim("dip-3", "fig4c", "HIG below Adam", min_seconds=60)
def hig_below(datas):
    """Dipole: HIG minimises the loss faster and to a lower level than Adam. Rule: over fig. 4c's seeds (the paper's
    settings), HIG's median final loss <= half of Adam's, and HIG below Adam at a tenth of the budget (partly: below
    it at the end)"""
    adam, hig = _pair(datas, "fig4c")
    fa, fh = final(adam), final(hig)
    t10 = 0.1 * min(end_time(r) for r in adam + hig)
    ea, eh = median(loss_at(r, t10) for r in adam), median(loss_at(r, t10) for r in hig)
    floor = PAPER["float32_floor"]  # below it a value is the evaluation's rounding: a ratio only bounds
    ratio = f"{fa / fh:.2g}x" if fh >= floor else f"> {fa / floor:.2g}x" if fa >= floor else "both at the float32 floor"
    measured = (
        f"median over {len(hig)} seeds: final HIG {float32_loss(fh)} vs Adam {float32_loss(fa)} ({ratio}); at {t10:.0f} s HIG "
    )
    measured += f"{sci(eh)} vs Adam {sci(ea)}"
    return measured, fh <= 0.5 * fa and eh < ea, fh < fa, {"hig": fh, "adam": fa}


@claim(
    "dip-4",
    "fig4b",
    "~1e-6",
    min_seconds=DIPOLE_HIG_RUN,
    cause=Cause(
        "hardware",
        "the best run ends below {float32_floor:e}, where a float32 evaluation rounds, far below the "
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
    measured = f"lowest test loss of any fig4b run: {float32_loss(low)}"
    return measured, 1e-7 <= low <= 1e-5, low <= 1e-4, {"low": low, "decisive": low < 1e-7}


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
def dipole_tau(datas):
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
    cause=Cause(
        "budget",
        "best HIG {hig:e} against the best Adam {adam:e}, HIG still falling ({hig_half:e} half-way)",
        {"HIG still falling": below("hig", "hig_half")},
    ),
)
def cnn(datas):
    """Dipole CNN: the best HIG run beats the best Adam run. Rule: best HIG CNN run's final loss <= half of the best Adam
    CNN run's (partly: below it)"""
    adam, hig = by_setting(datas["fig10"].runs("adam")), by_setting(datas["fig11"].runs("hig"))
    require(adam, hig, what="fig10/fig11")
    a, h = min(adam, key=final), min(hig, key=final)  # the best settings by their median over seeds
    fa, fh = final(a), final(h)
    paper = [final(g) for g in adam if g[0].cfg("optimizer.lr") == 2e-4 and g[0].cfg("batch_size") == 256]
    vs_paper = f"; Adam at the paper's η=2e-4 b=256 {sci(paper[0])} ({paper[0] / fh:.2g}x)" if paper else ""
    measured = f"best HIG {sci(fh)} ({h[0].label()}), best Adam of the grid {sci(fa)} ({a[0].label()}; "
    measured += f"HIG's advantage {fa / fh:.2g}x)"
    seeds = f"; medians of {len(h)} and {len(a)} seeds" if len(a) > 1 or len(h) > 1 else ""
    values = {"hig": fh, "adam": fa, "hig_half": half_way(h), "margin": fa / fh / 2}
    return measured + vs_paper + seeds, fh <= 0.5 * fa, fh < fa, values


def time_to_reach(run, level: float) -> float:
    """Training seconds to ``level``: the project's one time-to-target rule (``targets.time_to``:
    the first evaluation at or below it; inf if none)."""
    return time_to(_loss_of(run), run.curves["wall_time"].to_numpy(dtype=float), level)


def _loss_of(run) -> np.ndarray:
    return run.curves["test_loss"].to_numpy(dtype=float)


CNN_LEVELS = (0.5, 1.0)  # Adam's levels at these shares of its run: past the first tenth, where B.4 puts start-up plateaus


def cnn3_rule(v: dict) -> tuple:
    """cnn-3's rule on its measured values: the time each takes to the same loss, at Adam's levels past the start-up."""
    sooner = [v[f"hig_t_{n}"] < v[f"adam_t_{n}"] for n in ("50", "100")]
    measured = "; ".join(
        f"to Adam's level at {n}% of its run ({sci(v[f'level_{n}'])}): HIG {v[f'hig_t_{n}']:.0f} s, Adam {v[f'adam_t_{n}']:.0f} s"
        for n in ("50", "100")
    )
    measured += f" (medians of {v['seeds_read']} seeds; at a tenth of the run HIG {sci(v['hig_10'])}, Adam {sci(v['adam_10'])})"
    return measured, all(sooner), any(sooner)


@claim(
    "cnn-3",
    "fig10 fig11",
    "HIG faster than Adam (CNN)",
    min_seconds=60,
    decide=cnn3_rule,
    cause=Cause(
        "disagreement",
        "HIG takes {hig_t_50:.0f} s to the level Adam reaches at half of its run ({adam_t_50:.0f} s) and {hig_t_100:.0f} s "
        "to Adam's final level ({adam_t_100:.0f} s; medians of {seeds_read} seeds): not faster to those levels",
        {"HIG not sooner at one level": lambda v: v["hig_t_50"] >= v["adam_t_50"] or v["hig_t_100"] >= v["adam_t_100"]},
    ),
)
def cnn_faster(datas):
    """Dipole CNN (appendix B.4): HIG minimises the loss faster than Adam. Rule: the best HIG CNN setting reaches the
    levels the best Adam setting reaches at half of its run and at its end sooner than Adam does (time to each
    level, targets.time_to; medians over seeds; partly: one of the two). The first tenth is left out: B.4 puts HIG's early
    plateaus down to the framework's start-up, not the method"""
    adam, hig = by_setting(datas["fig10"].runs("adam")), by_setting(datas["fig11"].runs("hig"))
    require(adam, hig, what="fig10/fig11")
    a, h = min(adam, key=final), min(hig, key=final)
    t_end = min(end_time(r) for r in a + h)
    values = {"hig_10": median(loss_at(r, 0.1 * t_end) for r in h), "adam_10": median(loss_at(r, 0.1 * t_end) for r in a)}
    for share in CNN_LEVELS:
        n = f"{share * 100:.0f}"
        level = median(loss_at(r, share * t_end) for r in a)
        values[f"level_{n}"] = level
        values[f"adam_t_{n}"] = median(time_to_reach(r, level) for r in a)
        values[f"hig_t_{n}"] = median(time_to_reach(r, level) for r in h)
    return values | {"seeds_read": min(len(a), len(h))}


@claim(
    "dip-7",
    "fig8",
    "Adam: slow convergence or oscillation",
    min_seconds=20,
    cause=Cause(
        "seeds",
        "at all {slow_b} of {n_b} batch sizes the smallest η is the slowest at a tenth of the budget, as the paper says; "
        "the largest η oscillates most at {shaky_b} of them and a middle η at the others (first at b={calm_b}), each "
        "from a single seed per setting (a median needs three)",
        {"the smallest η slow at every b": lambda v: v["slow_b"] == v["n_b"], "one seed": lambda v: v["seeds"] < 3},
        otherwise=Cause(
            "disagreement",
            "over the median of {seeds} seeds, at all {slow_b} of {n_b} batch sizes the smallest η is the slowest at a "
            "tenth of the budget, as the paper says; but at b={calm_b} the largest η is not the one that oscillates "
            "most: η={wobble_most_lr} changes by {wobble_most:.2f} decades per evaluation and the largest η by "
            "{largest_wobble:.2f}, against {smallest_wobble:.2f} for the smallest. Adam trades speed against "
            "oscillation there too, but the oscillation peaks below the largest η",
            {
                "the smallest η slow at every b": lambda v: v["slow_b"] == v["n_b"],
                "three seeds": lambda v: v["seeds"] >= 3,
                "a middle η oscillating most": lambda v: v["wobble_most"] > v["largest_wobble"],
            },
        ),
    ),
)
def adam_trade_off(datas):
    """Dipole (fig. 8): Adam trades slow convergence against oscillation. Rule: at every b the smallest-η Adam setting
    is the highest at 10% of the budget (slow) and the largest-η setting oscillates most over the last half (partly: at
    some b); each setting by its median over seeds"""
    require(runs := datas["fig8"].runs("adam"), what="fig8")
    per_b, slow, shaky, text, calm = [], [], [], [], {}
    for b in sorted({r.cfg("batch_size") for r in runs}):
        at_b = by_setting([r for r in runs if r.cfg("batch_size") == b])
        settings = sorted(at_b, key=lambda g: g[0].cfg("optimizer.lr"))
        if len(settings) < 2:
            continue
        t10 = 0.1 * min(end_time(r) for g in settings for r in g)
        early = [median(loss_at(r, t10) for r in g) for g in settings]
        wobble = [median(map(oscillation, g)) for g in settings]
        lrs = [num(g[0].cfg("optimizer.lr")) for g in settings]
        slow.append(early[0] == max(early))
        shaky.append(_largest_oscillates_most(wobble))
        per_b.append(slow[-1] and shaky[-1])
        if not shaky[-1] and not calm and np.isfinite(wobble).any():  # the first b where a middle η oscillates most
            most = int(np.nanargmax(wobble))
            calm = {"calm_b": b, "wobble_most_lr": lrs[most], "wobble_most": wobble[most]}
            calm |= {"largest_wobble": wobble[-1], "smallest_wobble": wobble[0]}
        text.append(
            f"b={b}: at 10% of the budget η={lrs[0]} {sci(early[0])}, η={lrs[-1]} {sci(early[-1])} (lowest: "
            f"η={lrs[int(np.argmin(early))]}); oscillation " + ", ".join(f"η={lr} {w:.2g}" for lr, w in zip(lrs, wobble))
        )
    require(per_b, what="fig8 (two η at one b)")
    seeds = min(len(g) for g in by_setting(runs))  # the fewest any η has
    values = {"n_b": len(per_b), "slow_b": sum(slow), "shaky_b": sum(shaky)} | calm
    measured = "; ".join(text) + (f" (medians of {seeds} seeds)" if seeds > 1 else "")
    return measured, all(per_b), any(per_b), values


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


CNN_BEST = {
    "hig": {"optimizer.lr": 0.7, "batch_size": 16, "optimizer.tau": 1e-4},
    "adam": {"optimizer.lr": 2e-4, "batch_size": 256},
}


@claim(
    "cnn-4",
    "fig10 fig11",
    "best: HIG η=0.7 b=16 τ=1e-4; Adam η=2e-4 b=256",
    min_seconds=60,
    cause=Cause(
        "hardware",
        "the best HIG setting here is τ={hig_best_tau:e} ({hig_best:e} against {hig_paper:e} at the paper's τ; medians of "
        "{seeds} seeds): with our double-precision inversion a τ below the paper's trains as well as or better than the "
        "paper's, as dip-8's precision probe shows for the MLP (no precision probe of the CNN is committed)",
        {"a smaller τ best here": lambda v: v["hig_best_tau"] < CNN_BEST["hig"]["optimizer.tau"]},
    ),
)
def cnn_best_settings(datas):
    """Dipole CNN (appendix B.4): the best HIG run has η=0.7, b=16, τ=1e-4 and the best Adam run η=2e-4, b=256. Rule: of
    fig. 11's HIG settings and fig. 10's Adam settings, those are the lowest by their median over seeds (partly: one of
    the two)"""
    found = {}
    for opt, fid in (("hig", "fig11"), ("adam", "fig10")):
        groups = by_setting(datas[fid].runs(opt))
        require(groups, what=f"{fid} {opt}")
        best_group = min(groups, key=final)
        paper = [g for g in groups if all(g[0].cfg(k) == v for k, v in CNN_BEST[opt].items())]
        found[opt] = (best_group, paper[0] if paper else None)
    values = {"hig_best": final(found["hig"][0]), "adam_best": final(found["adam"][0])}
    values |= {"hig_best_tau": found["hig"][0][0].cfg("optimizer.tau")}
    is_paper = {o: found[o][1] is found[o][0] for o in found}
    for o in found:
        values[f"{o}_paper"] = final(found[o][1]) if found[o][1] else math.nan
    measured = "; ".join(
        f"best {OPTIMIZER_NAMES[o]}: {found[o][0][0].label()} {sci(values[f'{o}_best'])} (the paper's setting "
        f"{sci(values[f'{o}_paper'])})"
        for o in found
    )
    return measured, all(is_paper.values()), any(is_paper.values()), values


# -- ablations (figures 12, 13) -------------------------------------------------------------
# Paper appendix C. fig12: sweeps "beta" and "kappa"; fig13: "hig" and "gn" over τ.


@claim(
    "abl-1",
    "fig12",
    "little influence",
    min_seconds=120,
    cause=Cause(
        "budget",
        "a negative β scales HIG's step by max(s)^β, a slower start: the spread over β shrinks from {spread_half:.0f}x "
        "half-way to {spread:.0f}x at the end",
        {"the spread shrinks": below("spread", "spread_half")},
    ),
)
def beta(datas):
    """Ablation: β has little influence on the outcome. Rule: final losses over β within 10x, none diverged (partly:
    within 100x)"""
    require(len(runs := datas["fig12"].runs("beta")) >= 2, what="fig12a")
    fin = {r.cfg("optimizer.beta"): final([r]) for r in runs}
    finite = [v for v in fin.values() if math.isfinite(v)]
    spread = max(finite) / min(finite) if finite else math.inf
    measured = ", ".join(f"β={num(b)}: {sci(v)}" for b, v in sorted(fin.items(), reverse=True)) + f" (spread {spread:.1f}x)"
    halves = [h for r in runs if math.isfinite(h := half_way([r]))]
    values = {"spread": spread, "spread_half": max(halves) / min(halves) if halves else math.inf}
    return measured, spread < 10 and len(finite) == len(fin), spread < 100, values


@claim("abl-2", "fig12", "orders of magnitude", min_seconds=30)
def kappa(datas):
    """Ablation: κ > 0 stagnates early; κ < 0 ends orders of magnitude lower. Rule: best negative-κ run >= 100x below
    the best positive-κ run (partly: >= 10x)"""
    runs = datas["fig12"].runs("kappa")
    pos, neg = ([final([r]) for r in runs if sign * r.cfg("optimizer.kappa") > 0] for sign in (1, -1))
    require(pos, neg, what="fig12b (needs kappa > 0 and < 0)")
    ratio = min(pos) / min(neg) if min(neg) > 0 else math.inf
    values = {"ratio": ratio, "margin": ratio / 100}  # margin: how far the rule's 100x holds (the seed gate's exception)
    return f"best κ>0 {sci(min(pos))}, best κ<0 {sci(min(neg))} ({ratio:.0f}x)", ratio >= 100, ratio >= 10, values


def gn_small_tau_by_time(datas) -> dict:
    """GN's smallest-τ run of fig13 at half of its training time and at its end (test loss): whether it is
    still falling when its budget ends (time only: what the committed plotted data hold)."""
    gn = [r for r in datas["fig13"].runs("gn") if r.cfg("optimizer.tau") <= 1e-9]
    require(gn, what="fig13 GN at τ <= 1e-9")
    r = min(gn, key=lambda r: r.cfg("optimizer.tau"))
    return {"gn_small_half": half_way([r]), "gn_small_end": final([r]), "gn_small_half_s": 0.5 * end_time(r)}


@claim(
    "abl-3",
    "fig13",
    "GN diverges, HIG stable",
    min_seconds=120,
    cause=Cause(
        "seeds",
        "GN is tried at small τ with one seed only ({gn_seed}), the one of the {search_seeds} searched that survived the "
        "paper's τ ({search_diverged} diverged there): GN's instability shows over seeds at the paper's τ already, and the "
        "one stable seed does not diverge at small τ within {n} updates; its trend points away from the paper's "
        "divergence, not towards it: at equal updates its smallest τ ({tau_small:e}, {gn_small:e}) is its best "
        "({gn_best:e}), still falling ({gn_small_half:e} at {gn_small_half_s:.0f} s, {gn_small_end:e} at the end), and with "
        "the inversion in the authors' single precision it does not diverge either within {probe_updates} updates "
        "(precision probe: τ={probe_tau_small:e} {probe_small_float32_status} at {probe_small_float32:e}); so not a "
        "budget, and whether other seeds diverge at small τ cannot be told from one seed that survives the paper's τ; HIG "
        "ends lower ({hig_best:e})",
        {
            "GN completes at the smallest τ": lambda v: v["gn_small_status"] == "completed",
            "its smallest τ its best": lambda v: v["gn_small"] <= v["gn_best"] * (1 + 1e-9),
            "most searched seeds diverge at the paper's τ": lambda v: 2 * v["search_diverged"] > v["search_seeds"],
            "single precision completes too": lambda v: v["probe_small_float32_status"] == "completed",
            "HIG below GN": below("hig_best", "gn_best"),
        },
        probe=probe_values("precision.csv", precision_probe("oscillator")),
    ),
)
def ablation_tau(datas):
    """Ablation: GN becomes unstable for small τ (diverges at 1e-9, 1e-10); HIG tolerates τ and ends lower. Rule: at
    equal update counts (the fewest any run made: below τ ~1e-7 the SVD route is slower per update), GN (best stable
    seed) stable at τ >= 1e-6 and diverging or >10x worse at τ <= 1e-9, every HIG run stable and HIG's best below
    GN's (partly: the GN part or the HIG part)"""
    d = datas["fig13"]
    hig, gn = d.runs("hig"), d.runs("gn")
    require(hig, gn, what="fig13")
    t = {id(r): r.cfg("optimizer.tau") for r in gn + hig}
    n = min(updates_of(r) for r in gn + hig if r.status != "diverged")
    at = {id(r): math.inf if r.status == "diverged" else at_update(r, n) for r in gn + hig}
    large, small = [r for r in gn if t[id(r)] >= 1e-6], [r for r in gn if t[id(r)] <= 1e-9]
    gn_best = min(at[id(g)] for g in gn)
    measured = (
        f"after {n} updates, GN (seed {gn[0].seed}): "
        + ", ".join(f"τ={num(t[id(r)])} {r.status} {sci(at[id(r)])}" for r in gn)
        + "; HIG: "
        + ", ".join(f"τ={num(t[id(r)])} {sci(at[id(r)])}" for r in hig)
        + f"; GN seed search at τ=1e-6: {gn_search_summary(d, 'gn/search')}"
    )
    if not small or not large:
        return measured, None, "needs GN runs at τ >= 1e-6 and at τ <= 1e-9"
    gn_part = all(map(stable, large)) and all(r.status == "diverged" or at[id(r)] > 10 * gn_best for r in small)
    hig_part = all(map(stable, hig)) and min(at[id(r)] for r in hig) < gn_best
    smallest = min(small, key=lambda r: t[id(r)])
    values = {"n": n, "gn_seed": smallest.seed, "tau_small": t[id(smallest)], "gn_small": at[id(smallest)]}
    values |= {"gn_small_status": smallest.status, "gn_best": gn_best, "hig_best": min(at[id(r)] for r in hig)}
    search = d.runs("gn/search")
    values |= {"search_seeds": len(search), "search_diverged": sum(r.status == "diverged" for r in search)}
    values |= gn_small_tau_by_time(datas)
    return measured, gn_part and hig_part, gn_part or hig_part, values


SEVERAL_DECADES = 100  # "several orders of magnitude" (appendix C): two at least


def abl5_rule(v: dict) -> tuple:
    """abl-5's rule on its measured values: "stagnate early" as the paper's contrast, not a flat curve of its own."""
    stuck = [k for k in v["positive"].split(",") if k]
    above = all(v[f"above_{k}"] >= SEVERAL_DECADES for k in stuck)
    completed = not v["diverged_positive"]
    strong = v["gain"] >= SEVERAL_DECADES
    measured = "; ".join(f"κ={k} ends {v[f'above_{k}']:.0f}x above the best κ<0" for k in stuck)
    if v["diverged_positive"]:
        measured += f"; κ={v['diverged_positive']} diverged"
    measured += f"; κ=0 {sci(v['zero'])}, best κ<0 {sci(v['best_negative'])} ({v['gain']:.0f}x)"
    if v.get("diverged_negative"):
        measured += f"; κ={v['diverged_negative']} (Gauss-Newton's end of the family) diverged"
    return measured, above and completed and strong, above and strong


@claim(
    "abl-5",
    "fig12",
    "κ>0 stagnates early; κ<0 a strong improvement",
    min_seconds=120,
    decide=abl5_rule,
    cause=Cause(
        "disagreement",
        "κ={diverged_positive} diverges here (one seed; the largest κ is gradient descent's end of the family), where "
        "the paper's curve for it stagnates; the completed positive-κ runs end orders of magnitude above the best "
        "negative κ ({gain:.0f}x from zero κ), as the paper says",
        {
            "a positive-κ run diverged": lambda v: bool(v["diverged_positive"]),
            "negative κ far below": lambda v: v["gain"] >= SEVERAL_DECADES,
        },
    ),
)
def kappa_stagnates(datas):
    """Ablation (fig. 12b): for κ > 0 the curves stagnate early, while for negative κ the final losses are several orders
    of magnitude better, a strong improvement as soon as κ becomes negative. Rule: every κ>0 run completes and ends at
    least 100x ("several orders of magnitude") above the best κ<0 run, and that run is at least 100x below κ=0; a
    diverged run counts, as diverged (partly: the completed κ>0 runs and κ=0 are that far above)"""
    runs = datas["fig12"].runs("kappa")
    fin = {r.cfg("optimizer.kappa"): final([r]) for r in runs}
    neg = [v for k, v in fin.items() if k < 0 and math.isfinite(v)]
    pos = [r for r in runs if r.cfg("optimizer.kappa") > 0]
    require(pos, neg, 0.0 in fin, what="fig12b (κ>0, κ=0, κ<0)")
    best_negative = min(neg)
    done = [r for r in pos if r.status == "completed"]
    values = {f"above_{num(r.cfg('optimizer.kappa'))}": final([r]) / best_negative for r in done}
    values |= {"positive": ",".join(num(r.cfg("optimizer.kappa")) for r in done), "zero": fin[0.0]}
    values |= {"diverged_positive": ",".join(num(r.cfg("optimizer.kappa")) for r in pos if r.status != "completed")}
    values["diverged_negative"] = ",".join(
        num(r.cfg("optimizer.kappa")) for r in runs if r.cfg("optimizer.kappa") < 0 and r.status != "completed"
    )
    return values | {"best_negative": best_negative, "gain": fin[0.0] / best_negative}


@claim("abl-4", "fig12", "κ=-0.5 best", min_seconds=120)
def kappa_best(datas):
    """Ablation (fig. 12b): κ=-0.5 is the best κ. Rule: κ=-0.5 ends lowest of the κ sweep (partly: within 2x of the
    lowest)"""
    runs = datas["fig12"].runs("kappa")
    fin = {r.cfg("optimizer.kappa"): final([r]) for r in runs}
    require(-0.5 in fin and len(fin) >= 2, what="fig12b κ=-0.5 and others")
    k_best = min(fin, key=fin.get)
    return f"κ=-0.5 {sci(fin[-0.5])}; lowest: κ={num(k_best)} {sci(fin[k_best])}", k_best == -0.5, fin[-0.5] <= 2 * fin[k_best]


# -- tables 3-5: the cost of an update ------------------------------------------------------
# Paper 2.3 and tables 3-5, read through ``higbench.bench.tables.timing_frame``.


RATIO_RULE = (
    "measured HIG/Adam update-time ratio within 3x of the paper's ratio both on this CPU and on a GPU (the benchmark's GPU "
    "run, where committed) (partly: within 10x on either): the paper's ratio is its GPU's and its implementation's"
)
TABLE_SIZES = {"table3": ("oscillator", 128, 512), "table4": ("poisson", 64, 64), "table5": ("dipole", 16, 256)}


def reference_ratio(tid: str, hig_b: int, adam_b: int) -> dict:
    """The authors' own code's HIG/Adam update-time ratio on this CPU kind (reference.py), if measured."""
    t = {(r["optimizer"], r["batch_size"]): r["update_s"] for r in UPDATE_SECONDS if r["problem"] == PROBLEMS[tid]}
    found = ("hig", hig_b) in t and ("adam", adam_b) in t
    return {"ref_ratio": t[("hig", hig_b)] / t[("adam", adam_b)]} if found else {}


def on_a_gpu(table) -> dict:
    """The benchmark run on a GPU (``--device cuda``, docs/results/probes/gpu/paper_tables.csv): each table's HIG/Adam
    update-time ratio at the claims' batch sizes (structured route), HIG's GPU memory b=128 / b=32 on both routes
    (structured: block-diagonal; naive: the whole J), and the GPU."""
    rows = table.set_index(["problem", "optimizer", "batch_size", "jacobian"])
    t, m = rows["update_s"], rows["peak_mem_mb"]
    out = {"device": str(table["device"].iloc[0]).removeprefix("cuda (").removesuffix(")")}
    for tid, (problem, hig_b, adam_b) in TABLE_SIZES.items():
        if (problem, "hig", hig_b, "structured") in t and (problem, "adam", adam_b, "-") in t:
            out[f"ratio_{tid}"] = float(t[problem, "hig", hig_b, "structured"] / t[problem, "adam", adam_b, "-"])
    for route in ("structured", "naive"):
        out[f"memory_ratio_{route}"] = float(m["oscillator", "hig", 128, route] / m["oscillator", "hig", 32, route])
        out |= {f"mb_{route}_{b}": float(m["oscillator", "hig", b, route]) for b in (32, 64, 128)}
    jac = rows["jacobian_s"]
    out["jacobian_growth"] = float(jac["oscillator", "hig", 128, "structured"] / jac["oscillator", "hig", 32, "structured"])
    out["dipole_adam_growth"] = float(t["dipole", "adam", 1024, "-"] / t["dipole", "adam", 256, "-"])
    return out


def off_by(a: float, b: float) -> float:
    return max(a, b) / min(a, b)


ON_A_GPU = probe_values("gpu/paper_tables.csv", on_a_gpu)


def ratio_rule(tid: str):
    """The update-time ratio rule of a table's claim, on its measured values and the committed GPU run."""

    def decide(v: dict) -> tuple:
        gpu = ON_A_GPU().get(f"probe_ratio_{tid}")
        cpu_off = off_by(v["ratio"], v["paper_ratio"])
        gpu_off = off_by(gpu, v["paper_ratio"]) if gpu else None
        times = f"HIG {v['hig_s']:.3g} s / Adam {v['adam_s']:.3g} s = " if "hig_s" in v else ""
        measured = f"CPU: {times}{v['ratio']:.3g}x; " + (f"GPU: {gpu:.3g}x; " if gpu else "GPU: not run; ")
        measured += f"paper {v['paper_ratio']:.3g}x"
        full = cpu_off <= 3 and (gpu_off is None or gpu_off <= 3)
        return measured, full, cpu_off <= 10 or (gpu_off is not None and gpu_off <= 10)

    return decide


def ratio(cid: str, tid: str, hig_b: int, adam_b: int, paper: str, statement: str, cause: Cause | None = None) -> None:
    """Declare a claim on the HIG/Adam update-time ratio of a table."""

    def measure(datas):
        df = timing_frame(datas[tid])
        h, a = cell(df, "HIG", hig_b, "Update duration (s)"), cell(df, "Adam", adam_b, "Update duration (s)")
        if math.isnan(h) or math.isnan(a) or a <= 0:
            raise Missing(f"{tid} HIG b={hig_b} / Adam b={adam_b}")
        paper = PAPER_TIMINGS[tid][("hig", hig_b)][1] / PAPER_TIMINGS[tid][("adam", adam_b)][1]
        return {"ratio": h / a, "paper_ratio": paper, "hig_s": h, "adam_s": a} | reference_ratio(tid, hig_b, adam_b)

    measure.__doc__ = f"{statement} Rule: {RATIO_RULE}"
    claim(cid, tid, paper, cause=cause, decide=ratio_rule(tid))(measure)


HARDWARE_RATIO = Cause(
    "hardware",
    "measured on a CPU ({ratio:.3g}x) against the paper's GPU ({paper_ratio:.3g}x); higbench's benchmark on a GPU "
    "({probe_device}) gives {gpu_ratio:.3g}x: the ratio is the hardware's (and the implementation's), not the method's",
    {"the CPU's and the GPU's ratios far apart": lambda v: off_by(v["ratio"], v["gpu_ratio"]) > 3},
    probe=ON_A_GPU,
)


def hardware_ratio(tid: str) -> Cause:
    """``HARDWARE_RATIO`` reading the GPU ratio of table ``tid``."""

    def probes() -> dict:
        found = ON_A_GPU()
        return found | ({"gpu_ratio": found[f"probe_ratio_{tid}"]} if f"probe_ratio_{tid}" in found else {})

    return dataclasses.replace(HARDWARE_RATIO, probe=probes)


SPD1_CAUSE = Cause(
    "hardware",
    "measured on a CPU ({ratio:.1f}x) against the paper's GPU ({paper_ratio:.1f}x); the authors' own code on this CPU gives "
    "{ref_ratio:.0f}x (reference.py), and higbench's benchmark on a GPU ({probe_device}) {probe_ratio_table3:.1f}x: the "
    "ratio is the hardware's",
    {
        "the authors' code off the paper's ratio too": lambda v: off_by(v["ref_ratio"], v["paper_ratio"]) > 3,
        "the CPU's ratio off the paper's": lambda v: off_by(v["ratio"], v["paper_ratio"]) > 3,
    },
    probe=ON_A_GPU,
)
ratio(
    "spd-1",
    "table3",
    128,
    512,
    "0.146 s vs 0.081 s",
    "Oscillators: a HIG update (b=128) costs about 1.8 Adam updates (b=512)",
    SPD1_CAUSE,
)


def growth_exponent(mb: tuple[float, float, float]) -> float:
    """The exponent p of memory = c + a b^p through three memories at b, 2b, 4b, net of the constant c
    (whatever does not grow with b: the network, the framework): 2^p = (m4 - m2) / (m2 - m1). NaN
    when the memory does not grow at both steps (an allocator's rounding, not a growth)."""
    first, second = mb[1] - mb[0], mb[2] - mb[1]
    return math.log2(second / first) if first > 0 and second > 0 else math.nan


def memory_rule(v: dict) -> tuple:
    """spd-2's rule on its measured values: the growth exponent net of the constant, per route and device."""
    paper = growth_exponent(PAPER_MEMORY_MB)
    routes = [(f"{dev} {route}", v.get(f"p_{dev}_{route}")) for dev in ("cpu", "gpu") for route in ("naive", "structured")]
    shown = ", ".join(f"{name} {p:.2f}" if p is not None and math.isfinite(p) else f"{name} -" for name, p in routes)
    measured = (
        f"memory growth exponent over b=32/64/128 net of the constant: paper {paper:.2f}; here {shown} (CPU host memory "
        f"{v['cpu_naive_mb']} MB naive, {v['cpu_structured_mb']} MB structured, whose steps of a few MB beside a ~70 MB "
        "constant make its exponent noise; the structured routes are shown, not judged; '-': no growth at one step)"
    )
    naive = [p for name, p in routes if "naive" in name and p is not None and math.isfinite(p)]
    require(naive, what="table3 HIG naive-route memory at b=32/64/128")
    quadratic = all(p >= 1.5 for p in naive)
    return measured, quadratic, any(p >= 1.5 for p in naive), {"paper_exponent": paper, "naive_max": max(naive)}


def route_cell(df, b: int, route: str) -> float:
    """HIG's memory at b on one Jacobian route of table 3's measured frame (``cell`` reads the structured one)."""
    m = df[(df["Optimizer"].astype(str) == "HIG") & (df["Batch size"].astype(int) == b) & (df["Jacobian path"] == route)]
    return float(m["Memory (MB)"].iloc[0]) if len(m) else math.nan


PAPER_MEMORY_MB = tuple(PAPER_COSTS[("oscillator", "hig", b)][0] for b in (32, 64, 128))


@claim(
    "spd-2",
    "table3",
    "169 / 676 / 2640 MB at b=32/64/128; block-diagonal: linear",
    decide=memory_rule,
    cause=Cause(
        "hardware",
        "net of the memory that does not grow with b, the paper's memory grows as b to the {paper_exponent:.2f}; higbench's "
        "route that forms the whole Jacobian, as the paper's does, grows as b to at most {naive_max:.2f}: its memory is the "
        "Jacobian's, linear in b, not a quadratic term's, so the quadratic growth is the paper's implementation's and "
        "cannot be reproduced with this one (nor a linear route told from it)",
        {"the naive route grows less than quadratically": lambda v: v["naive_max"] < 1.5},
    ),
)
def memory(datas):
    """Oscillators (table 3, appendix B.2): HIG's memory grows about quadratically with the batch size in the paper's
    implementation, which forms the whole Jacobian; a block-diagonal one would scale linearly. Rule: net of the memory
    that does not grow with b, the growth exponent p (memory = c + a b^p through b=32, 64, 128) of higbench's route that
    forms the whole Jacobian, as the paper's, is at least 1.5 (about quadratic) on this CPU and on the committed GPU
    run (partly: on one); the total-memory ratio cannot tell (a constant of ~70 MB hides the growth)"""
    df = _table(datas, "table3")
    values = {}
    for route in ("naive", "structured"):
        mb = tuple(route_cell(df, b, route) for b in (32, 64, 128))
        if any(math.isnan(m) for m in mb):
            raise Missing(f"table3 HIG {route} memory at b=32/64/128")
        values[f"p_cpu_{route}"], values[f"cpu_{route}_mb"] = growth_exponent(mb), "/".join(f"{m:.0f}" for m in mb)
    gpu = ON_A_GPU()
    for route in ("naive", "structured"):
        if f"probe_mb_{route}_32" in gpu:
            values[f"p_gpu_{route}"] = growth_exponent(tuple(gpu[f"probe_mb_{route}_{b}"] for b in (32, 64, 128)))
    return values


ratio(
    "spd-3",
    "table4",
    64,
    64,
    "13.8 s vs 0.011 s",
    "Poisson: a HIG update costs about 1250 Adam updates (b=64)",
    hardware_ratio("table4"),
)
ratio(
    "spd-4",
    "table5",
    16,
    256,
    "0.60 s vs 0.40 s",
    "Dipole: a HIG update (b=16) costs about 1.5 Adam updates (b=256)",
    hardware_ratio("table5"),
)


def _table(datas, tid: str):
    """A table's measured frame: from the benchmark (a build) or its committed <id>.csv (``committed``)."""
    d = datas[tid]
    return d.frame if hasattr(d, "frame") else timing_frame(d)


@claim("spd-6", "table3", "0.081 s at b=256, 512, 1024")
def adam_time_flat(datas):
    """Oscillators (table 3): Adam's update time does not depend on the batch size. Rule: Adam's update time at b=1024
    within 2x of b=256's (partly: within 4x); a CPU's cost grows with the work, a GPU's hardly at these sizes"""
    df = _table(datas, "table3")
    t = {b: cell(df, "Adam", b, "Update duration (s)") for b in (256, 512, 1024)}
    if any(math.isnan(v) for v in t.values()):
        raise Missing("table3 Adam b=256/512/1024")
    growth = t[1024] / t[256]
    measured = "Adam update: " + ", ".join(f"b={b} {v:.3g} s" for b, v in t.items()) + f" ({growth:.2f}x); CPU"
    return measured, growth <= 2, growth <= 4, {"growth": growth}


@claim(
    "spd-7",
    "table3",
    "0.07 s at b=32, 64, 128",
    cause=Cause(
        "hardware",
        "on this CPU HIG's Jacobian time grows {cpu:.1f}x from b={b_lo} to b={b_hi}, on the committed GPU run "
        "{probe_jacobian_growth:.2f}x: a CPU's Jacobian cost grows with the work, a GPU's parallel one hardly at these sizes",
        {"the CPU's grows, the GPU's not": lambda v: v["cpu"] > 2 >= v["probe_jacobian_growth"]},
        probe=ON_A_GPU,
    ),
)
def jacobian_time_flat(datas):
    """Oscillators (table 3): HIG's Jacobian time does not depend on the batch size (0.07 s at b=32, 64, 128). Rule: HIG's
    Jacobian time at b=128 within 2x of b=32's on this CPU and on the committed GPU run (partly: on one)"""
    df = _table(datas, "table3")
    t32, t128 = cell(df, "HIG", 32, "Jacobian duration (s)"), cell(df, "HIG", 128, "Jacobian duration (s)")
    if math.isnan(t32) or math.isnan(t128) or t32 <= 0:
        raise Missing("table3 HIG b=32/128 Jacobian times")
    gpu = ON_A_GPU().get("probe_jacobian_growth")
    cpu = t128 / t32
    measured = f"HIG Jacobian b=128 / b=32: CPU {cpu:.2f}x" + (f", GPU {gpu:.2f}x" if gpu else ", GPU not run")
    values = {"cpu": cpu, "b_lo": 32, "b_hi": 128}
    return measured, cpu <= 2 and (gpu is None or gpu <= 2), cpu <= 2 or (gpu is not None and gpu <= 2), values


@claim(
    "spd-8",
    "table5",
    "Adam 0.40 / 0.50 / 1.33 s at b=256/512/1024",
    cause=Cause(
        "hardware",
        "Adam's update time grows {cpu:.1f}x from b={b_lo} to b={b_hi} on this CPU, as the paper's ({paper:.1f}x), and "
        "{probe_dipole_adam_growth:.2f}x on the committed GPU run: the growth is the device's, a GPU's cost hardly grows at "
        "these sizes",
        {"the CPU's grows, the GPU's not": lambda v: v["cpu"] >= 2 > v["probe_dipole_adam_growth"]},
        probe=ON_A_GPU,
    ),
)
def dipole_adam_time_grows(datas):
    """Dipole (table 5): Adam's update time grows with the batch size (0.40, 0.50, 1.33 s at b=256, 512, 1024). Rule:
    Adam's update time at b=1024 at least 2x b=256's on this CPU and on the committed GPU run (partly: on one)"""
    df = _table(datas, "table5")
    t = {b: cell(df, "Adam", b, "Update duration (s)") for b in (256, 1024)}
    if any(math.isnan(v) or v <= 0 for v in t.values()):
        raise Missing("table5 Adam b=256/1024")
    cpu, gpu = t[1024] / t[256], ON_A_GPU().get("probe_dipole_adam_growth")
    paper = PAPER_TIMINGS["table5"][("adam", 1024)][1] / PAPER_TIMINGS["table5"][("adam", 256)][1]
    measured = (
        f"Adam b=1024 / b=256: CPU {cpu:.2f}x" + (f", GPU {gpu:.2f}x" if gpu else ", GPU not run") + f"; paper {paper:.2f}x"
    )
    values = {"cpu": cpu, "paper": paper, "b_lo": 256, "b_hi": 1024}
    return measured, cpu >= 2 and (gpu is None or gpu >= 2), cpu >= 2 or (gpu is not None and gpu >= 2), values


@claim("spd-5", "table3", "O(|θ| b² |y|²); Jacobian ~ a backward pass")
def cost_scaling(datas):
    """Oscillators (§2.3, tables 3-5): a HIG update costs O(|θ| b² |y|²) and its Jacobian about a backward pass. Rule:
    HIG's update time grows at most quadratically from b=32 to 128 (<= 16x) and its Jacobian at b=128 takes at most
    10x Adam's whole update at b=512 (partly: one of the two)"""
    df = timing_frame(datas["table3"])
    t32, t128 = cell(df, "HIG", 32, "Update duration (s)"), cell(df, "HIG", 128, "Update duration (s)")
    jac, adam = cell(df, "HIG", 128, "Jacobian duration (s)"), cell(df, "Adam", 512, "Update duration (s)")
    if any(math.isnan(x) for x in (t32, t128, jac, adam)) or min(t32, adam) <= 0:
        raise Missing("table3 HIG b=32/128 update and Jacobian times, Adam b=512")
    growth, jac_ratio = t128 / t32, jac / adam
    measured = f"HIG update b=128 / b=32 {growth:.1f}x; Jacobian (b=128) / Adam update (b=512) {jac_ratio:.1f}x"
    return measured, growth <= 16 and jac_ratio <= 10, growth <= 16 or jac_ratio <= 10, {"growth": growth, "jac": jac_ratio}


# The paper's statements no row tests, and why (the report lists them under its table).
UNTESTED: list[tuple[str, str]] = [
    (
        "§2: Gauss-Newton's update steps in y-space are invariant under arbitrary rescaling of the parameters θ",
        "a property of the update's mathematics, not of a training run; it is checked on a 2-D quadratic whose second "
        "parameter is rescaled (scripts/scale_invariance.py, docs/scale-invariance.md, tests/test_scale_invariance.py): "
        "GN's step in y does not change with the scale, gradient descent's does",
    ),
    (
        "§2.3: a HIG update's cost grows quadratically with the dimension of y",
        "each problem here has one fixed |y|, and the committed benchmark varies the batch size only; no run or benchmark "
        "varies |y| at a fixed network and batch",
    ),
    (
        "§2.3: memory can be traded against time by parallelising the Jacobian computation only partly",
        "higbench computes the Jacobian in one vectorised pass per route (structured or whole J); it has no partly "
        "parallel route whose memory and time could be set against each other",
    ),
    (
        "Appendix B.4: Adam's small-η plateaus (fig. 8) differ in nature from HIG's start-up plateaus (fig. 9)",
        "a statement on the plateaus' causes (the framework's start-up against the optimizer), not a measurable "
        "quantity; what runs can show is counted elsewhere: dip-1 counts Adam's plateau in updates against HIG's, and "
        "cnn-3 leaves HIG's start-up out of its comparison",
    ),
    (
        "Appendix C: too little truncation (small τ) over-saturates neurons",
        "neuron statistics are logged for the toy problem only; the ablation's oscillator runs (fig. 13) do not log them",
    ),
    (
        "§2.3: overly large batch sizes make the Jacobian ill-conditioned and destabilise HIG's learning",
        "the paper names no batch size it calls overly large, and over the b=32-128 it runs (fig. 2c) it says HIG "
        "improves with b (osc-5); no HIG run here goes beyond b=128, so no run of fig. 2c can show the statement (the "
        "row that tested it read fig. 2c and demanded the opposite ordering to osc-5)",
    ),
    (
        "Table 1: the HIG update as a steepest descent in its combined metric",
        "a property of the update's mathematics, not of a run: no measurement of a run could contradict it",
    ),
    (
        "Appendix C, pure physics optimisation (no network): the oscillator stable over a large range of τ, the dipole "
        "worse or not converging at far smaller τ",
        "no network-free optimisation is run anywhere in higbench yet",
    ),
    (
        "§2.3: a HIG update's run time grows linearly with the number of network parameters",
        "the committed benchmark varies the batch size only (spd-5); no sweep over network sizes is committed",
    ),
    (
        "§2.3: HIG allows larger learning rates (η=1) than the gradient-descent family",
        "needs HIG's own η grid beside figs 5-6's at the same budget; fig2b runs HIG at η=1 only",
    ),
    (
        "Toy, γ=1: Adam fits ŷ(x) accurately",
        "needs the trained networks' predictions over x (the run files' weights), which the committed data do not hold",
    ),
    (
        "§3.3: the dipole's final losses differ less between the optimizers than in the other experiments",
        "the dipole's final losses sit at the float32 evaluation floor (dip-3), so their ratio only bounds, and ratios "
        "across problems run at different budgets and seeds compare the setups rather than the optimizers",
    ),
    (
        "Fig. 13: HIG's curves 'start to converge' over τ",
        "the text gives no measure of converging curves a run could fail; abl-3 tests HIG's stability over τ",
    ),
    (
        "CNN: the lower edge of τ 'in line with figure 9' (τ=1e-6 is the best CNN run here)",
        "the test would be dip-8's on fig11, and its cause needs a precision probe of the CNN (only the MLP dipole's is "
        "committed); not added yet",
    ),
    (
        "Tables 3-5's other entries: HIG's memory per b on a GPU, table 4's memory and Jacobian time, table 5's b=8 against b=16",
        "GPU memory is only measured in the committed GPU benchmark run (spd-2 quotes it); this CPU's resident memory is "
        "not the paper's quantity; the b=8/16 and table 4's Jacobian-time comparisons are not added yet (table 3's "
        "Jacobian time over b is spd-7, table 5's Adam time over b spd-8)",
    ),
]


def claims() -> dict[str, Claim]:
    """Every claim, in the report's order (declaration order above)."""
    return by_id(CLAIMS, "claim")
