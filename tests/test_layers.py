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


MAX_FILE_LINES, MAX_FUNCTION_LINES = 700, 80  # the house's sizes (docs/architecture.md)


def test_no_module_or_function_outgrows_the_house():
    """A module over 700 lines, or a function over 80, is two concepts in one place: split it."""
    import ast

    too_long = []
    for path in sorted([*(ROOT / "higbench").rglob("*.py"), *(ROOT / "hydra_plugins").rglob("*.py")]):
        text = path.read_text()
        name = path.relative_to(ROOT)
        if text.count("\n") > MAX_FILE_LINES:
            too_long.append(f"{name}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_FUNCTION_LINES:
                    too_long.append(f"{name}:{node.lineno} {node.name}: {length} lines")
    assert not too_long, too_long
