"""Figures 2a-c, 5, 6: control of two coupled nonlinear oscillators (paper 3.1, appendix B.2).

fig2b's runs use the per-pair paper defaults (conf/problem_optimizer/oscillator_*.yaml,
the hyper-parameters of table 2); table 2 is generated from the configs of these runs.
"""

from __future__ import annotations

import numpy as np

from higbench.figures import checks
from higbench.figures.checks import crossing_time, e, final, verdict
from higbench.figures.data import COLORS, OPTIMIZER_NAMES, FigureData, legend, new_figure, num, semilogy_axes
from higbench.figures.registry import Claim, claim, register
from higbench.figures.spec import Budget, Figure, Preset, SeedSearch, Sweep

FIG2B_OPTIMIZERS = ("adadelta", "adagrad", "adam", "gn", "hig", "rmsprop", "sgd")
GD_FAMILY = ("adadelta", "adagrad", "adam", "rmsprop", "sgd")
MAIN = Budget(seconds={"paper": 3600, "quick": 120, "standard": 240})
GRID = Budget(seconds={"paper": 3600, "quick": 12, "standard": 15})
FIG2C_BATCHES = {"adam": [256, 512, 1024], "gn": [32, 64, 128], "hig": [32, 64, 128]}
FIG5_LRS = {"adadelta": [0.01, 0.1, 1.0], "adagrad": [0.01, 0.1, 1.0], "sgd": [0.01, 0.1, 1.0], "rmsprop": [1e-5, 1e-4, 1e-3]}
FIG6_LRS = [3e-5, 3e-4, 3e-3]
GRID_BATCHES = [256, 512, 1024]
# GN from a fresh initialisation takes a first step far larger than the weights for most
# seeds (NaN or a loss 14-600x higher); the authors show GN's "best stable run" of one
# fixed seed, so GN's runs here use the best stable seed of a short search.
GN_SEARCH_BUDGET = Budget(seconds={"paper": 60, "quick": 15, "standard": 15})


def gn_search(p: Preset, **overrides) -> SeedSearch:
    return SeedSearch(p.pick(paper=list(range(8)), smoke=[0, 1]), GN_SEARCH_BUDGET, dict(overrides))


def fig2b_runs(p: Preset) -> list[Sweep]:
    others = [o for o in FIG2B_OPTIMIZERS if o != "gn"]
    return [
        Sweep("best", {"problem": "oscillator"}, MAIN, grid={"optimizer": others}),
        Sweep("best", {"problem": "oscillator", "optimizer": "gn"}, MAIN, seed_search=gn_search(p)),
        # Fair baseline: Adam re-tuned at the same budget (its cost per update hardly grows with b).
        Sweep(
            "adam_tuned",
            {"problem": "oscillator", "optimizer": "adam"},
            MAIN,
            grid={
                "optimizer.lr": p.pick(paper=[1e-4, 1e-3, 3e-3], quick=[1e-3, 3e-3], smoke=[1e-3]),
                "batch_size": p.pick(paper=[512, 2048], quick=[2048]),
            },
        ),
    ]


def tuned_adam(d: FigureData) -> tuple[float, str]:
    """(final loss, label) of the best re-tuned Adam run of fig2b (median over seeds per setting)."""
    best = (float("inf"), "not run")
    for lr in sorted({j.overrides["optimizer.lr"] for j in d.jobs if j.sweep == "adam_tuned"}):
        for b in sorted({j.overrides["batch_size"] for j in d.jobs if j.sweep == "adam_tuned"}):
            runs = d.runs("adam_tuned", optimizer__lr=lr, batch_size=b)
            if runs and final(runs) < best[0]:
                best = (final(runs), f"η={num(lr)} b={b}")
    return best


def fig2a_runs(p: Preset) -> list[Sweep]:
    return [Sweep("hig", {"problem": "oscillator", "optimizer": "hig"}, MAIN)]  # = fig2b's HIG run


