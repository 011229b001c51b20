"""Quantum dipole: 1-D Schroedinger equation in an infinite well, Crank-Nicolson in time.

    i dPsi/dt = H Psi,   H = -D2 + u(t) diag(x)

on [0, 2] with 16 grid points, the two boundary points pinned to Psi = 0, so N = 14
unknowns at x_k = k dx, k = 1..14, dx = 2/15; D2 is the 3-point second difference / dx^2.
Each step solves (1 + i dt/2 H) Psi_new = (1 - i dt/2 H) Psi_old, i.e. with
M = 1 + i dt/2 H:  Psi_new = 2 M^{-1} Psi_old - Psi_old (one solve, no right-hand matvec).

Fast solve. M is complex symmetric and tridiagonal, with constant off-diagonal
beta = -i alpha (alpha = dt / (2 dx^2)) and a diagonal d that depends on u only; u is known
for all steps up front. So the sequential part of a tridiagonal solve (the pivots) runs
once for all (step, sample) pairs, vectorised over both, and what is left per time step
is M^{-1} applied through its semiseparable form: eight (b, 14) ops, no loop over rows.
With forward pivots m_k = d_k - beta^2 / m_{k-1}, backward pivots q_k, r_l = -beta / m_l:

    M^{-1}[i, j] = g_i prod_{l=j}^{i-1} r_l = g_i R_i / R_j   (j <= i, symmetric above)
    g_i = M^{-1}[i, i] = 1 / (m_i + q_i - d_i)

R is a running product taken outward from the middle of the grid (R = 1 at index 7), which keeps
it and 1/R inside the float range up to |u| ~ 1e7 in float32 (NaN beyond ~1e8). Every pivot has real part
>= 1 (M = 1 + i * Hermitian), so no pivoting is needed and nothing divides by ~0.
``simulate_dense`` is the plain dense-solve reference used by the tests.
"""

from __future__ import annotations

import functools
import math

import torch

N = 14
DX = 2.0 / (N + 1)
DT = 0.05


def _complex_dtype(dtype: torch.dtype) -> torch.dtype:
    if dtype == torch.float32:
        return torch.complex64
    if dtype == torch.float64:
        return torch.complex128
    raise TypeError(f"expected a float32/float64 real tensor, got {dtype}")


def grid(dtype: torch.dtype = torch.float64, device=None) -> torch.Tensor:
    """Interior positions x_k = k * dx, k = 1..14. Returns (14,)."""
    return torch.arange(1, N + 1, dtype=dtype, device=device) * DX


def eigenstate(n: int, dtype: torch.dtype = torch.float64, device=None) -> torch.Tensor:
    """Normalised discrete eigenstate phi_n(k) = sqrt(2/15) sin(pi n k / 15) of -D2 (n = 1: ground state).

    Returns (14, 2): real part, zero imaginary part.
    """
    k = torch.arange(1, N + 1, dtype=torch.float64)
    re = math.sqrt(2.0 / (N + 1)) * torch.sin(math.pi * n * k / (N + 1))
    return torch.stack((re, torch.zeros_like(re)), dim=-1).to(dtype=dtype, device=device)


def to_complex(psi: torch.Tensor) -> torch.Tensor:
    """(..., 14, 2) real/imaginary parts -> (..., 14) complex."""
    return torch.complex(psi[..., 0], psi[..., 1])


def to_real(z: torch.Tensor) -> torch.Tensor:
    """(..., 14) complex -> (..., 14, 2) real/imaginary parts."""
    return torch.stack((z.real, z.imag), dim=-1)


