"""Physics of the coupled-oscillator solver: RK4 order, conservation laws, reference ODE solver, autograd.

Every test that integrates runs on both implementations (``problem.solver``): the reference
torch solver and the compiled loop with its hand-derived adjoint (``simulate`` fixture).
"""

import math

import numpy as np
import pytest
import torch
from scipy.integrate import solve_ivp

from higbench.physics import oscillator, oscillator_fast
from higbench.physics.oscillator import energy

F64 = torch.float64


@pytest.fixture(params=["reference", "fast"])
def simulate(request):
    return {"reference": oscillator.simulate, "fast": oscillator_fast.simulate}[request.param]


def states(b, seed=0, dtype=F64):
    return torch.rand(b, 4, generator=torch.Generator().manual_seed(seed), dtype=dtype)


def controls(b, steps, seed=1, dtype=F64):
    return torch.randn(b, steps, generator=torch.Generator().manual_seed(seed), dtype=dtype)


def rhs(t, y, u, k=1.0, c=(0.0, 3.0)):
    x1, x2, p1, p2 = y
    f = k * (x1 - x2) ** 3
    return [p1, p2, -x1 - f + u * c[0], -x2 + f + u * c[1]]


def scipy_reference(x0, u, dt, k=1.0, c=(0.0, 3.0)):
    """Integrate step by step with the control held constant in each step."""
    y = np.asarray(x0, dtype=float)
    for ut in u:
        y = solve_ivp(rhs, (0.0, dt), y, args=(float(ut), k, c), method="DOP853", rtol=1e-10, atol=1e-10).y[:, -1]
    return y


def test_shapes_and_trajectory(simulate):
    x0, u = states(3), controls(3, 7)
    out = simulate(x0, u)
    traj = simulate(x0, u, return_trajectory=True)
    assert out.shape == (3, 4) and traj.shape == (3, 8, 4)
    torch.testing.assert_close(traj[:, 0], x0, rtol=0, atol=0)
    torch.testing.assert_close(traj[:, -1], out, rtol=0, atol=0)
    assert simulate(x0.float(), u.float()).dtype == torch.float32


def test_rk4_fourth_order(simulate):
    # Constant control keeps the ODE autonomous, so only the integrator's error is measured.
    x0, u = states(4), 0.5 * torch.ones(4, 1, dtype=F64)
    t_end = 3.0
    ref = simulate(x0, u.expand(4, 3 * 256), dt=t_end / (3 * 256))
    errs = []
    for steps in (12, 24, 48):
        out = simulate(x0, u.expand(4, steps), dt=t_end / steps)
        errs.append((out - ref).abs().max().item())
    orders = [math.log2(errs[i] / errs[i + 1]) for i in range(2)]
    assert all(3.5 < p < 4.5 for p in orders), (errs, orders)


def test_uncoupled_energy_per_oscillator_conserved(simulate):
    x0, u = states(8), torch.zeros(8, 96, dtype=F64)
    traj = simulate(x0, u, coupling=0.0, return_trajectory=True)
    e = 0.5 * (traj[..., :2] ** 2 + traj[..., 2:] ** 2)  # (b, steps+1, 2)
    # RK4 on a harmonic oscillator scales the energy by |R(i dt)|^2 = 1 - dt^6/72 + dt^8/576
    # per step, for every state: conserved up to exactly that integrator error.
    per_step = 1.0 - 0.125**6 / 72 + 0.125**8 / 576
    expected = per_step ** torch.arange(97, dtype=F64)
    torch.testing.assert_close(e / e[:, :1], expected[None, :, None].expand_as(e), rtol=1e-12, atol=0)
    assert 1.0 - expected[-1] < 1e-5


def test_coupled_hamiltonian_conserved(simulate):
    x0 = states(8)
    traj = simulate(x0, torch.zeros(8, 96, dtype=F64), coupling=1.0, return_trajectory=True)
    h = energy(traj, coupling=1.0)
    assert ((h - h[:, :1]).abs() / h[:, :1]).max() < 1e-4  # measured 1.4e-5 at dt = 0.125
    traj = simulate(x0, torch.zeros(8, 384, dtype=F64), dt=0.125 / 4, coupling=1.0, return_trajectory=True)
    h = energy(traj, coupling=1.0)
    assert ((h - h[:, :1]).abs() / h[:, :1]).max() < 1e-4 / 4**4


