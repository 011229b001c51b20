"""Threads for one GN/HIG/LM update: the size rule that the runner's ``threads=auto`` and the
optimizers' own ``threads="auto"`` share.

An update whose Gram matrix has fewer than ``PARALLEL_MIN_ROWS`` rows (b·|y|) runs on one
thread: its small products and eigen-solve lose from a second thread even on an idle machine
(oscillator b=128: 17.9 ms with 1 thread, 22.7 ms with 2 on an idle 2-core machine), and on a
machine shared with other processes torch's default (one thread per core) collapses: the
threads wait for each other's cores (docs/hig.md, "Threads"). The 4096-row Poisson update
gains from a second thread (6.08 s -> 3.78 s), so larger updates keep the count they have.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch

# Gram rows from which a second thread pays for the eigen-solve: `python -m higbench.bench.threads`
# on an idle 2-core machine gave 2/1-thread time ratios of 0.98 at 512 rows, 1.08 at 1024, 0.81 at
# 1536, 0.68 at 2048 and 0.57 at 4096 (docs/benchmarks.md, "Threads").
PARALLEL_MIN_ROWS = 1536
THREAD_SETTINGS = "'auto', None or an integer >= 1"


def fit_to_work(threads: int, gram_rows: int | None) -> int:
    """``auto`` threads for a step of this size: 1 below ``PARALLEL_MIN_ROWS`` Gram rows."""
    if gram_rows is not None and gram_rows < PARALLEL_MIN_ROWS:
        return 1
    return threads


def check_threads(threads: object) -> None:
    """ValueError unless ``threads`` is 'auto', None or an integer >= 1."""
    ok = threads in ("auto", None) or (isinstance(threads, int) and not isinstance(threads, bool) and threads >= 1)
    if not ok:
        raise ValueError(f"threads={threads!r}: expected {THREAD_SETTINGS}")


@contextmanager
def update_threads(threads: int | str | None, gram_rows: int | None) -> Iterator[None]:
    """torch's thread count (which the Gram eigen-solve's BLAS follows) inside one update.

    threads: ``"auto"`` (``fit_to_work`` of torch's current count; unknown rows: unchanged),
    an integer, or None (leave torch's count alone). Restored afterwards, so code around the
    optimizer keeps its own setting.
    """
    have = torch.get_num_threads()
    want = have if threads is None else fit_to_work(have, gram_rows) if threads == "auto" else int(threads)
    if want == have:
        yield
        return
    torch.set_num_threads(want)
    try:
        yield
    finally:
        torch.set_num_threads(have)