def fig2c_runs(p: Preset) -> list[Sweep]:
    return [
        Sweep(
            opt,
            {"problem": "oscillator", "optimizer": opt},
            MAIN,
            grid={"batch_size": p.pick(paper=bs, quick=bs[::2] if opt == "gn" else bs, smoke=bs[:2])},
            seed_search=gn_search(p) if opt == "gn" else None,
        )
        for opt, bs in FIG2C_BATCHES.items()
    ]


def fig5_runs(p: Preset) -> list[Sweep]:
    return [
        Sweep(
            opt,
            {"problem": "oscillator", "optimizer": opt},
            GRID,
            grid={
                "optimizer.lr": p.pick(paper=lrs, smoke=lrs[1:2]),
                "batch_size": p.pick(paper=GRID_BATCHES, quick=[256, 1024], smoke=[512]),
            },
        )
        for opt, lrs in FIG5_LRS.items()
    ]


def fig6_runs(p: Preset) -> list[Sweep]:
    return [
        Sweep(
            "adam",
            {"problem": "oscillator", "optimizer": "adam"},
            GRID,
            grid={
                "optimizer.lr": p.pick(paper=FIG6_LRS, smoke=FIG6_LRS[:2]),
                "batch_size": p.pick(paper=GRID_BATCHES, quick=[256, 1024], smoke=[512]),
            },
        )
    ]


# -- plots ----------------------------------------------------------------------------------


def plot_fig2a(d: FigureData) -> None:
    import torch

    fig, axes = new_figure(1, 1, width=6.5, height=3.6)
    ax = axes[0, 0]
    runs = d.runs("hig")
    if runs:
        run = runs[0]
        problem, model = run.build_model()
        batch = problem.test_set()[:1]
        states, u = problem.trajectory(model, batch)
        states, u = states[0].double().numpy(), u[0].double().numpy()
        dt = float(problem.cfg.dt)
        t = np.arange(states.shape[0]) * dt
        tu = (np.arange(len(u)) + 0.5) * dt
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
        ax.set_title(f"a) oscillators under the HIG-trained network ({run.label()}); final squared error {e(err)}", fontsize=8)
        ax.plot([], [], "o", color="k", mfc="none", label="targets (= initial state)")
        legend(ax, loc="upper left")
    else:
        legend(ax)
    ax.set_xlabel("time t")
    ax.set_ylabel("oscillator position")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    d.save(fig)


def plot_fig2b(d: FigureData) -> None:
    fig, axes = new_figure(1, 1, width=6.4, height=4.2)
    ax = axes[0, 0]
    for opt in FIG2B_OPTIMIZERS:
        runs = d.runs("best", optimizer__name=opt)
        if runs:
            d.curve(ax, runs, runs[0].label(), panel="loss", color=COLORS[opt])
    semilogy_axes(ax)
    ax.set_title("b) oscillators: best run per optimizer (table 2 settings)", fontsize=9)
    legend(ax, ncol=2)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    d.save(fig)


def plot_fig2c(d: FigureData) -> None:
    fig, axes = new_figure(1, 1, width=6.4, height=4.2)
    ax = axes[0, 0]
    styles = ["-", "--", ":"]
    for opt, bs in FIG2C_BATCHES.items():
        for i, b in enumerate(bs):
            runs = d.runs(opt, batch_size=b)
            if runs:
                d.curve(ax, runs, runs[0].label(), panel="loss", color=COLORS[opt], ls=styles[i % 3])
    semilogy_axes(ax)
    ax.set_title("c) oscillators: Adam, GN, HIG for several batch sizes b", fontsize=9)
    legend(ax, ncol=3)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    d.save(fig)


