"""Which tests start processes: a pytest plugin (loaded by tests/conftest.py).

A test that starts a Python (the CLI, a script, a launcher's workers) pays for a new
interpreter and torch each time; most of the suite's time went there. This plugin wraps the
three ways a process starts (``subprocess.Popen``, ``os.fork``, and the fork-exec that
multiprocessing and joblib's workers use) for the whole session, counts the starts of each
test (setup, call and teardown), and

* fails a test of the default suite that starts one unless it is marked ``process`` (the few
  tests where the process is the point: signals, pipes, the installed wheel, parallel sweeps);
  everything else calls ``higbench.cli.main`` in this process or composes configs with
  Hydra's compose API (tests marked ``slow`` are counted, not failed);
* prints, at the end, how many tests started processes and, with ``--process-starts``, which;
  more than ``BUDGET`` of the default suite fail the session.

Only Python processes are counted (an interpreter, a console script, a worker or fork); small
system tools are not: ``git``, with which every run records the checkout's revision
(higbench/runner/revision.py), and the tools a few tests use to make a fault.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from collections import Counter
from pathlib import Path

import pytest

# tests of the default suite (not slow) that may start processes (issue 34); 16 since a background
# driver stopping a job still starting, which needs a process of its own
BUDGET = 16

ENFORCE = True  # fail a test of the default suite (not slow) that starts processes unmarked

_current: Counter | None = None  # the running test's starts, by program
_by_test: dict[str, tuple[Counter, bool]] = {}  # node id -> (starts by program, marked slow)


def _record(program: str | None) -> None:
    if _current is not None and program is not None:
        _current[program] += 1


def _program(args) -> str | None:
    """ "python", or the name of a Python console script (higbench, pip), of the program a
    command line starts (the first word of a shell command line, else the first argument);
    None for any other program: small system tools, milliseconds each (git, with which every
    run records the checkout's revision; mount, chattr, uname)."""
    if isinstance(args, str | bytes | os.PathLike):
        first = (os.fsdecode(args).split() or [""])[0]
    else:
        first = os.fsdecode(list(args)[0])
    if Path(first).name.startswith("python"):
        return "python"
    path = shutil.which(first)
    try:
        with open(path or first, "rb") as f:
            shebang = f.readline(200)
    except OSError:
        return None
    return Path(first).name if shebang.startswith(b"#!") and b"python" in shebang else None


def _wrap_starts(monkeypatch: pytest.MonkeyPatch) -> None:
    import _posixsubprocess

    execute_child = subprocess.Popen._execute_child

    def popen_child(self, args, *rest, **kw):
        _record(_program(args))
        return execute_child(self, args, *rest, **kw)

    fork, fork_exec = os.fork, _posixsubprocess.fork_exec

    def counted_fork():
        _record("fork")
        return fork()

    def counted_fork_exec(*args, **kw):  # multiprocessing's and loky's spawn (subprocess keeps its own reference)
        _record("python (worker)")
        return fork_exec(*args, **kw)

    monkeypatch.setattr(subprocess.Popen, "_execute_child", popen_child)
    monkeypatch.setattr(os, "fork", counted_fork)
    monkeypatch.setattr(_posixsubprocess, "fork_exec", counted_fork_exec)


def pytest_addoption(parser):
    parser.addoption("--process-starts", action="store_true", help="list the tests that started processes, and which")


def pytest_configure(config):
    config._process_patch = pytest.MonkeyPatch()
    _wrap_starts(config._process_patch)


def pytest_unconfigure(config):
    patch = getattr(config, "_process_patch", None)
    if patch is not None:
        patch.undo()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    global _current
    _current = Counter()
    try:
        yield
    finally:
        _current = None


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if call.when != "teardown" or not _current:
        return
    slow = item.get_closest_marker("slow") is not None
    report.user_properties.append(("process_starts", [dict(_current), slow]))  # to the summary (also from xdist's workers)
    if ENFORCE and item.get_closest_marker("process") is None and not slow and report.passed:
        report.outcome = "failed"
        started = ", ".join(f"{n} x {program}" for program, n in sorted(_current.items()))
        report.longrepr = (
            f"{item.nodeid} started processes ({started}) but is not marked `process`: call higbench.cli.main(argv) "
            "in this process (the `higbench` fixture), or mark it @pytest.mark.process where the process is the point"
        )


def pytest_runtest_logreport(report):
    for name, value in getattr(report, "user_properties", ()):
        if name == "process_starts":
            counts, slow = value
            _by_test[report.nodeid] = (Counter(counts), bool(slow))


def _over_budget() -> list[str]:
    fast = [nodeid for nodeid, (_, slow) in _by_test.items() if not slow]
    return fast if len(fast) > BUDGET else []


def pytest_sessionfinish(session, exitstatus):
    if _over_budget() and exitstatus == pytest.ExitCode.OK:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter, config):
    if not _by_test:
        return
    fast = [nodeid for nodeid, (_, slow) in _by_test.items() if not slow]
    total = sum(sum(counts.values()) for counts, _ in _by_test.values())
    terminalreporter.write_line(
        f"process starts: {len(_by_test)} tests started {total} processes; {len(fast)} of them not marked slow "
        f"(budget {BUDGET}); --process-starts lists them"
    )
    if _over_budget():
        terminalreporter.write_line(
            f"process starts: more than {BUDGET} tests of the default suite started processes: run the rest in this process",
            red=True,
        )
    if config.getoption("--process-starts") or _over_budget():
        for nodeid, (counts, slow) in sorted(_by_test.items()):
            starts = ", ".join(f"{n} x {program}" for program, n in sorted(counts.items()))
            terminalreporter.write_line(f"  {nodeid}{' (slow)' if slow else ''}: {starts}")
