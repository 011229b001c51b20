"""f(K) g for a symmetric K without forming its eigenvectors: tridiagonal reduction.

``torch.linalg.eigh`` (LAPACK syevd) = Householder tridiagonalisation K = Q T Q^T (sytrd),
eigen-decomposition of T, then the back-transformation U = Q W of all n eigenvectors, an
extra ~2 n^3 flops that dominates for large n (4096: eigh 36-47 s against 6 s for the
eigenvalues alone on this 2-core machine). The Jacobian-power step only needs
U f(Lambda) U^T g for ONE vector g, so here the reflectors of Q are applied to two vectors
(O(n^2)) instead: Q^T g, then W f(Lambda) W^T (.), then Q (.). Same algorithm class as
syevd/syevr (backward stable; eigenvalues err by ~eps * max |lambda|), 3-4x faster at
n = 4096 and ~2x at n = 512 on this machine.

When the divide-and-conquer tridiagonal solver fails to converge, ``tridiagonal_eigen``
retries with MRRR, QR iteration and a dense eigh of T, each on the intact (d, e): the
reduction's output is all they need, so a K overwritten by the reduction loses nothing.

Needs SciPy's LAPACK (``dsytrd`` and the divide-and-conquer tridiagonal solver ``dstevd``); without
SciPy, ``available()`` is False and callers use eigh. SciPy's OpenBLAS is multi-threaded
by default, which on a shared, loaded machine is catastrophically slow (oversubscription:
2048 took 16 s instead of 1.5 s here), so its thread count follows torch's
(``torch.get_num_threads()``, set from the run's ``threads``) for the duration of the call,
through threadpoolctl.
"""

from __future__ import annotations

import functools
from contextlib import contextmanager

import numpy as np
import torch

from higbench.optim.lapack import eigh, first_success


@functools.lru_cache(maxsize=1)
def available() -> bool:
    try:
        from scipy.linalg.lapack import dstevd, dsytrd, dsytrd_lwork  # noqa: F401
    except ImportError:
        return False
    return True


@functools.lru_cache(maxsize=1)
def _blas_controller():
    """threadpoolctl's view of the BLAS libraries loaded (SciPy's OpenBLAS among them), once."""
    import scipy.linalg.lapack  # noqa: F401  (loads SciPy's OpenBLAS before the scan)
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


@contextmanager
def blas_threads(n: int):
    """SciPy's (and every other loaded) BLAS thread count set to n inside the block, restored after."""
    with _blas_controller().limit(limits=n, user_api="blas"):
        yield


def _apply_reflectors_loop(c: np.ndarray, tau: np.ndarray, x: np.ndarray, transpose: bool) -> np.ndarray:
    """Q x (transpose=False) or Q^T x for Q = H(0) H(1) ... H(n-2) from dsytrd(lower=1).

    H(i) = I - tau_i v_i v_i^T with v_i = (0, ..., 0, 1, c[i+2:, i]) (the 1 at index i+1).
    ``c`` is the Fortran-ordered (column-major) output of dsytrd, so v_i is contiguous.
    """
    x = x.copy()
    n = x.shape[0]
    for step in range(n - 1):
        i = step if transpose else n - 2 - step
        t = tau[i]
        if t == 0.0:
            continue
        s = x[i + 1]
        for r in range(i + 2, n):
            s += c[r, i] * x[r]
        s *= t
        x[i + 1] -= s
        for r in range(i + 2, n):
            x[r] -= s * c[r, i]
    return x


try:  # compiled: the Python loop over n reflectors costs ~4 ms at n = 512, this ~0.3 ms
    import numba

    _apply_reflectors = numba.njit(cache=True, nogil=True)(_apply_reflectors_loop)
except ImportError:  # pragma: no cover

    def _apply_reflectors(c, tau, x, transpose):
        x = x.copy()
        n = x.shape[0]
        for i in range(n - 1) if transpose else range(n - 2, -1, -1):
            if tau[i] != 0.0:
                v = c[i + 2 :, i]
                s = tau[i] * (x[i + 1] + v @ x[i + 2 :])
                x[i + 1] -= s
                x[i + 2 :] -= s * v
        return x


