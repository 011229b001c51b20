"""The "Jacobian power" inversion shared by HIG, Gauss-Newton and gradient descent.

Paper eq. 6 and 22: with the thin SVD J = U diag(s) V^T,

    J^<beta, kappa> g = max(s)^beta * V diag(s^kappa) U^T g

with singular values below the cutoff dropped (set to zero, never clamped). HIG is
kappa = -1/2, Gauss-Newton kappa = -1, gradient descent kappa = 1 (all beta = 0).

Two equivalent routes:

* ``jacobian_power``: SVD of the materialised J (the reference; needed when tau is so
  small that tau^2 is near float64 precision).
* ``gram_coefficients``: eigen-decomposition of the Gram matrix K = J J^T = U diag(s^2) U^T.
  Since V diag(s^kappa) U^T = J^T U diag(s^(kappa-1)) U^T, the direction is J^T c with
  c = max(s)^beta U diag(s^(kappa-1)) U^T g: one vector-Jacobian product, no SVD of J.

Failures. LAPACK's default drivers (gesdd for the SVD, syevd for eigh, stevd for the
tridiagonal route) occasionally fail to converge on ill-conditioned matrices (torch raises
``LinAlgError``). Before giving up, each retries with other algorithms for the same
factorisation, always on an intact input (no driver here overwrites what a retry needs):
the QR-iteration SVD ``gesvd`` (SciPy) or the SVD through eigh; SciPy's ``syevr``/``syev``
or the SVD of K for eigh; MRRR, QR iteration or a dense eigh of the tridiagonal matrix for
the tridiagonal route (``tridiagonal.tridiagonal_eigen``). ``gram_coefficients`` with
``overwrite=True`` can only fail in the reduction itself; its caller then still has J and
takes the SVD route (``JacobianPower``). A run is declared diverged only when every route fails.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import torch

from higbench.optim import tridiagonal
from higbench.optim.lapack import eigh, svd

TRUNCATION_MODES = ("relative", "absolute")


def _keep_mask(s: torch.Tensor, tau: float, truncation: str) -> torch.Tensor:
    """Singular values that survive truncation (relative: s >= tau * max(s))."""
    if truncation not in TRUNCATION_MODES:
        raise ValueError(f"truncation={truncation!r}: expected one of {TRUNCATION_MODES}")
    if s.numel() == 0:
        return torch.zeros_like(s, dtype=torch.bool)
    cutoff = tau * s.max() if truncation == "relative" else torch.as_tensor(tau, dtype=s.dtype)
    # Exact zeros are dropped too, whatever tau is (0^kappa is undefined for kappa < 0).
    return (s >= cutoff) & (s > 0)


def _powered(s: torch.Tensor, keep: torch.Tensor, exponent: float) -> torch.Tensor:
    """s**exponent on kept entries, 0 elsewhere (safe for s = 0)."""
    safe = torch.where(keep, s, torch.ones_like(s))
    return torch.where(keep, safe**exponent, torch.zeros_like(s))


def _prefactor(s: torch.Tensor, beta: float) -> torch.Tensor:
    if beta == 0.0 or s.numel() == 0:
        return torch.ones((), dtype=s.dtype, device=s.device)
    return s.max() ** beta


def jacobian_power(
    J: torch.Tensor,
    g: torch.Tensor,
    kappa: float,
    beta: float = 0.0,
    tau: float = 1e-6,
    truncation: str = "relative",
    on_spectrum: Callable[[torch.Tensor, torch.Tensor], None] | None = None,
) -> torch.Tensor:
    """Direction ``max(s)^beta V diag(s^kappa) U^T g`` via the SVD of J.

    J: (rows, params) stacked per-sample Jacobians; g: (rows,) stacked loss gradients.
    Returns (params,). No minus sign and no learning rate: the caller applies
    ``theta -= lr * direction``. Computed in the dtype of J (use float64 for small tau).
    on_spectrum: called with the singular values s and the mask of those kept.
    """
    if J.ndim != 2 or g.ndim != 1 or J.shape[0] != g.shape[0]:
        raise ValueError(f"expected J (rows, params) and g (rows,), got {tuple(J.shape)} and {tuple(g.shape)}")
    if J.shape[0] < J.shape[1]:
        # Wide J: the SVD of J^T (a column-major view of row-major J) is the same factorisation
        # and 4-6x faster in LAPACK here than the SVD of J itself (no relayout of the long side).
        V, s, Uh = svd(J.T)
        U, Vh = Uh.T, V.T
    else:
        U, s, Vh = svd(J)
    keep = _keep_mask(s, tau, truncation)
    if on_spectrum is not None:
        on_spectrum(s, keep)
    coeff = _powered(s, keep, kappa) * (U.T @ g.to(J.dtype))
    return _prefactor(s, beta) * (Vh.T @ coeff)


EIGEN_METHODS = ("auto", "eigh", "tridiagonal")
# Below this size eigh is already cheap and its vectorised O(n^2) vector products win.
TRIDIAGONAL_MIN_ROWS = 256


def resolved_eigen_method(n: int, dtype: torch.dtype, device: torch.device | str = "cpu", method: str = "auto") -> str:
    """``auto``: the tridiagonal route for float64 CPU matrices of n >= 256 when SciPy is there."""
    if method not in EIGEN_METHODS:
        raise ValueError(f"method={method!r}: expected one of {EIGEN_METHODS}")
    if method != "auto":
        return method
    ok = dtype == torch.float64 and torch.device(device).type == "cpu" and n >= TRIDIAGONAL_MIN_ROWS
    return "tridiagonal" if ok and tridiagonal.available() else "eigh"


def gram_eigen(K: torch.Tensor, method: str = "auto", overwrite: bool = False):
    """(eigenvalues ascending, project v -> U^T v, expand w -> U w) of the Gram matrix K.

    The tridiagonal route (``method`` as in ``gram_coefficients``) never forms U: project
    and expand apply its Householder reflectors and the tridiagonal eigenvectors to vectors.
    """
    if resolved_eigen_method(K.shape[0], K.dtype, K.device, method) == "tridiagonal":
        try:
            eig = tridiagonal.TridiagonalEigen(K, overwrite=overwrite)
            return eig.values, eig.project, eig.expand
        except torch.linalg.LinAlgError:
            # After the reduction the tridiagonal solver has its own fallbacks; a failed
            # reduction with overwrite may have left K destroyed: the caller retries from J.
            if overwrite:
                raise
            warnings.warn("tridiagonal eigen-solver failed; retrying with eigh", RuntimeWarning, stacklevel=3)
    lam, U = eigh(K)  # UPLO="L": the lower triangle, no symmetrised copy
    return lam, (lambda v: U.T @ v), (lambda w: U @ w)


def gram_coefficients(
    K: torch.Tensor,
    g: torch.Tensor,
    kappa: float,
    beta: float = 0.0,
    tau: float = 1e-6,
    truncation: str = "relative",
    method: str = "auto",
    overwrite: bool = False,
    on_spectrum: Callable[[torch.Tensor, torch.Tensor], None] | None = None,
    n_params: int | None = None,
) -> torch.Tensor:
    """Output-space coefficients c with ``J^T c = jacobian_power(J, g, ...)``.

    K: (rows, rows) Gram matrix J J^T (its lower triangle is used); g: (rows,). Needs the
    eigen-pairs of K: eigenvalues s^2, so the relative cutoff on s is a cutoff tau^2 on s^2
    -- reliable only while tau^2 is well above the precision of K (see ``solver_choice.gram_is_accurate``).
    method: ``eigh`` (torch.linalg.eigh: all eigenvectors), ``tridiagonal`` (Householder
    tridiagonalisation, eigenvectors applied to g only; ``higbench.optim.tridiagonal``, needs
    SciPy) or ``auto`` (tridiagonal for float64 CPU matrices of 256 rows and more).
    overwrite: K may be destroyed (tridiagonal route; saves a copy of K).
    on_spectrum: called with the singular values s = sqrt(eigenvalues) and the mask of those kept.
    n_params: the columns of J, where known. A tall J (rows > n_params) has only n_params
        singular values: the other rows - n_params eigenvalues of K are zeros by structure
        (round-off in practice), never kept and not passed to ``on_spectrum`` (they are no
        singular values of J the truncation dropped).
    """
    if K.ndim != 2 or K.shape[0] != K.shape[1] or g.shape != (K.shape[0],):
        raise ValueError(f"expected K (rows, rows) and g (rows,), got {tuple(K.shape)} and {tuple(g.shape)}")
    g = g.to(K.dtype)
    lam, project, expand = gram_eigen(K, method, overwrite)
    s = lam.clamp_min(0).sqrt()  # round-off can make tiny eigenvalues negative
    if truncation == "relative":
        # Eigenvalues below n*eps*max are round-off, whatever tau says.
        floor = K.shape[0] * torch.finfo(K.dtype).eps * lam.abs().max()
        s = torch.where(lam > floor, s, torch.zeros_like(s))
    structural = max(0, s.numel() - n_params) if n_params is not None else 0
    if structural:  # the smallest eigenvalues (ascending): rank K <= n_params
        s = torch.cat([torch.zeros_like(s[:structural]), s[structural:]])
    keep = _keep_mask(s, tau, truncation)
    if on_spectrum is not None:
        on_spectrum(s[structural:], keep[structural:])
    coeff = _powered(s, keep, kappa - 1.0) * project(g)
    return _prefactor(s, beta) * expand(coeff)
