"""The import contracts of pyproject.toml ([tool.importlinter]: the design's layers from
errors up to cli, the run file knowing no science, reading runs never training, and no
cycles between sibling modules) hold. `make lint` runs the same check; this test makes CI
run it too."""

from pathlib import Path

from importlinter import cli

ROOT = Path(__file__).resolve().parents[1]


def test_import_contracts_hold(monkeypatch):
    monkeypatch.chdir(ROOT)  # lint-imports reads ./pyproject.toml
    assert cli.lint_imports(config_filename=str(ROOT / "pyproject.toml"), no_cache=True, no_logo=True) == 0
