"""How many threads a run uses: ``threads: auto | N | null`` (conf/config.yaml).

``auto`` = the cores this process may run on (``os.sched_getaffinity``: CPU sets, taskset and
cgroup cpusets respected), divided among the parallel jobs of a launcher. The launchers say
how many cores a job gets through ``OMP_NUM_THREADS``: joblib's loky workers get
``cores // n_jobs``, ``hydra/launcher=slurm`` exports ``cpus_per_task``. So auto takes
``OMP_NUM_THREADS`` when it is set (capped at the cores), else the cores idle *now*: the idle
time of each allowed CPU over 0.2 s (``/proc/stat`` deltas), summed and rounded, at least 1.
(The 1-minute load average lagged by a minute: a run started right after another saw load ~1
on an idle machine and took 1 thread.) Where ``/proc/stat`` cannot be read, the load average
is the fallback. That avoids the oversubscription collapse of BLAS threads on a shared
machine (docs/benchmarks.md, "Threads": 2 threads on a loaded 2-core machine made the
Poisson HIG step 3x slower).

Then the size of the work: a GN/HIG/LM step whose Gram matrix has fewer than
``PARALLEL_MIN_ROWS`` rows runs on 1 thread (``fit_to_work``), since its eigen-solve loses
from a second thread (oscillator b=128: 17.9 ms with 1 thread, 22.7 ms with 2 on an idle
2-core machine) while the 4096-row Poisson one gains (6.08 s -> 3.78 s). The count is taken
once, at the start of a run.

The count applies to torch's intra-op pool (``torch.set_num_threads``) and to SciPy's
BLAS/LAPACK (the Gram eigen-solve, ``higbench.optim.tridiagonal``), which follows torch's.
"""

from __future__ import annotations

import os
import time

from higbench.optim.threads import PARALLEL_MIN_ROWS, fit_to_work  # the size rule, shared with the optimizers

__all__ = ["PARALLEL_MIN_ROWS", "available_cores", "fit_to_work", "idle_cores", "resolve_threads"]

IDLE_INTERVAL_S = 0.2


def available_cores() -> int:
    """Cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not Linux
        return max(1, os.cpu_count() or 1)


def _proc_stat() -> str:
    with open("/proc/stat") as f:
        return f.read()


def _cpu_times(text: str) -> dict[int, tuple[int, int]]:
    """cpu index -> (idle + iowait jiffies, total jiffies) from /proc/stat."""
    out = {}
    for line in text.splitlines():
        name, *fields = line.split()
        if name.startswith("cpu") and name[3:].isdigit():
            values = [int(v) for v in fields[:8]]  # user nice system idle iowait irq softirq steal
            out[int(name[3:])] = (values[3] + values[4], sum(values))
    return out


def idle_cores(interval: float = IDLE_INTERVAL_S) -> float | None:
    """How many of this process's CPUs were idle over the last ``interval`` seconds (None: unknown)."""
    try:
        before = _cpu_times(_proc_stat())
        time.sleep(interval)
        after = _cpu_times(_proc_stat())
        allowed = os.sched_getaffinity(0)
    except (OSError, ValueError, AttributeError):
        return None
    idle = 0.0
    for cpu in allowed:
        if cpu in before and cpu in after:
            d_idle, d_total = after[cpu][0] - before[cpu][0], after[cpu][1] - before[cpu][1]
            idle += d_idle / d_total if d_total > 0 else 1.0
    return idle


def _free_cores(cores: int) -> int:
    idle = idle_cores()
    if idle is None:
        try:
            idle = cores - os.getloadavg()[0]
        except OSError:
            idle = cores
    return max(1, min(cores, int(idle + 0.5)))


def resolve_threads(value) -> int | None:
    """The thread count for ``threads=value``: an int, or None to leave torch's default."""
    if value is None:
        return None
    if value == "auto":
        cores = available_cores()
        share = os.environ.get("OMP_NUM_THREADS", "")
        if share.strip().isdigit() and int(share) >= 1:
            return min(int(share), cores)
        return _free_cores(cores)
    return int(value)
