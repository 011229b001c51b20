"""Where a second thread pays for the Gram eigen-solve: ``python -m higbench.bench.threads``.

For Gram matrices of n rows (K = J J^T of a random J, float64, as GN/HIG/LM build them) it
times ``gram_eigen`` (the route a run takes: tridiagonal reduction on the CPU) with 1 and 2
threads, alternating in one process, and prints the median of each and their ratio. The
crossover is what ``higbench.runner.threads.PARALLEL_MIN_ROWS`` should sit at; run it on an
idle machine (anything else running shares the cores).
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from higbench.display import md_table
from higbench.optim.inversion import gram_eigen


def time_eigen(n: int, threads: int, repeats: int) -> float:
    torch.manual_seed(0)
    J = torch.randn(n, 2 * n, dtype=torch.float64)
    K = J @ J.T
    torch.set_num_threads(threads)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        _values, project, expand = gram_eigen(K.clone())
        expand(project(torch.ones(n, dtype=torch.float64)))  # one use, as a step makes
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, nargs="+", default=[256, 512, 1024, 1536, 2048, 3072, 4096])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    head = ["Gram rows", "1 thread (s)", "2 threads (s)", "2 / 1"]
    print("\n".join(md_table(head, [])))
    for n in args.rows:  # each row as soon as it is measured
        one, two = time_eigen(n, 1, args.repeats), time_eigen(n, 2, args.repeats)
        print(md_table(head, [[n, f"{one:.4f}", f"{two:.4f}", f"{two / one:.2f}"]])[-1], flush=True)


if __name__ == "__main__":
    main()
