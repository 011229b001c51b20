"""Time one training update, by phase, and measure its peak memory (paper tables 3, 4, 5).

One configuration = problem x optimizer x batch size (x Jacobian path x solver). For each,
prints one JSON object with the medians over ``--repeats`` timed updates after
``--warmup`` untimed ones:

    problem, optimizer, batch_size, jacobian, solver, update_s, jacobian_s, inversion_s,
    apply_s, peak_mem_mb, repeats, threads, dtype

Phases are those of ``higbench.runner.updates``: ``jacobian_s`` = all derivatives (the
backward pass for first-order optimizers; for GN/HIG the solver Jacobians, the network
factors or J, and the Gram matrix), ``inversion_s`` = eigh/SVD and the product mapping the
coefficients back to the parameters, ``apply_s`` = the parameter update; ``update_s`` is
their sum. Each update starts from the same weights (restored after every update, outside
the clock) and the same batch, so every repeat does the same work.

Timing: all configurations of one invocation are built in ONE process and timed
interleaved (round robin over configurations, one update each per round), so a noisy,
shared machine slows them alike and their ratios hold.

Peak memory: each configuration once more in a fresh subprocess: the resident-set peak
(VmHWM, reset through /proc/self/clear_refs just before the first update) minus the
resident set at that moment, over warm-up plus one update. So it is the extra host memory
the updates need on top of the process with its data and model (the paper reports GPU
memory; first-order numbers here are therefore small). ``--no-memory`` skips it.

``--device cuda``: the same on a GPU, closer to the paper's tables: every phase ends with a
synchronisation (``higbench.runner.updates``), and memory is the peak of the GPU memory the
updates allocate on top of what is allocated before them (torch's allocator statistics).

Examples (``python scripts/bench_step.py`` and ``make bench`` are the same entry point):

    python -m higbench.bench.step --problem oscillator --optimizer adam hig --batch-size 128 512
    python -m higbench.bench.step --problem poisson --optimizer hig --batch-size 16 --jacobian structured naive --solver gram svd
    python -m higbench.bench.step --problem poisson --optimizer hig --batch-size 64 --solver gram krylov  # exact vs Lanczos
    python -m higbench.bench.step --paper-tables --out outputs/bench      # tables 3-5 (+ naive path)
    python -m higbench.bench.step --paper-tables --device cuda --out docs/results/probes/gpu

``--paper-tables`` writes ``paper_tables.csv`` and ``paper_tables.md`` to ``--out``
(default outputs/bench/) for the figures pipeline, with the paper's GPU figures beside
(``higbench.bench.paper``, the one copy of them).
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import statistics
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import torch

from higbench.bench.paper import PAPER_COSTS, PROBLEM_TABLES
from higbench.display import fmt, md_table
from higbench.dtypes import DTYPES
from higbench.runner.updates import synchronize

PHASES = ("jacobian_s", "inversion_s", "apply_s")
CPU = torch.device("cpu")
MEMORY_MEANING = {
    "cpu": "extra resident host memory of the update",
    "cuda": "peak GPU memory the update allocates beyond the set-up's",
}
DEFAULT_OUT = Path("outputs") / "bench"


@dataclass(frozen=True)
class Config:
    problem: str
    optimizer: str
    batch_size: int
    jacobian: str = "-"  # structured | naive for GN/HIG, "-" for first-order optimizers
    solver: str = "-"  # auto | gram | svd | krylov for GN/HIG
    overrides: tuple[str, ...] = ()

    @property
    def jacobian_power(self) -> bool:
        return self.jacobian != "-"

    def hydra_overrides(self) -> list[str]:
        out = [f"problem={self.problem}", f"optimizer={self.optimizer}", f"batch_size={self.batch_size}"]
        if self.jacobian_power:
            out += [f"optimizer.jacobian={self.jacobian}", f"optimizer.solver={self.solver}"]
        return out + list(self.overrides)

    def label(self) -> str:
        extra = f" {self.jacobian}/{self.solver}" if self.jacobian_power else ""
        return f"{self.problem} {self.optimizer} b={self.batch_size}{extra}"


@dataclass
class Timing:
    wall: list[float] = field(default_factory=list)
    cpu: list[float] = field(default_factory=list)
    phases: dict[str, list[float]] = field(default_factory=lambda: {k: [] for k in PHASES})
    finite: bool = True


def compose(cfg: Config):
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    from higbench.config import config_dir

    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        return hydra_compose(config_name="config", overrides=cfg.hydra_overrides())


def is_jacobian_power(optimizer: str) -> bool:
    from hydra.utils import get_class

    from higbench.optim.contract import uses_jacobian

    c = compose(Config("toy", optimizer, 1))
    return uses_jacobian(get_class(c.optimizer._target_))


class Runner:
    """One configuration, ready to run updates from fixed weights on a fixed batch."""

    def __init__(self, cfg: Config, dtype: torch.dtype, device: torch.device = CPU):
        from higbench.problems import build_problem
        from higbench.runner.updates import build_update

        c = compose(cfg)
        self.cfg = cfg
        self.problem = build_problem(c.problem, dtype=dtype, device=device, seed=0)
        self.model = self.problem.build_model()
        gen = torch.Generator().manual_seed(0)
        self.batch = next(iter(self.problem.epoch(cfg.batch_size, gen)))
        self.update = build_update(self.problem, self.model, c.optimizer)
        self.state = {k: v.clone() for k, v in self.model.state_dict().items()}
        self.opt_state = self.update.optimizer.state_dict()

    def __call__(self):
        result = self.update(self.batch)
        self.model.load_state_dict(self.state)
        self.update.optimizer.load_state_dict(self.opt_state)
        return result


def time_configs(
    configs: list[Config], repeats: int, warmup: int, dtype: torch.dtype, device: torch.device = CPU, log=print
) -> dict[Config, Timing]:
    """Interleaved timing: every round runs one update of every configuration."""
    runners = {}
    for cfg in configs:
        runners[cfg] = Runner(cfg, dtype, device)
        for _ in range(warmup):
            runners[cfg]()
    timings = {cfg: Timing() for cfg in configs}
    for r in range(repeats):
        for cfg, run in runners.items():
            synchronize(device)
            t0, c0 = time.perf_counter(), time.process_time()
            result = run()
            synchronize(device)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            t = timings[cfg]
            t.wall.append(wall)
            t.cpu.append(cpu)
            t.finite &= result.finite
            for k in PHASES:
                t.phases[k].append(result.timings.get(k, float("nan")))
        log(f"  round {r + 1}/{repeats} done", file=sys.stderr)
    return timings


# -- memory: one configuration per fresh subprocess --


def _status_mb() -> dict[str, float]:
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            key = line.split(":")[0]
            if key in ("VmRSS", "VmHWM"):
                out[key] = int(line.split()[1]) / 1024
    return out


def memory_probe(cfg: Config, warmup: int, dtype: torch.dtype, device: torch.device = CPU) -> float:
    """Peak extra memory (MB) of warm-up + one update, in this (fresh) process: resident host
    memory, or on a GPU the memory allocated on top of what the set-up holds."""
    run = Runner(cfg, dtype, device)
    import gc

    gc.collect()
    if device.type == "cuda":
        torch.cuda.synchronize(device)
        torch.cuda.reset_peak_memory_stats(device)
        base = torch.cuda.memory_allocated(device)
        for _ in range(max(warmup, 0) + 1):
            run()
        torch.cuda.synchronize(device)
        return max(0.0, (torch.cuda.max_memory_allocated(device) - base) / 2**20)
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # reset VmHWM to the current resident set
    base = _status_mb()["VmRSS"]
    for _ in range(max(warmup, 0) + 1):
        run()
    return max(0.0, _status_mb()["VmHWM"] - base)


def measure_memory(cfg: Config, warmup: int, dtype: str, threads: int, device: str = "cpu") -> float | None:
    cmd = [
        sys.executable,
        "-m",
        "higbench.bench.step",
        "--memory-probe",
        json.dumps(asdict(cfg)),
        "--warmup",
        str(min(warmup, 1)),
    ]
    cmd += ["--dtype", dtype, "--threads", str(threads), "--device", device]
    package_parent = str(Path(__file__).resolve().parents[2])  # the same higbench in the probe
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([package_parent, *filter(None, [os.environ.get("PYTHONPATH")])]))
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        print(f"memory probe failed for {cfg.label()}: {proc.stderr.strip().splitlines()[-1:]}", file=sys.stderr)
        return None
    return float(proc.stdout.strip().splitlines()[-1])


# -- results --


def row(cfg: Config, t: Timing, mem: float | None, threads: int, dtype: str, device: str = "cpu") -> dict:
    med = {k: statistics.median(v) for k, v in t.phases.items()}
    out = {
        "problem": cfg.problem,
        "optimizer": cfg.optimizer,
        "batch_size": cfg.batch_size,
        "jacobian": cfg.jacobian,
        "solver": cfg.solver,
        "update_s": sum(med.values()),
        **med,
        "wall_s": statistics.median(t.wall),
        # Less sensitive to other processes on a shared machine: the least disturbed repeat,
        # and the CPU time of this process (with 1 thread: the time it actually ran).
        "update_min_s": min(sum(v[i] for v in t.phases.values()) for i in range(len(t.wall))),
        "cpu_s": statistics.median(t.cpu) if t.cpu else float("nan"),
        "load": os.getloadavg()[0],
        "peak_mem_mb": mem,
        "repeats": len(t.wall),
        "threads": threads,
        "dtype": dtype,
        "device": device,
        "finite": t.finite,
    }
    if cfg.overrides:
        out["overrides"] = list(cfg.overrides)
    return out


def paper_configs(naive_all: bool) -> list[list[Config]]:
    """Groups timed together, one per problem: the paper's rows, plus the naive path beside.

    The naive rows (torch.func J of network + solver, SVD of J) sit in the same interleaved
    group as the structured ones, so their ratios hold on a noisy machine too.
    """
    groups = []
    for problem, adam_b, hig_b, naive_b in (
        ("oscillator", (256, 512, 1024), (32, 64, 128), (32, 64, 128)),
        ("poisson", (64,), (16, 64), (16, 64) if naive_all else (16,)),
        ("dipole", (256, 512, 1024), (8, 16), (8, 16)),
    ):
        group = [Config(problem, "adam", b) for b in adam_b]
        group += [Config(problem, "hig", b, "structured", "auto") for b in hig_b]
        group += [Config(problem, "hig", b, "naive", "svd") for b in naive_b]
        groups.append(group)
    return groups


def dict_table(rows: list[dict], columns: list[tuple[str, str]]) -> str:
    """``rows`` (dicts) as a Markdown table of ``columns`` ((key, title) pairs), numbers by ``fmt``."""
    return "\n".join(
        md_table([title for _, title in columns], [[fmt(r.get(key), grouped=True) for key, _ in columns] for r in rows])
    )


def _find(rows: list[dict], problem: str, optimizer: str, b: int, jacobian: str = "-", solver: str | None = None):
    """The measured row of one configuration, or None."""
    for r in rows:
        if (r["problem"], r["optimizer"], r["batch_size"], r["jacobian"]) == (problem, optimizer, b, jacobian) and (
            solver is None or r["solver"] == solver
        ):
            return r
    return None


def _figure(target: str, value: float, limit: float, how: str, value_min=None, reached: bool | None = None) -> dict:
    """One figure to reach (``reached``: at most ``limit`` unless given)."""
    reached = value <= limit if reached is None else reached
    row = {"target": target, "value": value, "value_min": value_min, "limit": limit, "reached": reached, "how": how}
    return row if value_min is not None else {k: v for k, v in row.items() if k != "value_min"}


def targets(rows: list[dict]) -> list[dict]:
    """The issue's figures to reach, from the measured rows."""
    out = []
    adam512 = _find(rows, "oscillator", "adam", 512)
    if adam512:
        out.append(_figure("oscillator Adam b=512 update (s)", adam512["update_s"], 0.017, "update_s", adam512["update_min_s"]))
    for name, hig, adam in (
        ("oscillator HIG b=128 / Adam b=512", ("oscillator", "hig", 128, "structured"), ("oscillator", "adam", 512)),
        ("dipole HIG b=16 / Adam b=256", ("dipole", "hig", 16, "structured"), ("dipole", "adam", 256)),
    ):
        a, b = _find(rows, *hig), _find(rows, *adam)
        if a and b:
            value, best = a["update_s"] / b["update_s"], a["update_min_s"] / b["update_min_s"]
            out.append(_figure(name, value, 1.5, "update_s ratio", best))
    p64 = _find(rows, "poisson", "hig", 64, "structured")
    if p64:
        out.append(_figure("Poisson HIG b=64 update (s)", p64["update_s"], 3.0, "update_s", p64["update_min_s"]))
        if p64["peak_mem_mb"] is not None:
            memory = p64["peak_mem_mb"]
            out.append(_figure("Poisson HIG b=64 peak memory (MB)", memory, 1024.0, "peak_mem_mb", reached=memory < 1024))
    gram, naive = _find(rows, "poisson", "hig", 16, "structured"), _find(rows, "poisson", "hig", 16, "naive", "svd")
    if gram and naive:
        value = naive["update_s"] / gram["update_s"]
        name = "Poisson b=16 naive SVD / Gram (speed-up)"
        out.append(_figure(name, value, 5.0, "update_s ratio, >= limit", reached=value >= 5.0))
    return out


