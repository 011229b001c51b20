"""The Jacobian-power step from products with K = J J^T alone (``optimizer.solver=krylov``).

The Gram route (``inversion.gram_coefficients``) needs the eigen-pairs of K: O(rows^2) memory
and O(rows^3) time (Poisson HIG at b=64: a 4,096^2 K; at b=1,024 K alone would be 34 GB).
The coefficients it computes are a matrix function of K applied to g,

    c = max(s)^beta f(K) g,   f(lambda) = lambda^((kappa - 1) / 2) on the kept spectrum

(lambda = s^2; s < tau * max(s) dropped, as ``gram_coefficients``), and the direction is J^T c.
Here f(K) g comes from m steps of Lanczos on K started at g, with full reorthogonalisation:

    K Q_m = Q_m T_m + beta_m q_{m+1} e_m^T,   c ~= |g| Q_m f(T_m) e_1

with f applied to the eigen-decomposition of the small tridiagonal T_m, the filter on its
Ritz values. Each step is one product K q = J (J^T q) (``StructuredJacobian.apply`` and
``transpose_apply``: for MLPs one sweep each way through the per-layer factors, J never
formed) and memory is O(rows x m). With m = rows (or at an invariant subspace, e.g. a tall J)
the result is the exact one up to round-off.

Why Lanczos rather than the other candidates: it uses nothing but the products, keeps the
filter's semantics (tau on the Ritz values, the largest of which converge first), is exact in
the limit, and gives a per-step error estimate for free; a randomised / Nystrom low-rank
factorisation needs as many products for a rank-m sketch but keeps only the top of the
spectrum, where HIG's f (an inverse power) puts the least weight; a coupled Newton iteration
for K^(-3/4) multiplies rows x rows matrices (it needs K itself).

Accuracy estimate (``step_error``): with Q_m orthonormal, |J^T Q_m z|^2 = z^T T_m z, so the
relative difference of the directions after m and m - d steps is computed from T_m alone:
sqrt(e^T T_m e / y^T T_m y) with e = y_m - [y_{m-d}; 0]. It estimates the error of the step
after m - d steps, an upper estimate of that after m when Lanczos converges. d = ``delay``
(10), or m // 2 for shorter runs.

Plain torch ops in the dtype of the products (float64 by default) on their device.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch

from higbench.optim.inversion import _keep_mask, _powered, _prefactor
from higbench.optim.solver_choice import lanczos_steps
from higbench.optim.structured import StructuredJacobian

# Lanczos steps between checks of the error estimate (early stop) and the delay d of the estimate.
CHECK_EVERY = 10


@dataclass
class LanczosBasis:
    """Q (rows, m) orthonormal, T_m's diagonal alpha (m,) and off-diagonal beta (m - 1,), |g|."""

    Q: torch.Tensor
    alpha: torch.Tensor
    beta: torch.Tensor
    g_norm: float
    invariant: bool = False  # Q spans an invariant subspace holding g: f(T_m) is exact there

    @property
    def steps(self) -> int:
        return self.alpha.numel()

    def tridiagonal(self, m: int | None = None) -> torch.Tensor:
        """T_m as a dense (m, m) matrix (m <= steps)."""
        m = self.steps if m is None else m
        a, b = self.alpha[:m], self.beta[: m - 1]
        return torch.diag(a) + torch.diag(b, 1) + torch.diag(b, -1)


@dataclass
class KrylovResult:
    """Coefficients c (rows,) with J^T c the direction; what the step saw and how good it is."""

    coefficients: torch.Tensor
    ritz_s: torch.Tensor  # sqrt of the Ritz values of the last T_m (ascending)
    keep: torch.Tensor  # which of them the filter kept
    steps: int  # Lanczos steps taken (<= the maximum: early stop or an invariant subspace)
    step_error: float  # estimated relative error of the direction J^T c (NaN: too few steps to tell)


def lanczos(
    matvec: Callable[[torch.Tensor], torch.Tensor],
    g: torch.Tensor,
    steps: int,
    converged: Callable[[LanczosBasis], bool] | None = None,
) -> LanczosBasis:
    """At most ``steps`` Lanczos steps on the symmetric operator ``matvec`` from g.

    Full reorthogonalisation (classical Gram-Schmidt, twice): the basis stays orthonormal to
    round-off, so the Ritz values carry no spurious copies. Stops early at an invariant
    subspace (the next beta below round-off) or when ``converged(basis so far)`` says so
    (asked every ``CHECK_EVERY`` steps).
    """
    rows = g.numel()
    steps = lanczos_steps(steps, rows)
    g_norm = float(torch.linalg.vector_norm(g))
    Q = torch.zeros(steps, rows, dtype=g.dtype, device=g.device)  # rows of Q: contiguous basis vectors
    alpha = torch.zeros(steps, dtype=g.dtype, device=g.device)
    beta = torch.zeros(steps, dtype=g.dtype, device=g.device)
    if g_norm == 0.0:  # K^p 0 = 0: one zero basis vector, exact
        return LanczosBasis(Q[:1].T, alpha[:1], beta[:0], g_norm, invariant=True)
    Q[0] = g / g_norm
    scale = 0.0  # running max |alpha|, |beta|: the size of K seen so far, for the breakdown test
    m, invariant = steps, steps == rows
    for j in range(steps):
        w = matvec(Q[j])
        alpha[j] = torch.dot(Q[j], w)
        for _ in range(2):  # "twice is enough" (Kahan, Parlett)
            w = w - Q[: j + 1].T @ (Q[: j + 1] @ w)
        b = torch.linalg.vector_norm(w)
        beta[j] = b
        scale = max(scale, float(alpha[j].abs()), float(b))
        if j + 1 == steps:
            break
        if float(b) <= rows * torch.finfo(g.dtype).eps * scale:  # invariant subspace: exact from here
            m, invariant = j + 1, True
            break
        Q[j + 1] = w / b
        if converged is not None and (j + 1) % CHECK_EVERY == 0:
            if converged(LanczosBasis(Q[: j + 1].T, alpha[: j + 1], beta[:j], g_norm)):
                m, invariant = j + 1, False
                break
    return LanczosBasis(Q[:m].T, alpha[:m], beta[: m - 1], g_norm, invariant)


