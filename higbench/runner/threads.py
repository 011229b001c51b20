"""How many threads a run uses: ``threads: auto | N | null`` (conf/config.yaml).

``auto`` = the cores this process may run on (``os.sched_getaffinity``: CPU sets, taskset and
cgroup cpusets respected), divided among the parallel jobs of a launcher. The launchers say
how many cores a job gets through ``OMP_NUM_THREADS``: joblib's loky workers get
``cores // n_jobs``, ``hydra/launcher=slurm`` exports ``cpus_per_task``. So auto takes
``OMP_NUM_THREADS`` when it is set (capped at the cores), else the cores not already busy:
when the process may use every core of the machine, the 1-minute load average (other
processes wanting a core) is subtracted, at least 1 thread. That avoids the
oversubscription collapse of BLAS threads on a shared machine (docs/benchmarks.md,
"Threads": 2 threads on a loaded 2-core machine made the Poisson HIG step 3x slower). With
a restricted affinity (cpusets, containers) the load average is the host's and is ignored.
The count is taken once, at the start of a run.

The count applies to torch's intra-op pool (``torch.set_num_threads``) and to SciPy's
BLAS/LAPACK (the Gram eigen-solve, ``higbench.optim.tridiagonal``), which follows torch's.
"""

from __future__ import annotations

import os


def available_cores() -> int:
    """Cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not Linux
        return max(1, os.cpu_count() or 1)


def resolve_threads(value) -> int | None:
    """The thread count for ``threads=value``: an int, or None to leave torch's default."""
    if value is None:
        return None
    if value == "auto":
        cores = available_cores()
        share = os.environ.get("OMP_NUM_THREADS", "")
        if share.strip().isdigit() and int(share) >= 1:
            return min(int(share), cores)
        if cores == (os.cpu_count() or cores):
            try:
                busy = os.getloadavg()[0]
            except OSError:
                busy = 0.0
            return max(1, min(cores, cores - int(busy + 0.5)))
        return cores
    return int(value)