def plot_grid(d: FigureData, rows: dict[str, list[float]], batches: list[int], prefix: str = "") -> None:
    """One row per optimizer, one column per learning rate, one line per batch size."""
    ncols = max(len(v) for v in rows.values())
    fig, axes = new_figure(ncols, len(rows), width=3.6, height=2.7, sharey=True)
    cmap = {b: c for b, c in zip(sorted(batches), ("tab:blue", "tab:orange", "tab:green", "tab:red"))}
    for r, (opt, lrs) in enumerate(rows.items()):
        for c, lr in enumerate(lrs):
            ax = axes[r, c]
            for b in batches:
                runs = d.runs(opt, optimizer__lr=lr, batch_size=b)
                if runs:
                    d.curve(ax, runs, f"b={b}", panel=f"{opt} η={num(lr)}", color=cmap[b])
            semilogy_axes(ax, xlabel="wall-clock time [s]" if r == len(rows) - 1 else "", ylabel="test loss" if c == 0 else "")
            ax.set_title(f"{prefix}{OPTIMIZER_NAMES[opt]} η={num(lr)}", fontsize=9)
            legend(ax)
        for c in range(len(lrs), ncols):
            axes[r, c].axis("off")
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    d.save(fig)


def _grid_axes(d: FigureData, opts) -> tuple[dict[str, list[float]], list[int]]:
    rows = {}
    batches: set[int] = set()
    for opt in opts:
        jobs = [j for j in d.jobs if j.sweep == opt]
        rows[opt] = sorted({j.overrides["optimizer.lr"] for j in jobs})
        batches |= {j.overrides["batch_size"] for j in jobs}
    return rows, sorted(batches)


def plot_fig5(d: FigureData) -> None:
    rows, batches = _grid_axes(d, FIG5_LRS)
    plot_grid(d, rows, batches, prefix="")


def plot_fig6(d: FigureData) -> None:
    rows, batches = _grid_axes(d, ["adam"])
    plot_grid(d, rows, batches)


register(
    Figure(
        "fig2a",
        "Oscillators: time evolution under a HIG-trained network, control signal behind it",
        fig2a_runs,
        plot_fig2a,
        family="oscillator",
    )
)
register(
    Figure(
        "fig2b", "Oscillators: loss over wall-clock time, best run of each optimizer", fig2b_runs, plot_fig2b, family="oscillator"
    )
)
register(Figure("fig2c", "Oscillators: Adam, GN and HIG for several batch sizes", fig2c_runs, plot_fig2c, family="oscillator"))
register(
    Figure(
        "fig5",
        "Oscillators: Adadelta, Adagrad, SGD, RMSprop for several learning rates and batch sizes",
        fig5_runs,
        plot_fig5,
        family="oscillator",
    )
)
register(
    Figure("fig6", "Oscillators: Adam for several learning rates and batch sizes", fig6_runs, plot_fig6, family="oscillator")
)


# -- claims ---------------------------------------------------------------------------------


def _finals(d: FigureData) -> dict[str, float]:
    return {o: final(d.runs("best", optimizer__name=o)) for o in FIG2B_OPTIMIZERS if d.runs("best", optimizer__name=o)}


def check_adam(datas):
    f = _finals(datas["fig2b"])
    gd = {o: f[o] for o in GD_FAMILY if o in f}
    if "adam" not in gd:
        return checks.na("fig2b Adam")
    best = min(gd, key=gd.get)
    level = 1e-5 <= gd["adam"] <= 1e-3
    measured = f"Adam {e(gd['adam'])}; best of the GD family: {OPTIMIZER_NAMES[best]} ({e(gd[best])})"
    return (
        measured,
        verdict(best == "adam" and level, best == "adam" or level),
        "rule: Adam best of SGD/Adagrad/Adadelta/RMSprop/Adam and final loss in [1e-5, 1e-3] (partly: one of the two)",
    )


def check_gn(datas):
    f = _finals(datas["fig2b"])
    runs = datas["fig2b"].runs("best", optimizer__name="gn")
    if "gn" not in f or "adam" not in f:
        return checks.na("fig2b GN/Adam")
    status = runs[0].status
    level = 1e-7 <= f["gn"] <= 1e-5 and status == "completed"
    search = gn_search_summary(datas["fig2b"], "best/search")
    return (
        f"GN {e(f['gn'])} ({status}, seed {runs[0].seed}); Adam {e(f['adam'])}; seed search: {search}",
        verdict(level, f["gn"] < f["adam"]),
        "rule: GN's best stable run (best seed of the search) ends in [1e-7, 1e-5] without diverging (partly: below Adam's)",
    )