def _filtered_coordinates(
    T: torch.Tensor, g_norm: float, kappa: float, beta: float, tau: float, truncation: str, rows: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(y, Ritz s ascending, keep): c = Q y = |g| Q max(s)^beta V diag(f(theta)) V^T e_1 for T = V diag(theta) V^T."""
    theta, V = torch.linalg.eigh(T)
    s = theta.clamp_min(0).sqrt()
    if truncation == "relative" and theta.numel():
        # Ritz values below rows*eps*max are round-off (as gram_coefficients' floor on K's eigenvalues).
        floor = rows * torch.finfo(T.dtype).eps * theta.abs().max()
        s = torch.where(theta > floor, s, torch.zeros_like(s))
    keep = _keep_mask(s, tau, truncation)
    y = _prefactor(s, beta) * (V @ (_powered(s, keep, kappa - 1.0) * (g_norm * V[0])))
    return y, s, keep


def _relative_change(T: torch.Tensor, y: torch.Tensor, y_earlier: torch.Tensor) -> float:
    """|J^T Q (y - y_earlier)| / |J^T Q y|, from T = Q^T K Q alone."""
    e = y.clone()
    e[: y_earlier.numel()] -= y_earlier
    norm2 = float(y @ (T @ y))
    if not norm2 > 0:
        return math.nan
    return math.sqrt(max(float(e @ (T @ e)), 0.0) / norm2)


def krylov_coefficients(
    matvec: Callable[[torch.Tensor], torch.Tensor],
    g: torch.Tensor,
    kappa: float,
    beta: float = 0.0,
    tau: float = 1e-6,
    truncation: str = "relative",
    steps: int = 200,
    tol: float = 0.0,
    delay: int = CHECK_EVERY,
    on_spectrum: Callable[[torch.Tensor, torch.Tensor], None] | None = None,
) -> KrylovResult:
    """Coefficients c ~= ``gram_coefficients(K, g, ...)`` from products ``matvec(v) = K v``.

    steps: most Lanczos steps (memory rows x steps); tol: stop early once the estimated
    relative error of the direction is below it (0: always take ``steps``); delay: the d of
    the estimate (the step after m is compared with that after m - d; m // 2 when smaller). on_spectrum: called
    with the Ritz singular values sqrt(theta) and the mask of those kept (at most ``steps``
    values: the spectrum Lanczos resolved, its extremes first).
    """
    if g.ndim != 1:
        raise ValueError(f"expected g (rows,), got {tuple(g.shape)}")
    if int(steps) != steps or steps < 1:
        raise ValueError(f"steps={steps}: must be an integer >= 1")
    if not tol >= 0:
        raise ValueError(f"tol={tol}: must be a number >= 0")
    rows = g.numel()
    if not bool(torch.isfinite(g).all()):  # the caller refuses a non-finite direction
        nan = torch.full_like(g, math.nan)
        return KrylovResult(nan, nan[:0], nan[:0].bool(), 0, math.nan)
    opts = dict(kappa=kappa, beta=beta, tau=tau, truncation=truncation, rows=rows)

    def estimate(basis: LanczosBasis) -> float:
        m = basis.steps
        d = min(delay, m // 2)  # short runs: against the step after half of them
        if d < 1:
            return math.nan
        T = basis.tridiagonal()
        y, _, _ = _filtered_coordinates(T, basis.g_norm, **opts)
        y_earlier, _, _ = _filtered_coordinates(basis.tridiagonal(m - d), basis.g_norm, **opts)
        return _relative_change(T, y, y_earlier)

    converged = (lambda basis: estimate(basis) < tol) if tol > 0 else None
    basis = lanczos(matvec, g, steps, converged)
    T = basis.tridiagonal()
    y, s, keep = _filtered_coordinates(T, basis.g_norm, **opts)
    if on_spectrum is not None:
        on_spectrum(s, keep)
    error = 0.0 if basis.invariant else estimate(basis)
    return KrylovResult(basis.Q @ y, s, keep, basis.steps, error)


def krylov_direction(J, g: torch.Tensor, **kwargs) -> tuple[torch.Tensor, KrylovResult]:
    """(J^T c, result) for a ``StructuredJacobian`` or a materialised J; kwargs as ``krylov_coefficients``."""
    if isinstance(J, StructuredJacobian):
        result = krylov_coefficients(J.gram_apply, g, **kwargs)
        return J.transpose_apply(result.coefficients), result
    result = krylov_coefficients(lambda v: J @ (J.T @ v), g.to(J.dtype), **kwargs)
    return J.T @ result.coefficients, result
