"""Fast dipole solver: the Crank-Nicolson loop of ``higbench.physics.dipole`` compiled, with its adjoint.

Same scheme, arguments and results as ``dipole.simulate`` (the reference, kept for the tests
and for non-CPU devices); equal to it to ~1e-13 relative in float64, outputs and gradients
(tests/physics/test_dipole.py runs every test on both).

Each step solves M psi_new' = psi (Thomas algorithm: M = 1 + i dt/2 H is tridiagonal with
real part 1 on the diagonal, so no pivoting) and sets psi_new = 2 psi_new' - psi.

Adjoint (real loss L, cotangent g = dL/dRe psi + i dL/dIm psi): the step is the complex-linear
map A = 2 M^{-1} - 1 with M complex *symmetric*, so A^H = 2 conj(M)^{-1} - 1 and

    z = conj(M)^{-1} g_new,    g_old = 2 z - g_new,
    dL/du_t = dt * Im( sum_k conj(z_k) x_k w_k ),   w = M^{-1} psi_old = (psi_new + psi_old) / 2

(from dM/du = i dt/2 diag(x) and d(M^{-1}) = -M^{-1} dM M^{-1}). The pivots of conj(M) are
shared by all cotangent seeds of a sample, so the |y| = 28 rows of a solver Jacobian cost
one pivot sweep plus 28 cheap substitutions per step.
"""

from __future__ import annotations

import numpy as np
import torch

from higbench.physics._adjoint import Kernels, as_numpy64, available, njit, run
from higbench.physics.dipole import DT, DX, N
from higbench.physics.dipole import simulate as simulate_reference


@njit
def _forward_kernel(psi0, u, dt, dx, traj):
    """traj[i, t] = complex state after t steps of sample i (traj[i, 0] = psi0[i])."""
    b, steps = u.shape
    n = psi0.shape[1]
    a = 0.5 * dt
    alpha = a / (dx * dx)
    beta = -1j * alpha
    cp = np.empty(n, dtype=np.complex128)
    rp = np.empty(n, dtype=np.complex128)
    for i in range(b):
        for k in range(n):
            traj[i, 0, k] = psi0[i, k]
        for t in range(steps):
            ut = a * u[i, t]
            den = 1.0 + 1j * (2.0 * alpha + ut * dx)
            cp[0] = beta / den
            rp[0] = traj[i, t, 0] / den
            for k in range(1, n):
                den = 1.0 + 1j * (2.0 * alpha + ut * (k + 1) * dx) - beta * cp[k - 1]
                cp[k] = beta / den
                rp[k] = (traj[i, t, k] - beta * rp[k - 1]) / den
            w = rp[n - 1]
            traj[i, t + 1, n - 1] = 2.0 * w - traj[i, t, n - 1]
            for k in range(n - 2, -1, -1):
                w = rp[k] - cp[k] * w
                traj[i, t + 1, k] = 2.0 * w - traj[i, t, k]


@njit
def _adjoint_kernel(traj, u, dt, dx, seeds, dtraj, has_dtraj, gx, gu):
    """Reverse sweep for m complex seeds per sample: seeds (m, b, n) on the final state, dtraj
    (m, b, steps + 1, n) on every state if has_dtraj. Writes gx (m, b, n), gu (m, b, steps)."""
    m, b, n = seeds.shape
    steps = u.shape[1]
    a = 0.5 * dt
    alpha = a / (dx * dx)
    beta = 1j * alpha  # off-diagonal of conj(M)
    cp = np.empty(n, dtype=np.complex128)
    inv = np.empty(n, dtype=np.complex128)
    g = np.empty((m, n), dtype=np.complex128)
    rp = np.empty(n, dtype=np.complex128)
    for i in range(b):
        for j in range(m):
            for k in range(n):
                g[j, k] = seeds[j, i, k]
                if has_dtraj:
                    g[j, k] += dtraj[j, i, steps, k]
        for t in range(steps - 1, -1, -1):
            ut = a * u[i, t]
            den = 1.0 - 1j * (2.0 * alpha + ut * dx)
            inv[0] = 1.0 / den
            cp[0] = beta * inv[0]
            for k in range(1, n):
                den = 1.0 - 1j * (2.0 * alpha + ut * (k + 1) * dx) - beta * cp[k - 1]
                inv[k] = 1.0 / den
                cp[k] = beta * inv[k]
            for j in range(m):
                rp[0] = g[j, 0] * inv[0]
                for k in range(1, n):
                    rp[k] = (g[j, k] - beta * rp[k - 1]) * inv[k]
                z = rp[n - 1]
                acc = 0.0
                for k in range(n - 1, -1, -1):
                    if k < n - 1:
                        z = rp[k] - cp[k] * z
                    w = 0.5 * (traj[i, t + 1, k] + traj[i, t, k])
                    acc += (z.real * w.imag - z.imag * w.real) * ((k + 1) * dx)  # Im(conj(z) w) x_k
                    g[j, k] = 2.0 * z - g[j, k]
                    if has_dtraj:
                        g[j, k] += dtraj[j, i, t, k]
                gu[j, i, t] = dt * acc
        for j in range(m):
            for k in range(n):
                gx[j, i, k] = g[j, k]


