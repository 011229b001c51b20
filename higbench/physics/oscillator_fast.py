"""Fast oscillator solver: the RK4 loop of ``higbench.physics.oscillator`` compiled, with its adjoint.

Same scheme, same arguments and results as ``oscillator.simulate`` (the reference, kept for
the tests and for ``problem.solver=reference``); equal to it to ~1e-13 relative in float64, outputs and
gradients (tests/physics/test_oscillator.py runs every test on both).

The state is s = (x1, x2, p1, p2), the right-hand side F(s) = (p, -a(x)) with the negated
acceleration a_i(x) = x_i +- k (x1 - x2)^3 - c_i u; one RK4 step is

    Y1 = s, Y2 = s + h/2 F(Y1), Y3 = s + h/2 F(Y2), Y4 = s + h F(Y3),
    s' = s + h/6 (F(Y1) + 2 F(Y2) + 2 F(Y3) + F(Y4)).

Its discrete adjoint (the exact transpose of the step's linearisation, so gradients equal
autograd's through the reference up to rounding): with lambda' = dL/ds' and Gk_i = dL/dF(Y_i),

    Gk4 = h/6 lambda',            Gk3 = h/3 lambda' + h  J4^T Gk4,
    Gk2 = h/3 lambda' + h/2 J3^T Gk3,  Gk1 = h/6 lambda' + h/2 J2^T Gk2,
    lambda = lambda' + sum_i J_i^T Gk_i,   dL/du = -sum_i c . (Gk_i)_p-part,

where J_i^T (gx, gp) = (-A(Y_i)^T gp, gx) and A = da/dx = [[1+e, -e], [-e, 1+e]], e = 3 k d^2.
The stage states are recomputed in the backward sweep from the stored step states.
"""

from __future__ import annotations

import numpy as np
import torch

from higbench.physics._adjoint import Kernels, as_numpy64, available, njit, on_host, run
from higbench.physics.oscillator import CONTROL, DT
from higbench.physics.oscillator import simulate as simulate_reference

# Arrays are sample-minor, (..., 4, b): the innermost loops run over independent samples and
# vectorise. The trajectory stays in that layout (it is private to the kernels).


@njit
def _forward_kernel(x0, u, dt, k, c1, c2, traj):
    """x0 (4, b), u (steps, b); writes traj (steps + 1, 4, b), traj[t] = state after t RK4 steps."""
    steps, b = u.shape
    h2, h6 = 0.5 * dt, dt / 6.0
    traj[0] = x0
    for t in range(steps):
        for i in range(b):
            x1, x2, p1, p2 = traj[t, 0, i], traj[t, 1, i], traj[t, 2, i], traj[t, 3, i]
            g1, g2 = c1 * u[t, i], c2 * u[t, i]
            d = x1 - x2
            f = k * d * d * d
            a1, a2 = x1 + f - g1, x2 - f - g2
            y1, y2 = x1 + h2 * p1, x2 + h2 * p2
            q1, q2 = p1 - h2 * a1, p2 - h2 * a2
            d = y1 - y2
            f = k * d * d * d
            b1, b2 = y1 + f - g1, y2 - f - g2
            y1, y2 = x1 + h2 * q1, x2 + h2 * q2
            r1, r2 = p1 - h2 * b1, p2 - h2 * b2
            d = y1 - y2
            f = k * d * d * d
            e1, e2 = y1 + f - g1, y2 - f - g2
            y1, y2 = x1 + dt * r1, x2 + dt * r2
            s1, s2 = p1 - dt * e1, p2 - dt * e2
            d = y1 - y2
            f = k * d * d * d
            f1, f2 = y1 + f - g1, y2 - f - g2
            traj[t + 1, 0, i] = x1 + h6 * (p1 + 2.0 * (q1 + r1) + s1)
            traj[t + 1, 1, i] = x2 + h6 * (p2 + 2.0 * (q2 + r2) + s2)
            traj[t + 1, 2, i] = p1 - h6 * (a1 + 2.0 * (b1 + e1) + f1)
            traj[t + 1, 3, i] = p2 - h6 * (a2 + 2.0 * (b2 + e2) + f2)


