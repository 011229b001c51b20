"""One HDF5 reader: only ``higbench/runfile/`` opens HDF5 files, and names the run file."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "higbench"


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        yield path.relative_to(PACKAGE.parent), ast.parse(path.read_text(), filename=str(path))


def _imported(tree: ast.AST) -> set[str]:
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
        elif isinstance(node, ast.Call) and getattr(node.func, "id", "") in ("__import__", "import_module"):
            names.update(a.value.split(".")[0] for a in node.args if isinstance(a, ast.Constant) and isinstance(a.value, str))
    return names


def test_only_runfile_imports_h5py():
    offenders = [str(rel) for rel, tree in _modules() if "h5py" in _imported(tree) and rel.parts[1] != "runfile"]
    assert not offenders, f"modules outside higbench/runfile that import h5py: {offenders}"
    assert any(rel.parts[1] == "runfile" and "h5py" in _imported(tree) for rel, tree in _modules())  # the check sees imports


def test_run_file_name_spelled_once():
    spelled = [
        f"{rel}:{node.lineno}"
        for rel, tree in _modules()
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant) and node.value == "run.h5"
    ]
    assert len(spelled) == 1 and spelled[0].startswith("higbench/runfile/reader.py:"), spelled