def _complex(a: np.ndarray) -> np.ndarray:
    """(..., n, 2) float64 -> (..., n) complex128 (a copy, C-contiguous)."""
    return np.ascontiguousarray(a[..., 0] + 1j * a[..., 1])


def _real(z: np.ndarray) -> torch.Tensor:
    """(..., n) complex128 -> (..., n, 2) float64 tensor."""
    return torch.from_numpy(np.ascontiguousarray(np.stack((z.real, z.imag), axis=-1)))


def _run_forward(psi0: torch.Tensor, u: torch.Tensor, params: tuple) -> torch.Tensor:
    """All states (b, steps + 1, 14, 2), float64, no graph."""
    (dt,) = params
    p0, un = _complex(as_numpy64(psi0)), as_numpy64(u)
    traj = np.empty((un.shape[0], un.shape[1] + 1, p0.shape[1]), dtype=np.complex128)
    _forward_kernel(p0, un, float(dt), DX, traj)
    return _real(traj)


def _run_adjoint(
    traj: torch.Tensor, u: torch.Tensor, params: tuple, seeds: torch.Tensor, full: bool
) -> tuple[torch.Tensor, torch.Tensor]:
    """Gradients (m, b, 14, 2) w.r.t. psi0 and (m, b, steps) w.r.t. u for m cotangents per sample."""
    (dt,) = params
    tn, un, sn = _complex(as_numpy64(traj)), as_numpy64(u), _complex(as_numpy64(seeds))
    m, b = sn.shape[0], sn.shape[1]
    if full:
        final, dtraj = np.zeros((m, b, tn.shape[2]), dtype=np.complex128), sn
    else:
        final, dtraj = sn, np.zeros((1, 1, 1, tn.shape[2]), dtype=np.complex128)
    gx = np.empty((m, b, tn.shape[2]), dtype=np.complex128)
    gu = np.empty((m, b, un.shape[1]))
    _adjoint_kernel(tn, un, float(dt), DX, final, dtraj, full, gx, gu)
    return _real(gx), torch.from_numpy(gu)


KERNELS = Kernels("dipole", _run_forward, _run_adjoint)


def simulate(psi0: torch.Tensor, u: torch.Tensor, dt: float = DT, return_trajectory: bool = False) -> torch.Tensor:
    """``dipole.simulate`` (same arguments, shapes, dtype) through the compiled loop.

    Falls back to the reference for tensors off the CPU or without numba.
    """
    if not available(psi0, u):
        return simulate_reference(psi0, u, dt, return_trajectory)
    return run(KERNELS, psi0, u.to(psi0.dtype), (float(dt),), bool(return_trajectory))


def solver_jacobian(psi0: torch.Tensor, u: torch.Tensor, dt: float = DT) -> tuple[torch.Tensor, torch.Tensor]:
    """Final states y (b, 28) (real/imaginary parts interleaved, as ``simulate(...).reshape(b, -1)``)
    and solver Jacobians A (b, 28, steps) = dy_i/du_i: one sweep with 28 seeds per sample."""
    traj = _run_forward(psi0, u, (float(dt),))
    b, n = traj.shape[0], traj.shape[2]
    m = 2 * n
    seeds = torch.eye(m, dtype=torch.float64).reshape(m, 1, n, 2).expand(m, b, n, 2)
    _, gu = _run_adjoint(traj, u, (float(dt),), seeds, False)
    return traj[:, -1].reshape(b, m).to(psi0.dtype), gu.permute(1, 0, 2).to(u.dtype)
