"""`python -m higbench`: the package's commands (it is a package, not one command)."""

from __future__ import annotations

import sys

COMMANDS = """higbench is a package of commands; run one of them:

  higbench --help                           train one run or a sweep (python -m higbench.cli)
  higbench-results outputs/ --best          the runs under a folder as a table, plots, profiles
                                            (python -m higbench.results)
  python -m higbench.figures --help         the paper's figures and tables
  python -m higbench.bench.step --help      the cost of one update, per optimizer

Start with README.md; `make run` trains a first run.
"""


def main() -> int:
    sys.stdout.write(COMMANDS)
    return 0


if __name__ == "__main__":
    sys.exit(main())
