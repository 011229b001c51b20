"""Time one training update by phase (paper tables 3-5): ``higbench.bench.step`` (see its docstring).

Example: ``python scripts/bench_step.py --paper-tables --out outputs/bench``.
"""

from higbench.bench.step import main

if __name__ == "__main__":
    main()
