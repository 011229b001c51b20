"""Shared fixtures: the CLI in this process (``higbench``) or as a process (``cli``), with the
one tiny run (tests/cases.py ``TINY_RUN``). Configs composed with Hydra's compose API, ``train``
in this process, a signal mid-run: tests/in_process.py.

Most tests call the CLI in this process: ``higbench.cli.main(argv)``, as the console script
does, with its exit code from ``SystemExit``. What one run leaves behind in the process is put
back after each test (``process_state``). A test that starts a process of its own is marked
``process`` (tests/process_starts.py counts them).
"""

from __future__ import annotations

import importlib.util
import logging
import os
import signal
import sys
from pathlib import Path

import pytest
from cases import TINY_RUN
from cli_runner import run_cli

ROOT = Path(__file__).resolve().parent.parent  # higbench is installed (editable): no sys.path entry needed

pytest_plugins = ["process_starts"]  # counts the processes each test starts; see tests/process_starts.py

TINY = list(TINY_RUN)  # the one tiny run, as a list for ``[*TINY, ...]``


def pytest_collection_modifyitems(config, items):
    """Tests marked `optuna` need the optuna extra: without it they are skipped, with the reason shown (-ra)."""
    try:
        if importlib.util.find_spec("hydra_plugins.hydra_optuna_sweeper") is not None:
            return
    except ModuleNotFoundError:  # no hydra_plugins namespace at all
        pass
    skip = pytest.mark.skip(reason="needs the optuna extra (Hydra's Optuna sweeper): run `make test-optuna`")
    for item in items:
        if "optuna" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(autouse=True)
def process_state(monkeypatch):
    """Put back, after every test, what a run of higbench in this process changes in it.

    A run sets torch's thread count, installs SIGINT/SIGTERM handlers (a single run leaves
    them ignored until exit), records HIGBENCH_PARALLEL_JOBS in the environment, rewrites
    sys.argv and holds a lock on its directory until exit; Hydra adds logging handlers (to
    the test's captured streams) and keeps its global state. Autouse: many tests call
    ``higbench.cli.main`` or ``train`` directly.
    """
    import torch
    from hydra.core.global_hydra import GlobalHydra

    from higbench import cli as entry

    monkeypatch.setattr(sys, "argv", list(sys.argv))
    hydra_was_initialized = GlobalHydra.instance().is_initialized()  # e.g. by a module-scoped compose fixture
    environ = dict(os.environ)
    threads = torch.get_num_threads()
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    loggers = {name: (lg.handlers[:], lg.level, lg.propagate, lg.disabled) for name, lg in _loggers()}
    try:
        yield
    finally:
        if not hydra_was_initialized:
            GlobalHydra.instance().clear()
        getattr(entry, "release_dirs", lambda: None)()  # as at the process's exit
        torch.set_num_threads(threads)
        for s, handler in handlers.items():
            signal.signal(s, handler)
        if dict(os.environ) != environ:
            os.environ.clear()
            os.environ.update(environ)
        for name, lg in _loggers():
            before, level, propagate, disabled = loggers.get(name, ([], logging.NOTSET, True, False))
            for h in lg.handlers[:]:
                if h not in before:
                    lg.removeHandler(h)
                    h.close()
            lg.setLevel(level)
            lg.propagate, lg.disabled = propagate, disabled


def _loggers():
    """The root logger and every named one."""
    yield "", logging.getLogger()
    for name, lg in list(logging.root.manager.loggerDict.items()):
        if isinstance(lg, logging.Logger):
            yield name, lg


@pytest.fixture
def higbench(tmp_path, monkeypatch, capsys):
    """higbench(*argv) in this process, from a fresh tmp dir -> (exit code, stdout, stderr).

    The front door as a user meets it, without a new Python and torch per call; the tiny run
    comes first unless ``tiny=False`` (later overrides win). Use ``cli`` (a process) only where
    the process itself is the point (signals, pipes, the entry point).
    """
    from higbench import cli as entry

    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)

    def _run(*args: str, tiny: bool = True):
        try:
            entry.main([*(TINY if tiny else []), *args])  # Hydra's flags may come anywhere
            code = 0
        except SystemExit as exc:
            code = exc.code
        out = capsys.readouterr()
        return code, out.out, out.err

    return _run


@pytest.fixture
def cli(tmp_path):
    """cli(*overrides) -> CompletedProcess, run from a fresh tmp dir (outputs/ lands there)."""

    def _run(*args: str, tiny: bool = True, timeout: float = 180):
        flags = [a for a in args if a.startswith("-")]  # Hydra's flags (-m) before the overrides
        overrides = [a for a in args if not a.startswith("-")]
        return run_cli([*flags, *(TINY if tiny else []), *overrides], cwd=tmp_path, timeout=timeout)

    return _run


@pytest.fixture
def fresh_joblib_workers():
    """joblib keeps its loky workers for the next sweep of this process, with the working
    directory and environment they started with: each in-process joblib test gets its own."""
    pytest.importorskip("hydra_plugins.hydra_joblib_launcher")
    from joblib.externals.loky import get_reusable_executor

    get_reusable_executor().shutdown(wait=True)
    yield
    get_reusable_executor().shutdown(wait=True)
