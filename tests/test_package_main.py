"""`python -m higbench` points to the commands instead of "is a package and cannot be directly executed"."""

import runpy

import pytest


def test_python_m_higbench_lists_the_commands(capsys):
    with pytest.raises(SystemExit) as info:
        runpy.run_module("higbench", run_name="__main__")  # what `python -m higbench` runs
    assert info.value.code == 0
    out = capsys.readouterr().out
    for command in ("higbench --help", "higbench-results", "python -m higbench.figures", "README.md"):
        assert command in out
