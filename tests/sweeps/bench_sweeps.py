"""Benchmarks behind docs/sweeps.md (a script, not a test; run it on a quiet machine).

    python tests/sweeps/bench_sweeps.py sweep [--updates 2000] [--optimizer adam]
    python tests/sweeps/bench_sweeps.py index [--files 1000]

sweep: wall time of `higbench -m +experiment=toy_lr_grid` (4 jobs, a fixed number of updates
each) through the basic launcher (sequential; torch's default threads, and threads=1) and
through joblib with 2 workers (threads=1, higbench's default); prints the speed-up.
index: writes N small synthetic run files with RunFileWriter, then times load_runs.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
sys.path[:0] = [str(REPO), str(HERE.parent)]  # tests/: synthetic.py


def sweep(updates: int, optimizer: str, repeats: int, only: list[str] | None) -> None:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.pop(var, None)
    base = ["-m", "+experiment=toy_lr_grid", f"optimizer={optimizer}", "budget.seconds=null", f"budget.max_updates={updates}",
            "eval_unit=updates", f"eval_every={max(updates // 4, 1)}", "progress=false"]  # fmt: skip
    variants = {
        "basic (sequential)": ["threads=null"],
        "basic, threads=1": ["threads=1"],
        "joblib n_jobs=2": ["hydra/launcher=joblib", "hydra.launcher.n_jobs=2"],
    }
    if only:
        short = {"basic (sequential)": "basic", "basic, threads=1": "basic1", "joblib n_jobs=2": "joblib"}
        variants = {k: v for k, v in variants.items() if short[k] in only}
    times: dict[str, list[float]] = {k: [] for k in variants}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(repeats):
            for name, extra in variants.items():
                out = Path(tmp) / f"{r}_{list(variants).index(name)}"
                t = time.perf_counter()
                cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
                proc = subprocess.run(
                    [sys.executable, "-m", "higbench.cli", *base, *extra, f"hydra.sweep.dir={out}"],
                    env=env,
                    cwd=tmp,
                    capture_output=True,
                    text=True,
                )
                times[name].append(time.perf_counter() - t)
                cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
                cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
                if proc.returncode != 0:
                    sys.exit(f"{name} failed:\n{proc.stderr[-2000:]}")
                from higbench.results import load_runs

                runs = load_runs(out)
                assert len(runs) == 4 and set(runs["status"]) == {"completed"}, runs[["path", "status"]]
                clocks = runs["train_time_s"].sum()
                threads = sorted(set(runs["env.torch_threads"]))
                print(
                    f"  {name:20s} {times[name][-1]:6.2f} s  cpu {cpu:6.2f} s ({cpu / times[name][-1]:.2f} cores)"
                    f"  sum of run clocks {clocks:6.2f} s, torch threads {threads}, load {os.getloadavg()[0]:.2f}",
                    flush=True,
                )
    best = {k: min(v) for k, v in times.items()}
    print(f"cores: {os.cpu_count()}, load average now: {os.getloadavg()}")
    for k, v in best.items():
        print(f"{k:20s} best of {repeats}: {v:6.2f} s")
    joblib_s = best.get("joblib n_jobs=2")
    for name in ("basic (sequential)", "basic, threads=1"):
        if joblib_s and name in best:
            print(f"speed-up joblib n_jobs=2 vs {name}: {best[name] / joblib_s:.2f}x")


def index(n: int, keep: str | None) -> None:
    from synthetic import write_run

    from higbench.results import load_runs

    root = Path(keep) if keep else Path(tempfile.mkdtemp())
    if not any(root.rglob("*.h5")):
        t = time.perf_counter()
        for i in range(n):
            path = root / f"sweep{i // 100}" / f"{i % 100}_lr={i}" / "run.h5"
            losses = [1.0 / (1 + k) for k in range(20)]
            write_run(
                path,
                optimizer=("adam", "sgd", "hig")[i % 3],
                lr=1e-3 * (i + 1),
                batch_size=2 ** (4 + i % 5),
                test_loss=losses,
                n_updates=200,
            )
        print(f"wrote {n} run files in {time.perf_counter() - t:.1f} s under {root}")
    for curves in (False, True, False):
        t = time.perf_counter()
        out = load_runs(root, curves=curves)
        dt = time.perf_counter() - t
        runs = out[0] if curves else out
        extra = f", curves: {len(out[1])} rows" if curves else ""
        per_file = 1e3 * dt / len(runs)
        print(
            f"load_runs(curves={curves}): {len(runs)} runs x {runs.shape[1]} cols in {dt:.2f} s ({per_file:.2f} ms/file){extra}"
        )
    print(f"load average: {os.getloadavg()}")


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="what", required=True)
    s = sub.add_parser("sweep")
    s.add_argument("--updates", type=int, default=2000)
    s.add_argument("--optimizer", default="adam")
    s.add_argument("--repeats", type=int, default=2)
    s.add_argument("--only", nargs="*", help="variants: basic (threads=null), basic1 (threads=1), joblib")
    i = sub.add_parser("index")
    i.add_argument("--files", type=int, default=1000)
    i.add_argument("--keep", help="directory to write the files into (reused if it has run files)")
    a = p.parse_args()
    if a.what == "sweep":
        sweep(a.updates, a.optimizer, a.repeats, a.only)
    else:
        index(a.files, a.keep)