def test_energy_is_the_hamiltonian_of_the_equations():
    # dH/dt along the flow with u = 0 is zero: grad H . f = 0.
    y = states(5).requires_grad_()
    (g,) = torch.autograd.grad(energy(y, coupling=1.0).sum(), y)
    f = torch.tensor([rhs(0.0, yi, 0.0) for yi in y.detach().tolist()], dtype=F64)
    torch.testing.assert_close((g * f).sum(-1), torch.zeros(5, dtype=F64), atol=1e-14, rtol=0)


def numpy_rk4(x0, u, dt, k=1.0, c=(0.0, 3.0)):
    """Plain transcription of the classic RK4 tableau, one sample: x0 (4,), u (steps,) -> (steps+1, 4)."""
    ys = [np.asarray(x0, dtype=float)]
    for ut in u:

        def f(z, ut=float(ut)):
            return np.array(rhs(0.0, z, ut, k, c))

        y = ys[-1]
        k1 = f(y)
        k2 = f(y + dt / 2 * k1)
        k3 = f(y + dt / 2 * k2)
        k4 = f(y + dt * k3)
        ys.append(y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4))
    return np.stack(ys)


@pytest.mark.parametrize("k,c,dt", [(1.0, (0.0, 3.0), 0.125), (0.5, (1.0, -2.0), 0.05), (0.0, (0.0, 3.0), 0.2)])
def test_is_classic_rk4(simulate, k, c, dt):
    x0, u = states(3, seed=7), controls(3, 6, seed=8)
    out = simulate(x0, u, dt=dt, coupling=k, control=c, return_trajectory=True)
    for i in range(3):
        np.testing.assert_allclose(out[i].numpy(), numpy_rk4(x0[i].numpy(), u[i].numpy(), dt, k, c), atol=1e-14, rtol=0)


def test_converges_to_scipy_with_piecewise_constant_control(simulate):
    # One control value per 0.125 time units, held constant; finer RK4 steps repeat it.
    x0, u = states(2, seed=3), controls(2, 24, seed=4)
    ref = np.stack([scipy_reference(x0[i].numpy(), u[i].numpy(), 0.125) for i in range(2)])
    errs = [np.abs(simulate(x0, u.repeat_interleave(r, 1), dt=0.125 / r).numpy() - ref).max() for r in (1, 2, 4)]
    assert errs[0] < 1e-4 and errs[2] < 1e-6, errs  # measured 1.8e-5, 1.2e-6, 7.4e-8
    orders = [math.log2(errs[i] / errs[i + 1]) for i in range(2)]
    assert all(3.5 < p < 4.5 for p in orders), (errs, orders)


def test_matches_scipy_full_horizon(simulate):
    # The paper's setting: 96 steps of 0.125. The global RK4 error over 12 time units is
    # ~1e-4 (u = 0) to ~1e-3 (u ~ 0.3 N(0,1)), grown from ~1e-7 local errors by the dynamics.
    x0, u = states(2, seed=3), 0.3 * controls(2, 96, seed=4)
    out = simulate(x0, u)
    for i in range(2):
        np.testing.assert_allclose(out[i].numpy(), scipy_reference(x0[i].numpy(), u[i].numpy(), 0.125), atol=3e-3, rtol=0)


def test_float32_matches_float64(simulate):
    x0, u = states(16), controls(16, 96)
    out64 = simulate(x0, u)
    out32 = simulate(x0.float(), u.float())
    torch.testing.assert_close(out32.double(), out64, atol=1e-4, rtol=1e-4)


def test_batch_independence(simulate):
    x0, u = states(6), controls(6, 20)
    full = simulate(x0, u)
    for i in (0, 4):
        torch.testing.assert_close(simulate(x0[i : i + 1], u[i : i + 1])[0], full[i], rtol=0, atol=1e-15)
    jac = torch.autograd.functional.jacobian(lambda v: simulate(x0, v), u)  # (b, 4, b, steps)
    off = jac.clone()
    off[range(6), :, range(6)] = 0.0
    assert off.abs().max() == 0.0 and jac.abs().max() > 0.0


def test_gradcheck(simulate):
    x0 = states(2).requires_grad_()
    u = controls(2, 3).requires_grad_()
    assert torch.autograd.gradcheck(lambda a, b: simulate(a, b, dt=0.2), (x0, u))


def test_torch_func_per_sample_jacobian(simulate):
    # The HIG Jacobian code runs the physics under vmap(jacrev(...)) with a batch of one.
    x0, u = states(3), controls(3, 8)

    def single(x, v):
        return simulate(x[None], v[None])[0]

    jac = torch.func.vmap(torch.func.jacrev(single, argnums=1))(x0, u)  # (b, 4, steps)
    full = torch.autograd.functional.jacobian(lambda v: simulate(x0, v), u)
    torch.testing.assert_close(jac, full[range(3), :, range(3)])
