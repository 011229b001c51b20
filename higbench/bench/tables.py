"""Tables 3-5 measured here: memory, update duration and Jacobian duration per optimizer and
batch size (oscillators, Poisson, dipole), beside the paper's (``higbench.bench.paper``).

Source, in this order:
1. the benchmark's ``<runs root>/bench/paper_tables.csv`` (``python -m higbench.bench.step
   --paper-tables --out <runs root>/bench``, also ``scripts/bench_step.py``: interleaved timing
   of single updates by phase, memory measured in fresh subprocesses); the figures run it
   when that file is missing (``ensure_bench``);
2. otherwise short timing runs (a budget in updates), read from their run files: median
   ``/updates/update_s`` and ``jacobian_s`` without the first (warm-up) update, and memory as
   the growth of the process's resident set over the run (``/memory`` peak_rss_mb -
   baseline_rss_mb; ``cuda_peak_mb`` on a GPU). CPU RSS is not the paper's GPU memory; the
   numbers are for comparison between rows.

Both the figures' tables and the claims on them (``higbench.paper.tables``) read a
table through ``timing_frame``; optimizers keep their
config names here ("adam", "hig").
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from higbench.bench.paper import PROBLEM_TABLES, costs_of_table

# (table, optimizer, batch size) -> paper's (memory MB, update s, Jacobian s); GPU, TensorFlow.
PROBLEMS = {f"table{n}": problem for problem, n in PROBLEM_TABLES.items()}
PAPER_TIMINGS = {tid: costs_of_table(tid) for tid in PROBLEMS}


def bench_file(runs_root: str | Path) -> Path:
    return Path(runs_root) / "bench" / "paper_tables.csv"


def ensure_bench(runs_root: str | Path, log=print) -> bool:
    """Run the benchmark (``higbench.bench.step --paper-tables``) if its table is missing."""
    import subprocess
    import sys
    import time

    target = bench_file(runs_root)
    if target.is_file():
        return True
    log(f"[figures] tables 3-5: running higbench.bench.step --paper-tables (minutes) -> {target.parent}")
    t0 = time.perf_counter()
    target.parent.mkdir(parents=True, exist_ok=True)
    with open(target.parent / "bench.log", "w") as out:
        cmd = [sys.executable, "-m", "higbench.bench.step", "--paper-tables", "--out", str(target.parent)]
        code = subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT).returncode
    ok = code == 0 and target.is_file()
    status = "done" if ok else f"failed (exit {code}, see {target.parent / 'bench.log'}); using timing runs"
    log(f"[figures] tables 3-5: benchmark {status} in {time.perf_counter() - t0:.0f} s")
    return ok


def _median_after_first(up: pd.DataFrame, col: str) -> float:
    v = up[col].to_numpy(dtype=float) if col in up else np.array([])
    v = v[1:] if len(v) > 1 else v
    return float(np.median(v)) if len(v) else math.nan


def _memory_mb(run) -> float:
    mem = run.meta.get("memory", {})
    if (cuda := float(mem.get("cuda_peak_mb", 0.0) or 0.0)) > 0:
        return cuda
    return float(mem.get("peak_rss_mb", math.nan)) - float(mem.get("baseline_rss_mb", math.nan))


def timing_frame(d) -> pd.DataFrame:
    """One row per (optimizer, batch size) of table ``d.figure.id``: measured and paper values;
    ``attrs``: its ``source`` and what its numbers are (``meaning``). ``d``: the table's figure
    data (its preset and its timing runs, ``d.runs(optimizer, batch_size=b)``)."""
    tid = d.figure.id
    if (bench := bench_file(d.preset.runs_root)).is_file():
        return bench_frame(pd.read_csv(bench), tid, str(bench))
    rows = []
    for (opt, b), paper in PAPER_TIMINGS[tid].items():
        row = {"Optimizer": opt, "Batch size": b}
        if runs := d.runs(opt, batch_size=b) or (d.runs(opt) if d.preset.name == "smoke" else []):
            r, up = runs[0], runs[0].updates
            row |= {
                "Batch size": int(r.cfg("batch_size")),
                "Memory (MB)": _memory_mb(r),
                "Update duration (s)": _median_after_first(up, "update_s"),
                "Jacobian duration (s)": _median_after_first(up, "jacobian_s"),
                "updates timed": max(0, len(up) - 1),
            }
        rows.append(row | dict(zip(("paper: memory (MB)", "paper: update (s)", "paper: Jacobian (s)"), paper)))
    df = pd.DataFrame(rows).drop_duplicates(subset=["Optimizer", "Batch size"])
    df.attrs["source"] = "timing runs of this tool (run files)"
    df.attrs["meaning"] = (
        "memory: growth of the process's resident set during the run (CPU), not GPU memory; durations: median "
        "over the timed updates, first (warm-up) update left out"
    )
    return df


def bench_frame(raw: pd.DataFrame, tid: str, source: str) -> pd.DataFrame:
    """The benchmark's rows of one table in ``timing_frame``'s layout."""
    sub = raw[raw["table"] == int(tid[-1])]
    cols = {
        "Jacobian path": "jacobian",
        "solver": "solver",
        "Memory (MB)": "peak_mem_mb",
        "Update duration (s)": "update_s",
        "Jacobian duration (s)": "jacobian_s",
        "Inversion duration (s)": "inversion_s",
        "paper: memory (MB)": "paper_mem_mb",
        "paper: update (s)": "paper_update_s",
        "paper: Jacobian (s)": "paper_jacobian_s",
    }
    out = pd.DataFrame(
        {"Optimizer": sub["optimizer"], "Batch size": sub["batch_size"].astype(int)}
        | {k: sub.get(v, "-" if k in ("Jacobian path", "solver") else None) for k, v in cols.items()}
    )
    main = out["Jacobian path"].isin(["-", "structured"])
    out = pd.concat([out[main], out[~main]]).reset_index(drop=True)  # the paper's rows first, then the naive path
    threads = ", ".join(sorted(set(sub["threads"].astype(str)))) if "threads" in sub else "?"
    out.attrs["source"] = f"{source} (scripts/bench_step.py --paper-tables; threads {threads})"
    out.attrs["meaning"] = (
        "memory: extra resident host memory of one update (fresh process), not GPU memory; durations: medians of "
        "interleaved single updates (see scripts/bench_step.py)"
    )
    return out


def cell(df: pd.DataFrame, opt: str, b: int, col: str) -> float:
    """One measured value of a ``timing_frame`` (the paper's Jacobian path; NaN if absent)."""
    m = df[(df["Optimizer"].astype(str).str.lower() == opt.lower()) & (df["Batch size"].astype(int) == b)]
    if "Jacobian path" in df.columns:
        m = m[m["Jacobian path"].isin(["-", "structured"])]
    return float(m[col].iloc[0]) if len(m) and col in m else math.nan
