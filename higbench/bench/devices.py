"""GPU against CPU on one machine, at equal training clock: ``python -m higbench.bench.devices``.

For each problem it starts the same run twice at once, side by side on the same machine:
``device=cuda`` and ``device=cpu`` (each with its own threads), for the same training-clock
budget, then reads both run files and prints the training clock at which each reached each
of the problem's test-loss targets (``problem.targets``), and its updates and final loss. One row per (problem, device):

    python -m higbench.bench.devices --problems oscillator dipole poisson --seconds 30 --out outputs/bench/devices

The question it answers is the one a user with a GPU asks: on this machine, does
``device=cuda`` reach each loss no later than ``device=cpu``? Runs side by side share the
machine's memory bus and the host's cores (the compiled solvers of a CUDA run run on the
host): give each its share of the cores with ``--cuda-threads`` and ``--cpu-threads`` (each run
takes ``threads=auto`` within its share, as under a parallel launcher).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
from pathlib import Path

from higbench.results.index import TIME_TO_PREFIX, read_run_summary
from higbench.runfile.reader import RUN_FILE

DEVICES = ("cuda", "cpu")
# The test loss is evaluated on a schedule of training-clock seconds (eval_every, 1 s or more):
# two runs that reach a loss at the same scheduled evaluation differ by the clock's jitter (ms).
SAME_EVALUATION_S = 0.5


def run_command(problem: str, optimizer: str, device: str, seconds: float, run_dir: Path, extra) -> list[str]:
    return [
        sys.executable, "-m", "higbench.cli", f"problem={problem}", f"optimizer={optimizer}", f"device={device}",
        "threads=auto", f"budget.seconds={seconds}", "progress=false", "checkpoint_every=null",
        f"hydra.run.dir={run_dir}", *extra,
    ]  # fmt: skip


def thread_share(threads: int) -> dict:
    """The environment of a run given ``threads`` cores: ``threads=auto`` takes this share, as
    under a parallel launcher (and still drops to one thread for a small eigen-solve)."""
    return {**os.environ, "OMP_NUM_THREADS": str(threads)}


def run_side_by_side(problem: str, optimizer: str, seconds: float, out: Path, threads: dict, extra=()) -> dict[str, Path]:
    """Both devices' runs of one problem at once; their run files by device. Not through
    ``higbench.jobs.launch``: the measurement is two processes started together, each with its
    own thread share (an environment per process), and always run anew (no reuse: a run from
    another moment of the machine would not be side by side)."""
    dirs = {d: out / f"{problem}_{optimizer}" / d for d in DEVICES}
    procs = {
        d: subprocess.Popen(run_command(problem, optimizer, d, seconds, dirs[d], extra), env=thread_share(threads[d]),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        for d in DEVICES
    }  # fmt: skip
    for d, proc in procs.items():
        output, _ = proc.communicate()
        if proc.returncode != 0:
            print(f"{problem} {optimizer} device={d} exited {proc.returncode}:\n{output[-2000:]}", file=sys.stderr)
    return {d: dirs[d] / RUN_FILE for d in DEVICES}


def summary(problem: str, optimizer: str, device: str, path: Path) -> dict:
    row, _ = read_run_summary(path)  # time_to_<t> at the problem's targets (its stored config's)
    out = {"problem": problem, "optimizer": optimizer, "device": device, "status": row.get("status", row.get("error"))}
    for key in ("steps", "final_test_loss", "best_test_loss", "wall_time", "mean_update_s"):
        out[key] = row.get(key)
    out.update({k: v for k, v in row.items() if k.startswith(TIME_TO_PREFIX)})
    return out


def verdicts(rows: list[dict]) -> list[str]:
    """Per problem: every target (the rows' ``time_to_<t>`` columns) either device reached, and
    whether cuda got there no later."""
    lines = []
    for problem in dict.fromkeys(r["problem"] for r in rows):
        by = {r["device"]: r for r in rows if r["problem"] == problem}
        if set(by) != set(DEVICES):
            continue
        columns = dict.fromkeys(c for r in by.values() for c in r if c.startswith(TIME_TO_PREFIX))
        for col in sorted(columns, key=lambda c: -float(c[len(TIME_TO_PREFIX) :])):
            t = float(col[len(TIME_TO_PREFIX) :])
            cuda, cpu = _finite(by["cuda"].get(col)), _finite(by["cpu"].get(col))
            if cuda is None and cpu is None:
                continue
            ok = cuda is not None and (cpu is None or cuda <= cpu + SAME_EVALUATION_S)
            lines.append(f"{problem} {t:g}: cuda {_s(cuda)}, cpu {_s(cpu)}: {'no later' if ok else 'LATER'}")
    return lines


def _finite(x):
    return None if x is None or (isinstance(x, float) and not math.isfinite(x)) else float(x)


def _s(x) -> str:
    return "not reached" if x is None else f"{x:.1f} s"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problems", nargs="+", default=["oscillator", "dipole", "poisson"])
    parser.add_argument("--optimizer", default="hig")
    parser.add_argument("--seconds", type=float, default=30.0, help="training clock per run")
    parser.add_argument("--cuda-threads", type=int, default=2, help="host threads of the CUDA run (its compiled solvers)")
    parser.add_argument("--cpu-threads", type=int, default=8)
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="extra overrides for every run")
    parser.add_argument("--out", type=Path, default=Path("outputs/bench/devices"))
    args = parser.parse_args(argv)
    threads = {"cuda": args.cuda_threads, "cpu": args.cpu_threads}
    rows = []
    for problem in args.problems:
        paths = run_side_by_side(problem, args.optimizer, args.seconds, args.out, threads, args.set)
        for device, path in paths.items():
            rows.append(summary(problem, args.optimizer, device, path))
            print(json.dumps(rows[-1], default=str), flush=True)
    for line in verdicts(rows):
        print(line)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "devices.json").write_text(json.dumps({"rows": rows, "verdicts": verdicts(rows)}, indent=1, default=str))


if __name__ == "__main__":
    main()