COST_COLUMNS = [("optimizer", "optimizer"), ("batch_size", "b"), ("jacobian", "Jacobian"), ("solver", "solver"),
                ("peak_mem_mb", "memory (MB)"), ("update_s", "update (s)"), ("update_min_s", "best (s)"), ("cpu_s", "CPU (s)"),
                ("jacobian_s", "Jacobian (s)"), ("inversion_s", "inversion (s)"), ("paper_mem_mb", "paper memory (MB)"),
                ("paper_update_s", "paper update (s)"), ("paper_jacobian_s", "paper Jacobian (s)")]  # fmt: skip
SPEEDUP_COLUMNS = [("problem", "problem"), ("batch_size", "b"), ("naive_s", "naive update (s)"),
                   ("structured_s", "structured update (s)"), ("speedup", "speed-up"), ("naive_mb", "naive memory (MB)"),
                   ("structured_mb", "structured memory (MB)")]  # fmt: skip
TARGET_COLUMNS = [("target", "figure"), ("value", "measured (median)"), ("value_min", "best repeat"), ("limit", "target"),
                  ("reached", "reached")]  # fmt: skip


def speedups(rows: list[dict]) -> list[dict]:
    """Each naive-path row against the structured path of the same configuration."""
    out = []
    for r in rows:
        fast = _find(rows, r["problem"], r["optimizer"], r["batch_size"], "structured") if r["jacobian"] == "naive" else None
        if fast:
            out.append({"problem": r["problem"], "batch_size": r["batch_size"], "naive_s": r["update_s"],
                        "structured_s": fast["update_s"], "speedup": r["update_s"] / fast["update_s"],
                        "naive_mb": r["peak_mem_mb"], "structured_mb": fast["peak_mem_mb"]})  # fmt: skip
    return out