def overlap(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Complex inner product <a, b> = sum_k conj(a_k) b_k. a, b (..., 14, 2) -> complex (...)."""
    # Real arithmetic: conj() on the autograd path breaks torch.func.vmap (no rule for _neg_view).
    ar, ai, br, bi = a[..., 0], a[..., 1], b[..., 0], b[..., 1]
    return torch.complex((ar * br + ai * bi).sum(-1), (ar * bi - ai * br).sum(-1))


def fidelity_loss(psi: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """1 - |<psi, target>|^2 per sample. psi, target (..., 14, 2) -> (...)."""
    ov = overlap(psi, target)
    return 1.0 - (ov.real**2 + ov.imag**2)


def energy_overlap_loss(psi: torch.Tensor, target: torch.Tensor, n: int) -> torch.Tensor:
    """(|<psi, phi_n>| - |<phi_n, target>|)^2 per sample: n = 2 low-, n = 3 high-energy loss (figure 4c).

    psi, target (..., 14, 2) -> (...).
    """
    phi = eigenstate(n, dtype=psi.dtype, device=psi.device)
    return (overlap(psi, phi).abs() - overlap(phi, target).abs()) ** 2


def _inverse_factors(u: torch.Tensor, dt: float, cdtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor]:
    """Factors P = 2 g R and Q = 1 / R of 2 M^{-1} for every control value.

    u: (...) real. Returns P, Q, each (..., 14) complex, such that
    (2 M^{-1} v)_i = P_i sum_{j<=i} Q_j v_j + Q_i sum_{j>i} P_j v_j.
    """
    a = 0.5 * dt
    alpha = a / DX**2
    al2 = alpha**2  # -beta^2
    x = grid(u.dtype, u.device)
    im = torch.addcmul(torch.full_like(x, 2.0 * alpha), u[..., None], a * x)
    d = torch.complex(torch.ones_like(im), im).unbind(-1)  # diagonal of M, row by row
    m, w = [d[0]], []  # forward pivots m_k = d_k + alpha^2 / m_{k-1}, and w_k = 1 / m_k
    for k in range(1, N):
        w.append(m[-1].reciprocal())
        m.append(torch.add(d[k], w[-1], alpha=al2))
    q = [d[-1]]  # backward pivots, only needed for the diagonal g
    for k in range(N - 2, -1, -1):
        q.append(torch.add(d[k], q[-1].reciprocal(), alpha=al2))
    q = q[::-1]
    # g_k = 1 / (m_k + q_k - d_k), and m_k - d_k = alpha^2 w_{k-1}.
    g = [q[0].reciprocal()] + [torch.add(q[k], w[k - 1], alpha=al2).reciprocal() for k in range(1, N)]
    # R_k = (i alpha)^(k-c) rho_k with rho_k = prod_{l=c}^{k-1} w_l (k > c) or
    # prod_{l=k}^{c-1} m_l (k < c); 1/R_k likewise with m and w swapped.
    c = N // 2
    rho, rho_inv = [None] * N, [None] * N
    rho[c] = rho_inv[c] = torch.ones_like(g[0])
    for k in range(c + 1, N):
        rho[k], rho_inv[k] = rho[k - 1] * w[k - 1], rho_inv[k - 1] * m[k - 1]
    for k in range(c - 1, -1, -1):
        rho[k], rho_inv[k] = rho[k + 1] * m[k], rho_inv[k + 1] * w[k]
    e = (1j * alpha) ** torch.arange(-c, N - c, dtype=torch.float64)
    e = e.to(dtype=cdtype, device=u.device)
    P = torch.stack(g, -1) * torch.stack(rho, -1) * (2.0 * e)
    Q = torch.stack(rho_inv, -1) / e
    return P, Q


@functools.cache
def _triangles(cdtype: torch.dtype, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """Constant (14, 14) masks: v @ lower = sum_{j<=i} v_j, v @ upper = sum_{j>i} v_j (cached: tril is slow)."""
    i = torch.arange(N, device=device)
    lower = (i[:, None] <= i[None, :]).to(cdtype)
    return lower, (i[:, None] > i[None, :]).to(cdtype)


def simulate(psi0: torch.Tensor, u: torch.Tensor, dt: float = DT, return_trajectory: bool = False) -> torch.Tensor:
    """Crank-Nicolson time stepping, ``u.shape[1]`` steps of size ``dt``, u constant within a step.

    psi0: (b, 14, 2) real/imaginary parts (float32 -> complex64 inside, float64 -> complex128);
    u: (b, steps) real. Returns the final state (b, 14, 2), or with ``return_trajectory``
    every state including the initial one, (b, steps + 1, 14, 2).
    """
    cdtype = _complex_dtype(psi0.dtype)
    # Time-major so that each step reads contiguous (b, 14) slices; unbind = one backward node.
    P, Q = (f.unbind(0) for f in _inverse_factors(u.to(psi0.dtype).transpose(0, 1), dt, cdtype))
    lower, upper = _triangles(cdtype, psi0.device)
    psi = to_complex(psi0)
    traj = [psi] if return_trajectory else None
    for pt, qt in zip(P, Q):
        # 2 M^{-1} psi - psi, M^{-1} split into its lower triangle and strict upper triangle.
        psi = pt * ((psi * qt) @ lower) + qt * ((psi * pt) @ upper) - psi
        if traj is not None:
            traj.append(psi)
    if traj is None:
        return to_real(psi)
    return to_real(torch.stack(traj, dim=1))


def crank_nicolson_matrix(u: torch.Tensor, dt: float = DT, cdtype: torch.dtype = torch.complex128) -> torch.Tensor:
    """M = 1 + i dt/2 (-D2 + u diag(x)) as dense matrices. u (...,) real -> (..., 14, 14) complex."""
    x = grid(u.real.dtype, u.device)
    d2 = (torch.diag(torch.full((N,), -2.0)) + torch.diag(torch.ones(N - 1), 1) + torch.diag(torch.ones(N - 1), -1)) / DX**2
    h = -d2.to(u.dtype).to(u.device) + u[..., None, None] * torch.diag(x)
    eye = torch.eye(N, dtype=cdtype, device=u.device)
    return eye + (0.5j * dt) * h.to(cdtype)


def simulate_dense(psi0: torch.Tensor, u: torch.Tensor, dt: float = DT) -> torch.Tensor:
    """Reference: one dense batched ``torch.linalg.solve`` per step (slow, for tests). Same shapes as ``simulate``."""
    cdtype = _complex_dtype(psi0.dtype)
    psi = to_complex(psi0)
    for m in crank_nicolson_matrix(u.to(psi0.dtype).transpose(0, 1), dt, cdtype).unbind(0):
        psi = 2.0 * torch.linalg.solve(m, psi) - psi
    return to_real(psi)