@njit
def _adjoint_kernel(traj, u, dt, k, c1, c2, seeds, dtraj, has_dtraj, gx, gu):
    """Reverse sweep for m seeds per sample at once.

    seeds (m, 4, b): dL/d(final state); dtraj (m, steps + 1, 4, b): dL/d(every state), read
    only if has_dtraj. Writes gx (m, 4, b) = dL/dx0 and gu (m, steps, b) = dL/du.
    """
    m, b = seeds.shape[0], seeds.shape[2]
    steps = u.shape[0]
    h2, h6 = 0.5 * dt, dt / 6.0
    lam = seeds.copy()
    if has_dtraj:
        for j in range(m):
            lam[j] += dtraj[j, steps]
    # Stiffness e = 3 k d^2 of the four stages of step t, shared by the m seeds.
    st = np.empty((4, b))
    for t in range(steps - 1, -1, -1):
        for i in range(b):
            # Recompute the stage positions of step t from its stored state.
            x1, x2, p1, p2 = traj[t, 0, i], traj[t, 1, i], traj[t, 2, i], traj[t, 3, i]
            g1, g2 = c1 * u[t, i], c2 * u[t, i]
            d = x1 - x2
            f = k * d * d * d
            st[0, i] = 3.0 * k * d * d
            a1, a2 = x1 + f - g1, x2 - f - g2
            y1, y2 = x1 + h2 * p1, x2 + h2 * p2
            d = y1 - y2
            f = k * d * d * d
            st[1, i] = 3.0 * k * d * d
            b1, b2 = y1 + f - g1, y2 - f - g2
            q1, q2 = p1 - h2 * a1, p2 - h2 * a2
            d = (x1 + h2 * q1) - (x2 + h2 * q2)
            st[2, i] = 3.0 * k * d * d
            r1, r2 = p1 - h2 * b1, p2 - h2 * b2
            d = (x1 + dt * r1) - (x2 + dt * r2)
            st[3, i] = 3.0 * k * d * d
        for j in range(m):
            for i in range(b):
                e_1, e_2, e_3, e_4 = st[0, i], st[1, i], st[2, i], st[3, i]
                lx1, lx2, lp1, lp2 = lam[j, 0, i], lam[j, 1, i], lam[j, 2, i], lam[j, 3, i]
                # Stage 4: dL/dk4 = h/6 lambda'; k4 = (v4, -a4): v-part gx, a-part -gp.
                vx1, vx2 = h6 * lx1, h6 * lx2
                va1, va2 = -h6 * lp1, -h6 * lp2  # dL/d(a4)
                # Back through Y4 = (x + h r, p - h c): position gets A^T va, momentum gets vx.
                px1 = va1 + e_4 * (va1 - va2)
                px2 = va2 - e_4 * (va1 - va2)
                ax1, ax2 = px1, px2  # accumulated dL/dx from the stages
                ap1, ap2 = vx1, vx2  # accumulated dL/dp
                du = -(c1 * va1 + c2 * va2)
                # Stage 3: v3 = r gets 2h/6 lambda'_x + h dL/dY4pos; a3 gets -2h/6 lambda'_p - h dL/dY4mom.
                vx1, vx2 = 2.0 * h6 * lx1 + dt * px1, 2.0 * h6 * lx2 + dt * px2
                va1, va2 = -2.0 * h6 * lp1 - dt * ap1, -2.0 * h6 * lp2 - dt * ap2
                px1 = va1 + e_3 * (va1 - va2)
                px2 = va2 - e_3 * (va1 - va2)
                ax1, ax2 = ax1 + px1, ax2 + px2
                ap1, ap2 = ap1 + vx1, ap2 + vx2
                du -= c1 * va1 + c2 * va2
                # Stage 2.
                mx1, mx2 = vx1, vx2  # dL/d(momentum of Y3)
                vx1, vx2 = 2.0 * h6 * lx1 + h2 * px1, 2.0 * h6 * lx2 + h2 * px2
                va1, va2 = -2.0 * h6 * lp1 - h2 * mx1, -2.0 * h6 * lp2 - h2 * mx2
                px1 = va1 + e_2 * (va1 - va2)
                px2 = va2 - e_2 * (va1 - va2)
                ax1, ax2 = ax1 + px1, ax2 + px2
                ap1, ap2 = ap1 + vx1, ap2 + vx2
                du -= c1 * va1 + c2 * va2
                # Stage 1 (Y1 = s).
                mx1, mx2 = vx1, vx2
                vx1, vx2 = h6 * lx1 + h2 * px1, h6 * lx2 + h2 * px2
                va1, va2 = -h6 * lp1 - h2 * mx1, -h6 * lp2 - h2 * mx2
                px1 = va1 + e_1 * (va1 - va2)
                px2 = va2 - e_1 * (va1 - va2)
                ax1, ax2 = ax1 + px1, ax2 + px2
                ap1, ap2 = ap1 + vx1, ap2 + vx2
                du -= c1 * va1 + c2 * va2
                gu[j, t, i] = du
                lam[j, 0, i], lam[j, 1, i] = lx1 + ax1, lx2 + ax2
                lam[j, 2, i], lam[j, 3, i] = lp1 + ap1, lp2 + ap2
            if has_dtraj:
                lam[j] += dtraj[j, t]
    gx[:] = lam


