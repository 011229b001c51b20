"""threads=auto: the cores the process may use, shared among a launcher's jobs, minus busy ones."""

import os

import pytest

from higbench.runner import threads as T


@pytest.fixture
def machine(monkeypatch):
    def setup(affinity, cpus, load, omp=None):
        monkeypatch.setattr(T.os, "sched_getaffinity", lambda pid: set(range(affinity)))
        monkeypatch.setattr(T.os, "cpu_count", lambda: cpus)
        monkeypatch.setattr(T.os, "getloadavg", lambda: (load, load, load))
        if omp is None:
            monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
        else:
            monkeypatch.setenv("OMP_NUM_THREADS", omp)

    return setup


@pytest.mark.parametrize(
    "affinity,cpus,load,omp,expected",
    [
        (2, 2, 0.1, None, 2),  # quiet machine: every core
        (2, 2, 0.7, None, 1),  # one core busy with another process
        (2, 2, 5.0, None, 1),  # shared and loaded: never below one
        (16, 16, 3.2, None, 13),
        (4, 64, 40.0, None, 4),  # restricted affinity: the host's load average is not ours
        (8, 8, 0.0, "2", 2),  # a launcher's share (loky: cores // n_jobs; slurm: cpus_per_task)
        (2, 2, 0.0, "8", 2),  # never more than the cores
    ],
)
def test_auto(machine, affinity, cpus, load, omp, expected):
    machine(affinity, cpus, load, omp)
    assert T.resolve_threads("auto") == expected


def test_explicit_and_null():
    assert T.resolve_threads(3) == 3
    assert T.resolve_threads(None) is None
    assert T.available_cores() == len(os.sched_getaffinity(0))
