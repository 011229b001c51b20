"""threads=auto: the cores the process may use, shared among a launcher's jobs, idle now
(/proc/stat over 0.2 s, not the lagging load average), and 1 for a small eigen-solve."""

import os

import pytest

from higbench.runner import threads as T


def proc_stat(cpus, busy, allowed):
    """Two /proc/stat snapshots 100 jiffies apart per CPU, ``busy`` cores' worth busy on the allowed ones."""
    calls = {"n": 0}

    def read():
        n, calls["n"] = calls["n"], calls["n"] + 1
        lines = ["cpu  0 0 0 0 0 0 0 0 0 0"]
        for c in range(cpus):
            share = busy / allowed if c < allowed else 0.0
            work = int(round(100 * n * share))
            lines.append(f"cpu{c} {work} 0 0 {100 * n - work} 0 0 0 0 0 0")
        return "\n".join(lines) + "\nintr 1 2 3\n"

    return read


@pytest.fixture
def machine(monkeypatch):
    def setup(affinity, cpus, load, omp=None):
        """``load`` busy cores now, spread over the allowed CPUs; /proc/stat unreadable when load is None."""
        monkeypatch.setattr(T.os, "sched_getaffinity", lambda pid: set(range(affinity)))
        monkeypatch.setattr(T.os, "cpu_count", lambda: cpus)
        monkeypatch.setattr(T.os, "getloadavg", lambda: (9.0, 9.0, 9.0))  # lagging: must not matter
        monkeypatch.setattr(T, "_proc_stat", proc_stat(cpus, busy=min(load, affinity), allowed=affinity))
        monkeypatch.setattr(T.time, "sleep", lambda s: None)
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
        (4, 64, 1.0, None, 3),  # restricted affinity: only the allowed CPUs count
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


def test_idle_is_measured_now_not_from_the_load_average(monkeypatch):
    """Old code: load average 1 right after another run -> 1 thread on an idle machine."""
    monkeypatch.setattr(T.os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(T.os, "cpu_count", lambda: 2)
    monkeypatch.setattr(T.os, "getloadavg", lambda: (1.0, 0.5, 0.2))
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    monkeypatch.setattr(T, "_proc_stat", proc_stat(2, busy=0.0, allowed=2))
    monkeypatch.setattr(T.time, "sleep", lambda s: None)
    assert T.resolve_threads("auto") == 2


def test_without_proc_stat_the_load_average_is_the_fallback(monkeypatch):
    monkeypatch.setattr(T.os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(T.os, "getloadavg", lambda: (0.9, 0.9, 0.9))
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)

    def unreadable():
        raise OSError("no /proc")

    monkeypatch.setattr(T, "_proc_stat", unreadable)
    assert T.resolve_threads("auto") == 1


def test_idle_cores_reads_the_real_machine():
    idle = T.idle_cores(0.05)
    assert idle is not None and 0.0 <= idle <= T.available_cores() + 1e-9


@pytest.mark.parametrize("threads,rows,expected", [(2, 512, 1), (2, 4096, 2), (2, None, 2), (1, 8192, 1)])
def test_small_eigen_solves_run_on_one_thread(threads, rows, expected):
    assert T.fit_to_work(threads, rows) == expected


def test_the_threads_benchmark_prints_a_row_per_size(capsys):
    """`python -m higbench.bench.threads`, whose table sets PARALLEL_MIN_ROWS, runs (tiny sizes)."""
    from higbench.bench.threads import main

    main(["--rows", "64", "300", "--repeats", "1"])
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ") and line[2].isdigit()]
    assert [r.split("|")[1].strip() for r in rows] == ["64", "300"]
    assert all(float(r.split("|")[4]) > 0 for r in rows)