def _sample_minor(x: torch.Tensor, batch_dim: int) -> np.ndarray:
    """float64 NumPy copy with dimension ``batch_dim`` moved last (C-contiguous)."""
    return np.ascontiguousarray(np.moveaxis(as_numpy64(x), batch_dim, -1))


def _run_forward(x0: torch.Tensor, u: torch.Tensor, params: tuple) -> torch.Tensor:
    """All states, float64, no graph, in the kernels' layout (steps + 1, 4, b)."""
    dt, k, c1, c2 = params
    x0n, un = _sample_minor(x0, 0), _sample_minor(u, 0)
    traj = np.empty((un.shape[0] + 1, 4, un.shape[1]))
    _forward_kernel(x0n, un, float(dt), float(k), float(c1), float(c2), traj)
    return torch.from_numpy(traj)


def _run_adjoint(
    traj: torch.Tensor, u: torch.Tensor, params: tuple, seeds: torch.Tensor, full: bool
) -> tuple[torch.Tensor, torch.Tensor]:
    """Gradients (m, b, 4) w.r.t. x0 and (m, b, steps) w.r.t. u for m cotangents per sample.

    seeds: (m, b, 4) on the final state, or (m, b, steps + 1, 4) on every state if ``full``.
    """
    dt, k, c1, c2 = params
    tn, un, sn = as_numpy64(traj), _sample_minor(u, 0), _sample_minor(seeds, 1)
    m, b = sn.shape[0], tn.shape[-1]
    if full:
        final, dtraj = np.zeros((m, 4, b)), sn
    else:
        final, dtraj = sn, np.zeros((1, 1, 4, b))
    gx, gu = np.empty((m, 4, b)), np.empty((m, un.shape[0], b))
    _adjoint_kernel(tn, un, float(dt), float(k), float(c1), float(c2), final, dtraj, full, gx, gu)
    return torch.from_numpy(gx).transpose(1, 2), torch.from_numpy(gu).transpose(1, 2)


KERNELS = Kernels("oscillator", _run_forward, _run_adjoint, batch_dim=2)


@on_host
def simulate(
    x0: torch.Tensor,
    u: torch.Tensor,
    dt: float = DT,
    coupling: float = 1.0,
    control: tuple[float, float] = CONTROL,
    return_trajectory: bool = False,
) -> torch.Tensor:
    """``oscillator.simulate`` (same arguments, shapes, dtype) through the compiled loop.

    Runs on the host for tensors on any device (``on_host``); the reference runs without numba.
    """
    if not available(x0, u):
        return simulate_reference(x0, u, dt, coupling, control, return_trajectory)
    c1, c2 = (float(c) for c in control)
    return run(KERNELS, x0, u.to(x0.dtype), (float(dt), float(coupling), c1, c2), bool(return_trajectory))


@on_host
def solver_jacobian(
    x0: torch.Tensor, u: torch.Tensor, dt: float = DT, coupling: float = 1.0, control: tuple[float, float] = CONTROL
) -> tuple[torch.Tensor, torch.Tensor]:
    """Final states y (b, 4) and solver Jacobians A (b, 4, steps) = dy_i/du_i: one sweep, 4 seeds per sample."""
    c1, c2 = (float(c) for c in control)
    params = (float(dt), float(coupling), c1, c2)
    traj = _run_forward(x0, u, params)
    b = traj.shape[2]
    seeds = torch.eye(4, dtype=torch.float64)[:, None, :].expand(4, b, 4)
    _, gu = _run_adjoint(traj, u, params, seeds, False)
    return traj[-1].T.to(x0.dtype), gu.permute(1, 0, 2).to(u.dtype)
