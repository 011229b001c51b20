"""Candidates for the large Gram eigen-solve (Poisson HIG b=64: n = 4096): ``python -m higbench.bench.eigen``.

Times, alternating in one process (so load slows them alike), for a Gram matrix K = J J^T of a
random float64 J with n rows, with 1 and with 2 threads:

* ``route``: what a run does (``gram_eigen``: SciPy/OpenBLAS ``dsytrd`` reduction, ``dstevd``
  on the tridiagonal matrix, reflectors applied to the two vectors a step needs);
* ``scipy dsytrd``: the reduction alone (OpenBLAS), the part that dominates the route;
* ``torch eigvalsh``: torch's LAPACK (MKL) reduction plus eigenvalues only, an upper bound on
  MKL's reduction (MKL's ``dsytrd`` itself is not exported by torch);
* ``torch eigh``: MKL ``syevd`` with every eigenvector (the ``eigh`` route);
* ``scipy eigh``: OpenBLAS ``syevd`` with every eigenvector.

Prints a markdown table of the medians. The reduction cost does not depend on K's spectrum, so
a random J stands for the Poisson Jacobian.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import torch

from higbench.display import md_table
from higbench.optim.inversion import gram_eigen
from higbench.optim.tridiagonal import blas_threads


def _route(K: torch.Tensor) -> None:
    _values, project, expand = gram_eigen(K.clone())
    expand(project(torch.ones(K.shape[0], dtype=K.dtype)))


def _scipy_dsytrd(K: torch.Tensor) -> None:
    from scipy.linalg.lapack import dsytrd, dsytrd_lwork

    n = K.shape[0]
    lwork, _ = dsytrd_lwork(n, lower=1)
    dsytrd(np.asfortranarray(K.numpy()), lower=1, lwork=int(lwork), overwrite_a=1)


def _scipy_eigh(K: torch.Tensor) -> None:
    import scipy.linalg

    scipy.linalg.eigh(K.numpy(), lower=True, driver="evd", check_finite=False)


CANDIDATES = {
    "route (SciPy dsytrd + dstevd + reflectors)": _route,
    "scipy dsytrd (reduction only)": _scipy_dsytrd,
    "torch eigvalsh (MKL reduction + values)": lambda K: torch.linalg.eigvalsh(K),
    "torch eigh (MKL syevd, all vectors)": lambda K: torch.linalg.eigh(K),
    "scipy eigh (OpenBLAS syevd, all vectors)": _scipy_eigh,
}


def time_once(fn, K: torch.Tensor, threads: int) -> float:
    torch.set_num_threads(threads)
    with blas_threads(threads):  # SciPy's OpenBLAS too, as in a run
        t0 = time.perf_counter()
        fn(K)
        return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=4096)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args(argv)
    torch.manual_seed(0)
    J = torch.randn(args.rows, 2 * args.rows, dtype=torch.float64)
    K = J @ J.T
    del J
    times = {(name, t): [] for name in CANDIDATES for t in args.threads}
    for _ in range(args.repeats):  # round robin: every candidate once per round
        for (name, t), out in times.items():
            out.append(time_once(CANDIDATES[name], K.clone(), t))
    head = ["candidate", *(f"{t} thread{'s' if t > 1 else ''} (s)" for t in args.threads)]
    rows = [[name, *(f"{statistics.median(times[name, t]):.2f}" for t in args.threads)] for name in CANDIDATES]
    print(f"n = {args.rows}, median of {args.repeats}\n")
    print("\n".join(md_table(head, rows)))


if __name__ == "__main__":
    main()
