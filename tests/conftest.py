"""Shared fixtures: the CLI in this process (``higbench``), with the one tiny run (tests/cases.py
``TINY_RUN``). Configs composed with Hydra's compose API, ``train`` in this process, a signal
mid-run, the figures' launcher in this process: tests/in_process.py. The CLI as a process of
its own: tests/cli_runner.py.

Most tests call the CLI in this process: ``higbench.cli.main(argv)``, as the console script
does, with its exit code from ``SystemExit``. What one run leaves behind in the process is put
back after each test (``process_state``). A test that starts a process of its own is marked
``process`` (tests/process_starts.py counts them).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest
from cases import TINY_RUN
from in_process import restored_process_state

ROOT = Path(__file__).resolve().parent.parent  # higbench is installed (editable): no sys.path entry needed

pytest_plugins = ["process_starts"]  # counts the processes each test starts; see tests/process_starts.py

TINY = list(TINY_RUN)  # the one tiny run, as a list


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
def process_state():
    """Put back, after every test, what a run of higbench in this process changes in it
    (tests/in_process.py ``restored_process_state``). Autouse: many tests call
    ``higbench.cli.main`` or ``train`` directly."""
    with restored_process_state():
        yield


@pytest.fixture
def higbench(tmp_path, monkeypatch, capsys):
    """higbench(*argv) in this process, from a fresh tmp dir -> (exit code, stdout, stderr).

    The front door as a user meets it, without a new Python and torch per call; the tiny run
    comes first unless ``tiny=False`` (later overrides win). Start a process (tests/cli_runner.py)
    only where the process itself is the point (signals, pipes, the entry point).
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
def fresh_joblib_workers():
    """joblib keeps its loky workers for the next sweep of this process, with the working
    directory and environment they started with: each in-process joblib test gets its own."""
    pytest.importorskip("hydra_plugins.hydra_joblib_launcher")
    from joblib.externals.loky import get_reusable_executor

    get_reusable_executor().shutdown(wait=True)
    yield
    get_reusable_executor().shutdown(wait=True)
