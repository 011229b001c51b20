"""Tables 2-5.

table2: the hyper-parameters of figure 2b, read from the configs of the runs that drew it
(the same runs), next to the paper's values (conf/problem_optimizer/oscillator_*.yaml).

table3/4/5: memory, update duration and Jacobian duration per optimizer and batch size
(oscillators, Poisson, dipole), from the benchmark's table or, without it, from short timing
runs declared here (``higbench.bench.tables`` reads either).
"""

from __future__ import annotations

import pandas as pd

from higbench.bench.tables import PAPER_TIMINGS, PROBLEMS, bench_file, timing_frame
from higbench.display import OPTIMIZER_NAMES, num
from higbench.figures.data import FigureData
from higbench.figures.oscillator import FIG2B, FIG2B_OPTIMIZERS
from higbench.figures.spec import Budget, Figure, PerPreset, Preset, Sweep, paper_setting

TITLES = {
    t: f"{p}: memory, update duration and Jacobian duration for Adam and HIG"
    for t, p in (("table3", "Nonlinear oscillators"), ("table4", "Poisson problem"), ("table5", "Quantum dipole"))
}
# Timing runs: a budget in updates (the first one, with warm-up, is left out of the medians).
TIMING = {
    "table3": {"adam": {"paper": 200, "quick": 20, "smoke": 2}, "hig": {"paper": 100, "quick": 10, "smoke": 2}},
    "table4": {"adam": {"paper": 200, "quick": 20, "smoke": 2}, "hig": {"paper": 10, "quick": 2, "smoke": 2}},
    "table5": {"adam": {"paper": 50, "quick": 6, "smoke": 2}, "hig": {"paper": 50, "quick": 6, "smoke": 2}},
}
SMOKE_BATCH = {"table4": {"hig": 8}}  # smoke: the b=64 Poisson HIG update takes about a minute on 2 cores


def paper_table2(opt: str) -> str:
    """'512 / 3e-4 / -': the paper's b / eta / tau (GN has no eta; only GN and HIG have a tau)."""
    pair = f"oscillator_{opt}"
    lr = "-" if opt == "gn" else num(paper_setting(pair, "optimizer.lr"))
    tau = num(paper_setting(pair, "optimizer.tau")) if opt in ("gn", "hig") else "-"
    return f"{paper_setting(pair, 'batch_size')} / {lr} / {tau}"


def plot_table2(d: FigureData) -> None:
    cols = {}
    for opt in FIG2B_OPTIMIZERS:
        cols[OPTIMIZER_NAMES[opt]] = ["?", "?", "?", "-", "missing", paper_table2(opt)]
        if runs := d.runs("best", optimizer__name=opt):
            r = runs[0]
            lr = "-" if opt == "gn" else num(r.cfg("optimizer.lr"))
            tau = num(r.cfg("optimizer.tau")) if opt in ("gn", "hig") else "-"
            cols[OPTIMIZER_NAMES[opt]][:5] = [str(r.cfg("batch_size")), lr, tau, f"{r.final_loss:.2e}", r.status]
    table = pd.DataFrame(cols, index=["b", "η", "τ", "final test loss", "status", "paper: b / η / τ"])
    table.index.name = "Method"
    d.write_table(table, title="Hyper-parameters of the figure 2b runs (read from their run files)")


# -- tables 3-5 -----------------------------------------------------------------------------


def timing_runs(tid: str):
    def runs(p: Preset) -> list[Sweep]:
        if bench_file(p.runs_root).is_file():
            return []  # the benchmark script's table is used
        out = []
        for opt in ("adam", "hig"):
            batches = sorted({b for (o, b) in PAPER_TIMINGS[tid] if o == opt})
            small = [SMOKE_BATCH[tid][opt]] if opt in SMOKE_BATCH.get(tid, {}) else batches[:1]
            fixed = {"problem": PROBLEMS[tid], "optimizer": opt}
            out.append(Sweep(opt, fixed, Budget(updates=TIMING[tid][opt]), grid={"batch_size": PerPreset(batches, smoke=small)}))
        return out

    return runs


def plot_timing(d: FigureData) -> None:
    df = timing_frame(d)
    d.notes += [f"source: {df.attrs['source']}", df.attrs["meaning"]]
    df["Optimizer"] = df["Optimizer"].map(lambda o: OPTIMIZER_NAMES.get(o, o))
    d.write_table(df, index=False, title=TITLES[d.figure.id])


FIGURES = [
    Figure("table2", "Hyper-parameters of the optimizers in figure 2b (from the run configs)", FIG2B, plot_table2, kind="table"),
    *(Figure(t, TITLES[t], timing_runs(t), plot_timing, kind="table") for t in TITLES),
]