def write_tables(rows: list[dict], out_dir: Path, meta: dict) -> None:
    import pandas as pd

    out_dir.mkdir(parents=True, exist_ok=True)
    for r in rows:
        paper = PAPER_COSTS.get((r["problem"], r["optimizer"], r["batch_size"])) if r["jacobian"] in ("-", "structured") else None
        r["table"] = PROBLEM_TABLES[r["problem"]]
        r["paper_mem_mb"], r["paper_update_s"], r["paper_jacobian_s"] = paper if paper else (None, None, None)
    pd.DataFrame(rows).to_csv(out_dir / "paper_tables.csv", index=False)
    parts = [
        f"# Update cost, paper tables 3-5 (measured {meta['date']})",
        "",
        f"Machine: {meta['machine']}; torch {meta['torch']}, {meta['threads']} thread(s), {meta['dtype']}; "
        f"medians over {meta['repeats']} interleaved updates after {meta['warmup']} warm-up. "
        f"Paper columns: the paper's GPU figures. Memory: {meta.get('memory', MEMORY_MEANING['cpu'])} "
        "(see higbench/bench/step.py).",
        "",
    ]
    for problem, table in PROBLEM_TABLES.items():
        sub = [r for r in rows if r["problem"] == problem]
        if sub:
            parts += [f"## Table {table}: {problem}", "", dict_table(sub, COST_COLUMNS), ""]
    naive = speedups(rows)
    if naive:
        parts += ["## Naive path (torch.func J + SVD) against the structured path", "", dict_table(naive, SPEEDUP_COLUMNS), ""]
    goal = targets(rows) if meta.get("device", "cpu") == "cpu" else []  # the targets are CPU figures
    if goal:
        parts += ["## Targets", "", dict_table(goal, TARGET_COLUMNS), ""]
    (out_dir / "paper_tables.md").write_text("\n".join(parts))


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="python -m higbench.bench.step", description="Time GN/HIG and first-order updates by phase (see module docstring)."
    )
    parser.add_argument("--problem", nargs="+", default=["oscillator"])
    parser.add_argument("--optimizer", nargs="+", default=["adam", "hig"])
    parser.add_argument("--batch-size", nargs="+", type=int, default=None, help="default: the problem x optimizer default")
    parser.add_argument(
        "--pairs",
        nargs="+",
        default=None,
        metavar="OPTIMIZER:B",
        help="optimizer/batch-size pairs instead of --optimizer x --batch-size (e.g. adam:256 hig:16)",
    )
    parser.add_argument("--jacobian", nargs="+", default=["structured"], choices=["structured", "naive"])
    parser.add_argument("--solver", nargs="+", default=["auto"], choices=["auto", "gram", "svd", "krylov"])
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="extra Hydra overrides for every configuration")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--warmup", type=int, default=2)
    parser.add_argument(
        "--threads",
        default="1",
        help="torch and BLAS threads: N or auto (as the runner's threads=auto); 1: robust on a shared machine",
    )
    parser.add_argument("--dtype", default="float32", choices=["float32", "float64"])
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda"], help="where the updates run (cuda: a GPU)")
    parser.add_argument("--no-memory", action="store_true", help="skip the per-configuration memory subprocesses")
    parser.add_argument("--paper-tables", action="store_true", help="the rows of paper tables 3-5, plus the naive path")
    parser.add_argument(
        "--naive-all", action="store_true", help="with --paper-tables: also the naive Poisson b=64 row (~5 GB, minutes)"
    )
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="--paper-tables: where to write (outputs/bench)")
    parser.add_argument("--memory-probe", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.device == "cuda" and not torch.cuda.is_available():
        parser.error("--device cuda: CUDA is not available on this machine")
    return args


def config_groups(args: argparse.Namespace) -> list[list[Config]]:
    """The configurations to time, in groups timed interleaved: the paper's tables, or the
    command line's problems x optimizers (or --pairs) x batch sizes x Jacobian paths."""
    if args.paper_tables:
        return paper_configs(args.naive_all)
    configs = []
    pairs = [(p.split(":")[0], int(p.split(":")[1])) for p in args.pairs] if args.pairs else None
    for problem, optimizer in itertools.product(args.problem, [o for o, _ in pairs] if pairs else args.optimizer):
        sizes = [b for o, b in pairs if o == optimizer][:1] if pairs else None
        sizes = sizes or args.batch_size or [default_batch(problem, optimizer)]
        paths = list(itertools.product(args.jacobian, args.solver)) if is_jacobian_power(optimizer) else [("-", "-")]
        for b, (jac, solver) in itertools.product(sizes, paths):
            configs.append(Config(problem, optimizer, b, jac, solver, tuple(args.set)))
    return [configs]


def machine_meta(args: argparse.Namespace, device: torch.device) -> dict:
    """What the paper tables say of the machine and the measurement."""
    import platform

    return {
        "date": time.strftime("%Y-%m-%d %H:%M"),
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}"
        + (f"; {device_name(device)}" if device.type == "cuda" else ""),
        "memory": MEMORY_MEANING[device.type],
        "device": device.type,
        "torch": torch.__version__,
        "threads": args.threads,
        "dtype": args.dtype,
        "repeats": args.repeats,
        "warmup": args.warmup,
    }