def _dstevd(d: np.ndarray, e: np.ndarray):
    from scipy.linalg.lapack import dstevd

    # Divide and conquer (as syevd): 0.66 s at n = 4096 against 3.6 s for MRRR (stemr).
    values, W, info = dstevd(d, e, compute_v=1)  # d and e are copied (overwrite_d/e = 0)
    if info != 0:
        raise torch.linalg.LinAlgError(f"dstevd failed (info={info})")
    return values, W


def _dstev(d: np.ndarray, e: np.ndarray):
    from scipy.linalg.lapack import dstev

    values, W, info = dstev(d, e, compute_v=1)  # implicit QL/QR iteration
    if info != 0:
        raise torch.linalg.LinAlgError(f"dstev failed (info={info})")
    return values, W


def _dense_eigh(d: np.ndarray, e: np.ndarray):
    T = torch.from_numpy(np.diag(d) + np.diag(e, -1))  # lower triangle is all eigh reads
    lam, W = eigh(T)
    return lam.numpy(), W.numpy()


def tridiagonal_eigen(d: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (ascending) and eigenvectors of the symmetric tridiagonal T = (d, e).

    LAPACK's divide and conquer first; when it fails to converge, MRRR (stemr), QR
    iteration (stev) and finally the dense eigh of T (with its own fallbacks) are tried,
    each on the same intact d and e (no driver here writes into them).
    """
    import scipy.linalg

    def stemr():
        return scipy.linalg.eigh_tridiagonal(d, e, lapack_driver="stemr", check_finite=False)

    routes = [("dstevd", lambda: _dstevd(d, e)), ("stemr", stemr), ("dstev", lambda: _dstev(d, e)),
              ("dense eigh of T", lambda: _dense_eigh(d, e))]  # fmt: skip
    values, W = first_success("tridiagonal eigen-solver", [(n, _as_torch(r)) for n, r in routes])
    return values.numpy(), W.numpy()


def _as_torch(route):
    return lambda: tuple(torch.from_numpy(np.asarray(x)) for x in route())


class TridiagonalEigen:
    """K = Q W diag(values) W^T Q^T, with Q kept as reflectors (never formed).

    ``project(g)`` = U^T g and ``expand(x)`` = U x for U = Q W (the eigenvectors of K).
    K must be float64 and symmetric (one triangle is used). ``overwrite``: K (a contiguous
    CPU tensor) may be destroyed, saving a copy of n^2 doubles.
    """

    def __init__(self, K: torch.Tensor, overwrite: bool = False):
        from scipy.linalg.lapack import dsytrd, dsytrd_lwork

        if K.dtype != torch.float64:
            raise TypeError(f"TridiagonalEigen needs float64, got {K.dtype}")
        n = K.shape[0]
        self.device = K.device
        a = K.detach().cpu().numpy()
        with blas_threads(torch.get_num_threads()):
            if n == 1:
                self.c, self.tau = np.zeros((1, 1)), np.zeros(0)
                d, e = a.reshape(1).copy(), np.zeros(0)
            else:
                lwork, info = dsytrd_lwork(n, lower=1)
                # a.T is the Fortran-ordered view of the same (symmetric) matrix: no relayout.
                self.c, d, e, self.tau, info = dsytrd(
                    a.T, lower=1, lwork=int(lwork), overwrite_a=int(overwrite and K.is_contiguous())
                )
                if info != 0:
                    raise torch.linalg.LinAlgError(f"dsytrd failed (info={info})")
            if n > 1:
                values, self.W = tridiagonal_eigen(d, e)
            else:
                values, self.W = d, np.ones((1, 1))
        self.values = torch.from_numpy(np.ascontiguousarray(values)).to(self.device)

    def project(self, g: torch.Tensor) -> torch.Tensor:
        h = _apply_reflectors(self.c, self.tau, np.ascontiguousarray(g.detach().cpu().numpy(), dtype=np.float64), True)
        return torch.from_numpy(self.W.T @ h).to(self.device)

    def expand(self, x: torch.Tensor) -> torch.Tensor:
        y = self.W @ x.detach().cpu().numpy().astype(np.float64)
        return torch.from_numpy(_apply_reflectors(self.c, self.tau, np.ascontiguousarray(y), False)).to(self.device)
