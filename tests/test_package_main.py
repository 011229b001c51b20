"""`python -m higbench` points to the commands instead of "is a package and cannot be directly executed"."""

import subprocess
import sys


def test_python_m_higbench_lists_the_commands():
    proc = subprocess.run([sys.executable, "-m", "higbench"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    for command in ("higbench --help", "higbench-results", "python -m higbench.figures", "README.md"):
        assert command in proc.stdout
