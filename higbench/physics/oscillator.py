"""Two coupled nonlinear oscillators with a control force, integrated with classic RK4.

State (x1, x2, p1, p2). Equations of motion (spec "oscillator", reference-code sign):

    dx_i/dt = p_i
    dp_i/dt = -x_i - k * (x_i - x_j)^3 + u(t) * c_i        (j = the other oscillator)

derived from H = sum_i (x_i^2 + p_i^2) / 2 + (k/4) (x1 - x2)^4 - u(t) * sum_i c_i x_i.

The solver is called thousands of times with (b, steps) = (512, 96), so it works on the
four state components as separate (b,) tensors (no stack/cat inside the time loop) and
tracks the *negated* accelerations so that every RK4 update is one ``torch.add``/``sub``
with a Python-scalar ``alpha``. Everything is plain torch, so autograd and torch.func
(vmap, jacrev, jvp) work through it.
"""

from __future__ import annotations

import torch

DT = 0.125
CONTROL = (0.0, 3.0)


def simulate(
    x0: torch.Tensor,
    u: torch.Tensor,
    dt: float = DT,
    coupling: float = 1.0,
    control: tuple[float, float] = CONTROL,
    return_trajectory: bool = False,
) -> torch.Tensor:
    """Integrate ``u.shape[1]`` RK4 steps of size ``dt``; u is constant within a step.

    x0: (b, 4) initial states (x1, x2, p1, p2); u: (b, steps) controls, same dtype.
    Returns the final state (b, 4), or with ``return_trajectory`` the states at every
    step including the initial one, (b, steps + 1, 4).
    """
    k = float(coupling)
    c1, c2 = (float(c) for c in control)
    x1, x2, p1, p2 = x0.unbind(-1)
    steps = u.shape[-1]
    # Per-step control forces, split once (unbind has a single backward node).
    f1 = (u * c1).unbind(-1) if c1 != 0.0 else (None,) * steps
    f2 = (u * c2).unbind(-1) if c2 != 0.0 else (None,) * steps

    def neg_acc(y1, y2, g1, g2):
        # -dp/dt for both oscillators.
        a1, a2 = y1, y2
        if k != 0.0:
            d3 = (y1 - y2).pow(3)
            a1 = torch.add(y1, d3, alpha=k)
            a2 = torch.sub(y2, d3, alpha=k)
        if g1 is not None:
            a1 = a1 - g1
        if g2 is not None:
            a2 = a2 - g2
        return a1, a2

    h2, h6 = 0.5 * dt, dt / 6.0
    traj = [(x1, x2, p1, p2)] if return_trajectory else None
    for t in range(steps):
        g1, g2 = f1[t], f2[t]
        # Stage 1..4: velocities are the stage momenta, forces from the stage positions.
        a1, a2 = neg_acc(x1, x2, g1, g2)
        y1, y2 = torch.add(x1, p1, alpha=h2), torch.add(x2, p2, alpha=h2)
        q1, q2 = torch.sub(p1, a1, alpha=h2), torch.sub(p2, a2, alpha=h2)
        b1, b2 = neg_acc(y1, y2, g1, g2)
        y1, y2 = torch.add(x1, q1, alpha=h2), torch.add(x2, q2, alpha=h2)
        r1, r2 = torch.sub(p1, b1, alpha=h2), torch.sub(p2, b2, alpha=h2)
        c1_, c2_ = neg_acc(y1, y2, g1, g2)
        y1, y2 = torch.add(x1, r1, alpha=dt), torch.add(x2, r2, alpha=dt)
        s1, s2 = torch.sub(p1, c1_, alpha=dt), torch.sub(p2, c2_, alpha=dt)
        d1, d2 = neg_acc(y1, y2, g1, g2)
        # Weighted sums k1 + 2 k2 + 2 k3 + k4 of velocities and (negated) accelerations.
        x1 = torch.add(x1, torch.add(torch.add(p1, q1 + r1, alpha=2.0), s1), alpha=h6)
        x2 = torch.add(x2, torch.add(torch.add(p2, q2 + r2, alpha=2.0), s2), alpha=h6)
        p1 = torch.sub(p1, torch.add(torch.add(a1, b1 + c1_, alpha=2.0), d1), alpha=h6)
        p2 = torch.sub(p2, torch.add(torch.add(a2, b2 + c2_, alpha=2.0), d2), alpha=h6)
        if traj is not None:
            traj.append((x1, x2, p1, p2))
    if traj is None:
        return torch.stack((x1, x2, p1, p2), dim=-1)
    comps = [torch.stack(c, dim=-1) for c in zip(*traj)]  # 4 x (b, steps + 1)
    return torch.stack(comps, dim=-1)


def energy(state: torch.Tensor, coupling: float = 1.0) -> torch.Tensor:
    """Hamiltonian without control, sum (x^2 + p^2)/2 + (k/4)(x1 - x2)^4. state (..., 4) -> (...)."""
    x1, x2, p1, p2 = state.unbind(-1)
    return 0.5 * (x1**2 + x2**2 + p1**2 + p2**2) + 0.25 * coupling * (x1 - x2) ** 4
