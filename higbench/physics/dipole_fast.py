"""Fast dipole solver: the Crank-Nicolson loop of ``higbench.physics.dipole`` compiled, with its adjoint.

Same scheme, arguments and results as ``dipole.simulate`` (the reference, kept for the tests
and for ``problem.solver=reference``); equal to it to ~1e-13 relative in float64, outputs and gradients
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

from higbench.physics._adjoint import Kernels, as_numpy64, available, njit, on_host, run
from higbench.physics.dipole import DT, DX
from higbench.physics.dipole import simulate as simulate_reference

# The kernels work on real/imaginary parts in real arithmetic (a compiled complex division is
# several times slower than one reciprocal of |den|^2), sample-minor: arrays are
# (..., n, 2, b) so that the innermost loop runs over independent samples and vectorises
# (the Thomas recursion itself is sequential in k). The trajectory stays in that layout
# (it is private to the kernels); only what leaves this module is transposed.


@njit
def _forward_kernel(psi0, u, dt, dx, traj):
    """psi0 (n, 2, b), u (steps, b); writes traj (steps + 1, n, 2, b), traj[0] = psi0."""
    steps, b = u.shape
    n = psi0.shape[0]
    a = 0.5 * dt
    alpha = a / (dx * dx)
    # M = 1 + i dt/2 H: diagonal 1 + i (2 alpha + a u x_k), off-diagonal beta = -i alpha.
    cr, ci = np.zeros((n, b)), np.zeros((n, b))  # cp_k = beta / den_k
    rr, ri = np.zeros((n, b)), np.zeros((n, b))  # rp_k = (psi_k - beta rp_{k-1}) / den_k
    traj[0] = psi0
    for t in range(steps):
        for k in range(n):
            xk = (k + 1) * dx
            km = max(k - 1, 0)
            first = 0.0 if k == 0 else 1.0
            for i in range(b):
                # den = d_k - beta cp_{k-1};  beta z = alpha Im z - i alpha Re z.
                pcr, pci = first * cr[km, i], first * ci[km, i]
                prr, pri = first * rr[km, i], first * ri[km, i]
                dr = 1.0 - alpha * pci
                di = 2.0 * alpha + a * u[t, i] * xk + alpha * pcr
                q = 1.0 / (dr * dr + di * di)
                ir, ii = dr * q, -di * q  # 1 / den
                cr[k, i], ci[k, i] = alpha * ii, -alpha * ir  # beta / den
                sr = traj[t, k, 0, i] - alpha * pri
                si = traj[t, k, 1, i] + alpha * prr
                rr[k, i], ri[k, i] = sr * ir - si * ii, sr * ii + si * ir
        # Back substitution w_k = rp_k - cp_k w_{k+1}, in place (rr, ri then hold w = M^{-1} psi).
        for k in range(n - 2, -1, -1):
            for i in range(b):
                wr, wi = rr[k + 1, i], ri[k + 1, i]
                rr[k, i] -= cr[k, i] * wr - ci[k, i] * wi
                ri[k, i] -= cr[k, i] * wi + ci[k, i] * wr
        for k in range(n):
            for i in range(b):
                traj[t + 1, k, 0, i] = 2.0 * rr[k, i] - traj[t, k, 0, i]
                traj[t + 1, k, 1, i] = 2.0 * ri[k, i] - traj[t, k, 1, i]


@njit
def _adjoint_kernel(traj, u, dt, dx, seeds, dtraj, has_dtraj, gx, gu):
    """Reverse sweep for m seeds per sample: seeds (m, n, 2, b) on the final state, dtraj
    (m, steps + 1, n, 2, b) on every state if has_dtraj. Writes gx (m, n, 2, b), gu (m, steps, b)."""
    m, n, b = seeds.shape[0], seeds.shape[1], seeds.shape[3]
    steps = u.shape[0]
    a = 0.5 * dt
    alpha = a / (dx * dx)
    # conj(M): diagonal 1 - i (2 alpha + a u x_k), off-diagonal beta = +i alpha.
    cr, ci, ir, ii = np.zeros((n, b)), np.zeros((n, b)), np.zeros((n, b)), np.zeros((n, b))
    rr, ri = np.zeros((n, b)), np.zeros((n, b))
    acc = np.zeros(b)
    g = seeds.copy()
    if has_dtraj:
        for j in range(m):
            g[j] += dtraj[j, steps]
    for t in range(steps - 1, -1, -1):
        for k in range(n):
            xk = (k + 1) * dx
            km = max(k - 1, 0)
            first = 0.0 if k == 0 else 1.0
            for i in range(b):
                # den = d_k - beta cp_{k-1};  beta z = -alpha Im z + i alpha Re z.
                dr = 1.0 + alpha * first * ci[km, i]
                di = -(2.0 * alpha + a * u[t, i] * xk) - alpha * first * cr[km, i]
                q = 1.0 / (dr * dr + di * di)
                ir[k, i], ii[k, i] = dr * q, -di * q
                cr[k, i], ci[k, i] = -alpha * ii[k, i], alpha * ir[k, i]
        for j in range(m):
            for k in range(n):
                km = max(k - 1, 0)
                first = 0.0 if k == 0 else 1.0
                for i in range(b):
                    sr = g[j, k, 0, i] + alpha * first * ri[km, i]
                    si = g[j, k, 1, i] - alpha * first * rr[km, i]
                    rr[k, i] = sr * ir[k, i] - si * ii[k, i]
                    ri[k, i] = sr * ii[k, i] + si * ir[k, i]
            # z = conj(M)^{-1} g by back substitution in place; then dL/du_t and g_old = 2 z - g.
            for k in range(n - 2, -1, -1):
                for i in range(b):
                    zr, zi = rr[k + 1, i], ri[k + 1, i]
                    rr[k, i] -= cr[k, i] * zr - ci[k, i] * zi
                    ri[k, i] -= cr[k, i] * zi + ci[k, i] * zr
            acc[:] = 0.0
            for k in range(n):
                xk = (k + 1) * dx
                for i in range(b):
                    wr = 0.5 * (traj[t + 1, k, 0, i] + traj[t, k, 0, i])  # M^{-1} psi_old
                    wi = 0.5 * (traj[t + 1, k, 1, i] + traj[t, k, 1, i])
                    acc[i] += (rr[k, i] * wi - ri[k, i] * wr) * xk  # Im(conj(z) w) x_k
                    g[j, k, 0, i] = 2.0 * rr[k, i] - g[j, k, 0, i]
                    g[j, k, 1, i] = 2.0 * ri[k, i] - g[j, k, 1, i]
            for i in range(b):
                gu[j, t, i] = dt * acc[i]
            if has_dtraj:
                g[j] += dtraj[j, t]
    for j in range(m):
        gx[j] = g[j]


def _sample_minor(x: torch.Tensor, batch_dim: int) -> np.ndarray:
    """float64 NumPy copy with dimension ``batch_dim`` moved last (C-contiguous)."""
    return np.ascontiguousarray(np.moveaxis(as_numpy64(x), batch_dim, -1))


def _run_forward(psi0: torch.Tensor, u: torch.Tensor, params: tuple) -> torch.Tensor:
    """All states, float64, no graph, in the kernels' layout (steps + 1, 14, 2, b)."""
    (dt,) = params
    p0, un = _sample_minor(psi0, 0), _sample_minor(u, 0)
    traj = np.empty((un.shape[0] + 1, *p0.shape))
    _forward_kernel(p0, un, float(dt), DX, traj)
    return torch.from_numpy(traj)


