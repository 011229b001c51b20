"""What recording the spectrum of a GN/HIG/LM step costs, against the step itself.

    python -m higbench.bench.spectrum_cost                       # oscillator hig b=128, poisson hig b=16
    python -m higbench.bench.spectrum_cost --config poisson:hig:64 --repeats 3

The singular values come out of the inversion anyway; what recording them adds is, per
update, the optimizer's ``_record_spectrum`` (a NumPy view of s, its largest value, the
smallest kept, the count dropped), ``sinks.spectrum_columns`` and the run-file sink taking
three more values; at each evaluation, ``sinks.spectrum_quantiles`` and writing the three
extra ``/updates`` columns (spread over the updates between two evaluations: the
problem's ``eval_every`` seconds over the update's time, at least 1).

For each configuration, in one process: the update (``bench.step.Runner``: fixed weights,
fixed batch; median over ``--repeats``) and each piece of that work on the update's own
singular values (the best of several batches of calls: the least disturbed by other
processes). Prints one JSON object per configuration; ``share`` is the spectrum's time per
update over the update's.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from higbench.bench.step import Config, Runner, compose
from higbench.runfile.reader import RUN_FILE
from higbench.runfile.writer import RunFileWriter
from higbench.runner.sinks import RunFileSink, spectrum_columns, spectrum_quantiles


def best_time(fn, calls: int, batches: int = 5) -> float:
    """Seconds per call of ``fn()``: the fastest of ``batches`` batches of ``calls`` calls."""
    best = float("inf")
    for _ in range(batches):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - t0) / calls)
    return best


def capture_spectrum(run: Runner) -> tuple[torch.Tensor, torch.Tensor]:
    """(s, keep) as the inversion hands them to the optimizer, from one update."""
    opt, seen = run.update.optimizer, {}
    record = opt._record_spectrum

    def capture(s: torch.Tensor, keep: torch.Tensor) -> None:
        seen["args"] = (s.clone(), keep.clone())
        record(s, keep)

    opt._record_spectrum = capture
    try:
        run()
    finally:
        del opt._record_spectrum  # the class's method again
    return seen["args"]


def write_cost(rows: int, calls: int = 20) -> float:
    """Seconds to append ``rows`` rows of the three spectrum columns to a run file's /updates
    (what a flush writes for them; the flush itself happens at every evaluation anyway)."""
    with tempfile.TemporaryDirectory() as tmp:
        writer = RunFileWriter(Path(tmp) / RUN_FILE, "{}", [], env={}, meta={})
        columns = {name: np.full(rows, 1.0) for name in ("sv_max", "sv_min_kept", "sv_dropped")}
        try:
            return best_time(lambda: writer.append_rows("updates", columns), calls)
        finally:
            writer.close("completed")


def measure(cfg: Config, repeats: int, warmup: int) -> dict:
    run = Runner(cfg, torch.float32)
    for _ in range(warmup):
        run()
    updates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        run()
        updates.append(time.perf_counter() - t0)
    update_s = statistics.median(updates)
    s, keep = capture_spectrum(run)
    opt = run.update.optimizer
    spectrum = dict(opt.last_spectrum)
    sink = RunFileSink(writer=None)
    row = spectrum_columns(spectrum)
    eval_every = float(compose(cfg).eval_every)  # seconds of training clock (the problem's default)
    per_eval = max(1, round(eval_every / update_s))
    pieces = {
        "record_s": best_time(lambda: opt._record_spectrum(s, keep), 200),
        "columns_s": best_time(lambda: spectrum_columns(spectrum), 2000),
        "sink_s": best_time(lambda: sink.on_update(row), 2000),
        "quantiles_s": best_time(lambda: spectrum_quantiles(spectrum), 200) / per_eval,
        "write_s": write_cost(per_eval) / per_eval,
    }
    total = sum(pieces.values())
    return {
        "config": cfg.label(),
        "singular_values": int(s.numel()),
        "update_s": update_s,
        **pieces,
        "updates_per_eval": per_eval,
        "spectrum_s": total,
        "share": total / update_s,
        "repeats": repeats,
        "threads": torch.get_num_threads(),
        "load": os.getloadavg()[0],
    }


def parse_config(text: str) -> Config:
    problem, optimizer, b = text.split(":")
    return Config(problem, optimizer, int(b), "structured", "auto")


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m higbench.bench.spectrum_cost", description=__doc__.splitlines()[0])
    p.add_argument("--config", nargs="+", default=["oscillator:hig:128", "poisson:hig:16"], metavar="PROBLEM:OPTIMIZER:B")
    p.add_argument("--repeats", type=int, default=20, help="timed updates per configuration (median)")
    p.add_argument("--warmup", type=int, default=2)
    p.add_argument("--threads", type=int, default=1)
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    for text in args.config:
        print(json.dumps(measure(parse_config(text), args.repeats, args.warmup)), flush=True)


if __name__ == "__main__":
    main()