def gn_search_summary(d: FigureData, sweep: str) -> str:
    """Share of the searched seeds whose GN run diverged (NaN) or ended above its initial loss."""
    runs = d.runs(sweep)
    if not runs:
        return "not run"
    diverged = sum(r.status == "diverged" for r in runs)
    rose = sum(r.status == "completed" and not (r.final_loss < r.initial_loss) for r in runs)
    budget = checks.budget_of(runs[0])
    return (
        f"{len(runs)} seeds x {budget}: {diverged}/{len(runs)} diverged ({diverged / len(runs):.0%}), {rose} ended above "
        f"their initial loss, {len(runs) - diverged - rose} stable"
    )


def check_hig(datas):
    d = datas["fig2b"]
    f = _finals(d)
    if "hig" not in f:
        return checks.na("fig2b HIG")
    ft, tlabel = tuned_adam(d)
    if ft < float("inf"):
        f["adam (re-tuned)"] = ft
    best = min(f, key=f.get)
    level = 1e-8 <= f["hig"] <= 1e-6
    adv = f"HIG's advantage: {f['adam'] / f['hig']:.1f}x over Adam (paper setting)" if "adam" in f else ""
    if ft < float("inf"):
        adv += f", {ft / f['hig']:.1f}x over re-tuned Adam ({tlabel}: {e(ft)})"
    return (
        f"HIG {e(f['hig'])}; lowest of all: {OPTIMIZER_NAMES.get(best, best)} ({e(f[best])}); {adv}",
        verdict(level and best == "hig", level or best == "hig"),
        "rule: HIG's final loss in [1e-8, 1e-6] and the lowest of the seven and of re-tuned Adam (partly: one of the two)",
    )


def check_crossing(datas):
    d = datas["fig2b"]
    hig, adam = d.runs("best", optimizer__name="hig"), d.runs("best", optimizer__name="adam")
    if not hig or not adam:
        return checks.na("fig2b HIG/Adam")
    tuned = [r for r in d.runs("adam_tuned")]
    t_tuned = [crossing_time(hig[0], r) for r in tuned]
    tuned_text = ""
    if tuned:
        never = sum(x is None for x in t_tuned)
        late = max((x for x in t_tuned if x is not None), default=None)
        tuned_text = f"; against re-tuned Adam ({len(tuned)} settings): HIG never passes {never}" + (
            f", passes the others by t = {late:.0f} s" if late is not None else ""
        )
    t = crossing_time(hig[0], adam[0])
    if t is None:
        return (
            "HIG does not pass Adam within the budget" + tuned_text,
            checks.NOT,
            "rule: HIG stays below Adam from a time in [60, 540] s on (partly: from any time on)",
        )
    return (
        f"HIG below Adam (paper setting) from t = {t:.0f} s on" + tuned_text,
        verdict(60 <= t <= 540, True),
        "rule: HIG stays below Adam from a time in [60, 540] s on (partly: from any time on)",
    )


def check_batch(datas):
    d = datas["fig2c"]
    fin = {(o, b): final(d.runs(o, batch_size=b)) for o, bs in FIG2C_BATCHES.items() for b in bs if d.runs(o, batch_size=b)}
    adam = [fin[("adam", b)] for b in FIG2C_BATCHES["adam"] if ("adam", b) in fin]
    if len(adam) < 2 or not any(k[0] == "hig" for k in fin):
        return checks.na("fig2c")
    spread = max(adam) / min(adam)
    ends = {}
    for o in ("hig", "gn"):
        bs = [b for b in FIG2C_BATCHES[o] if (o, b) in fin]
        if len(bs) >= 2:
            ends[o] = (bs[0], bs[-1])
    improves = {o: fin[(o, hi)] < fin[(o, lo)] for o, (lo, hi) in ends.items()}
    measured = f"Adam max/min over b: {spread:.1f}x; " + ", ".join(
        f"{OPTIMIZER_NAMES[o]} b={lo}->{hi}: {e(fin[(o, lo)])}->{e(fin[(o, hi)])}" for o, (lo, hi) in ends.items()
    )
    full = spread < 3 and all(improves.values()) and len(improves) == 2
    part = spread < 3 or any(improves.values())
    return (
        measured,
        verdict(full, part),
        (
            "rule: Adam's final losses within 3x over b, and HIG and GN lower at the largest b than at the smallest "
            "(partly: one of these)"
        ),
    )