def _run_adjoint(
    traj: torch.Tensor, u: torch.Tensor, params: tuple, seeds: torch.Tensor, full: bool
) -> tuple[torch.Tensor, torch.Tensor]:
    """Gradients (m, b, 14, 2) w.r.t. psi0 and (m, b, steps) w.r.t. u for m cotangents per sample.

    seeds: (m, b, 14, 2) on the final state, or (m, b, steps + 1, 14, 2) on every state if ``full``.
    """
    (dt,) = params
    tn, un, sn = as_numpy64(traj), _sample_minor(u, 0), _sample_minor(seeds, 1)
    m, b, n = sn.shape[0], tn.shape[-1], tn.shape[1]
    if full:
        final, dtraj = np.zeros((m, n, 2, b)), sn
    else:
        final, dtraj = sn, np.zeros((1, 1, n, 2, b))
    gx, gu = np.empty((m, n, 2, b)), np.empty((m, un.shape[0], b))
    _adjoint_kernel(tn, un, float(dt), DX, final, dtraj, full, gx, gu)
    return torch.from_numpy(gx).permute(0, 3, 1, 2), torch.from_numpy(gu).transpose(1, 2)


KERNELS = Kernels("dipole", _run_forward, _run_adjoint, batch_dim=3)


@on_host
def simulate(psi0: torch.Tensor, u: torch.Tensor, dt: float = DT, return_trajectory: bool = False) -> torch.Tensor:
    """``dipole.simulate`` (same arguments, shapes, dtype) through the compiled loop.

    Runs on the host for tensors on any device (``on_host``); the reference runs without numba.
    """
    if not available(psi0, u):
        return simulate_reference(psi0, u, dt, return_trajectory)
    return run(KERNELS, psi0, u.to(psi0.dtype), (float(dt),), bool(return_trajectory))


@on_host
def solver_jacobian(psi0: torch.Tensor, u: torch.Tensor, dt: float = DT) -> tuple[torch.Tensor, torch.Tensor]:
    """Final states y (b, 28) (real/imaginary parts interleaved, as ``simulate(...).reshape(b, -1)``)
    and solver Jacobians A (b, 28, steps) = dy_i/du_i: one sweep with 28 seeds per sample."""
    traj = _run_forward(psi0, u, (float(dt),))
    n, b = traj.shape[1], traj.shape[3]
    m = 2 * n
    seeds = torch.eye(m, dtype=torch.float64).reshape(m, 1, n, 2).expand(m, b, n, 2)
    _, gu = _run_adjoint(traj, u, (float(dt),), seeds, False)
    return traj[-1].permute(2, 0, 1).reshape(b, m).to(psi0.dtype), gu.permute(1, 0, 2).to(u.dtype)
