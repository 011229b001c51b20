"""Shared fixtures: the CLI in this process (``higbench``) or as a process (``cli``), tiny budgets, a tmp dir."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest
from cli_runner import run_cli

ROOT = Path(__file__).resolve().parent.parent  # higbench is installed (editable): no sys.path entry needed


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


# A budget of a few updates, one evaluation per update, no progress bar.
TINY = ["budget.max_updates=3", "budget.seconds=null", "eval_unit=updates", "eval_every=1", "progress=false"]


@pytest.fixture
def higbench(tmp_path, monkeypatch, capsys):
    """higbench(*argv) in this process, from a fresh tmp dir -> (exit code, stdout, stderr).

    The front door as a user meets it, without a new Python and torch per call; use ``cli``
    (a subprocess) where the process itself is the point (signals, pipes, the entry point).
    """
    from higbench import cli as entry

    monkeypatch.chdir(tmp_path)

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