claim(
    Claim(
        "osc-1",
        ("fig2b",),
        "Oscillators: Adam is the best of the gradient-descent family, final loss ~1e-4",
        "Adam ~1e-4",
        check_adam,
    )
)
claim(Claim("osc-2", ("fig2b",), "Oscillators: GN's best stable run reaches ~1e-6", "GN ~1e-6", check_gn))
claim(Claim("osc-3", ("fig2b",), "Oscillators: HIG gives the best result, ~1e-7", "HIG ~1e-7", check_hig))
claim(Claim("osc-4", ("fig2b",), "Oscillators: HIG passes Adam after about three minutes", "~180 s", check_crossing))
claim(
    Claim(
        "osc-5",
        ("fig2c",),
        "Oscillators: Adam's runs converge alike for all b; HIG and GN improve with larger b",
        "Adam ~b-independent; HIG/GN better at larger b",
        check_batch,
    )
)


# -- beside the authors' code ---------------------------------------------------------------


def ref_runs(p: Preset) -> list[Sweep]:
    # = fig2b's Adam, HIG and GN runs (table-2 settings, the reference's settings)
    return [
        *(Sweep(opt, {"problem": "oscillator", "optimizer": opt}, MAIN) for opt in ("adam", "hig")),
        Sweep("gn", {"problem": "oscillator", "optimizer": "gn"}, MAIN, seed_search=gn_search(p)),
    ]


def reference_rows(d: FigureData) -> list[dict]:
    """Reference points with higbench's loss at the same training time (median over seeds)."""
    from higbench.figures.reference import OSCILLATOR_CURVES

    rows = []
    for opt, ref in OSCILLATOR_CURVES.items():
        runs = d.runs(opt)
        for t, loss in ref["points"]:
            ours = None
            if runs and all(t <= float(r.curves["wall_time"].iloc[-1]) for r in runs):
                ours = checks.median([checks.loss_at(r, t) for r in runs])
            rows.append({"optimizer": opt, "t": t, "reference": loss, "higbench": ours})
    return rows


def plot_reference(d: FigureData) -> None:
    from higbench.figures.reference import OSCILLATOR_CURVES, SOURCE, UPDATE_SECONDS

    fig, axes = new_figure(1, 1, width=6.4, height=4.2)
    ax = axes[0, 0]
    for opt, ref in OSCILLATOR_CURVES.items():
        runs = d.runs(opt)
        if runs:
            d.curve(ax, runs, f"higbench {runs[0].label()}", panel="loss", color=COLORS[opt])
        t, y = zip(*ref["points"])
        ax.plot(t, y, "o--", color=COLORS[opt], mfc="none", label=f"authors' TF code {OPTIMIZER_NAMES[opt]} ({ref['note']})")
        d.record("loss", f"reference {opt}", None, "wall_time", t, "test_loss", y)
    semilogy_axes(ax)
    ax.set_title("oscillators: higbench beside the authors' TensorFlow code (same settings, 2 CPU cores)", fontsize=8)
    legend(ax)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    d.save(fig)
    ours = {}
    for opt in ("adam", "hig", "gn"):
        runs = d.runs(opt)
        if runs and "update_s" in runs[0].updates:
            ours[opt] = checks.median([float(r.updates["update_s"].iloc[1:].median()) for r in runs])
    d.sidecar["reference"] = {
        "source": SOURCE,
        "loss_points": reference_rows(d),
        "update_seconds": [
            {**row, "higbench_update_s": ours.get(row["optimizer"]) if row["problem"] == "oscillator" else None}
            for row in UPDATE_SECONDS
        ],
    }


register(
    Figure(
        "ref_oscillator",
        "Oscillators: higbench's Adam and HIG curves beside the authors' TensorFlow code on the same CPU kind",
        ref_runs,
        plot_reference,
        family="oscillator",
    )
)