def main(argv=None) -> None:
    args = parse_args(argv)
    from higbench.runner.threads import resolve_threads

    args.threads = resolve_threads(args.threads if args.threads == "auto" else int(args.threads))
    torch.set_num_threads(args.threads)
    dtype, device = DTYPES[args.dtype], torch.device(args.device)
    if args.memory_probe:
        spec = json.loads(args.memory_probe)
        spec["overrides"] = tuple(spec["overrides"])
        print(memory_probe(Config(**spec), args.warmup, dtype, device))
        return
    rows = []
    for group in config_groups(args):
        print(f"timing {len(group)} configuration(s) interleaved: {', '.join(c.label() for c in group)}", file=sys.stderr)
        timings = time_configs(group, args.repeats, args.warmup, dtype, device)
        for cfg in group:
            mem = None if args.no_memory else measure_memory(cfg, args.warmup, args.dtype, args.threads, args.device)
            r = row(cfg, timings[cfg], mem, args.threads, args.dtype, device_name(device))
            rows.append(r)
            print(json.dumps(r), flush=True)
    if args.paper_tables:
        write_tables(rows, args.out, machine_meta(args, device))
        for t in targets(rows) if device.type == "cpu" else []:
            print(json.dumps(t), flush=True)
        print(f"wrote {args.out / 'paper_tables.csv'} and {args.out / 'paper_tables.md'}", file=sys.stderr)


def device_name(device: torch.device) -> str:
    return f"cuda ({torch.cuda.get_device_name(device)})" if device.type == "cuda" else "cpu"


def default_batch(problem: str, optimizer: str) -> int:
    """The batch size the configs give this pair (conf/problem_optimizer/)."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    from higbench.config import config_dir

    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        return int(hydra_compose(config_name="config", overrides=[f"problem={problem}", f"optimizer={optimizer}"]).batch_size)


if __name__ == "__main__":
    main()
