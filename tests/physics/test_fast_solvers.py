"""The fast solvers (compiled loop + hand-derived adjoint) against the reference torch solvers.

The issue's bar: equal to 1e-10 relative in float64, outputs, gradients and solver Jacobians,
at the paper's sizes (96 RK4 steps, 384 Crank-Nicolson steps).
"""

import pytest
import torch

from higbench.optim.structured import solver_jacobian
from higbench.physics import dipole, dipole_fast, oscillator, oscillator_fast

F64 = torch.float64
TOL = 1e-10


def gen(seed):
    return torch.Generator().manual_seed(seed)


def rel(a, b):
    return ((a - b).norm() / b.norm()).item()


def osc_case(b=16, steps=96):
    return torch.rand(b, 4, generator=gen(0), dtype=F64), torch.randn(b, steps, generator=gen(1), dtype=F64)


def dip_case(b=6, steps=384):
    psi = torch.randn(b, 14, 2, generator=gen(2), dtype=F64)
    psi = psi / psi.square().sum((-2, -1), keepdim=True).sqrt()
    return psi, 3.0 * torch.randn(b, steps, generator=gen(3), dtype=F64)


CASES = {
    "oscillator": (oscillator.simulate, oscillator_fast.simulate, osc_case),
    "dipole": (dipole.simulate, dipole_fast.simulate, dip_case),
}


@pytest.mark.parametrize("name", CASES)
@pytest.mark.parametrize("trajectory", [False, True])
def test_outputs_and_gradients_equal_reference(name, trajectory):
    ref, fast, case = CASES[name]
    x0, u = case()
    outs, grads = [], []
    for solve in (ref, fast):
        x, v = x0.clone().requires_grad_(), u.clone().requires_grad_()
        y = solve(x, v, return_trajectory=trajectory)
        w = torch.randn(y.shape, generator=gen(4), dtype=F64)  # a generic cotangent
        (y * w).sum().backward()
        outs.append(y.detach())
        grads.append((x.grad, v.grad))
    assert rel(outs[1], outs[0]) < TOL
    assert rel(grads[1][0], grads[0][0]) < TOL and rel(grads[1][1], grads[0][1]) < TOL


@pytest.mark.parametrize("name", CASES)
def test_solver_jacobian_routes_equal_reference(name):
    ref, fast, case = CASES[name]
    x0, u = case(b=4)

    def wrap(solve):
        return lambda x, v: solve(x, v).reshape(v.shape[0], -1)

    y_ref, A_ref = solver_jacobian(wrap(ref), x0, u)  # autograd, is_grads_batched, reference
    y_bat, A_bat = solver_jacobian(wrap(fast), x0, u)  # autograd through the fast Function
    direct = oscillator_fast.solver_jacobian if name == "oscillator" else dipole_fast.solver_jacobian
    y_dir, A_dir = direct(x0, u)  # one adjoint sweep with |y| seeds per sample
    for y, A in ((y_bat, A_bat), (y_dir.reshape(y_ref.shape), A_dir)):
        assert A.shape == A_ref.shape
        assert rel(y, y_ref) < TOL and rel(A, A_ref) < TOL


@pytest.mark.parametrize("name", CASES)
def test_float32_in_float32_out(name):
    ref, fast, case = CASES[name]
    x0, u = case(b=3, steps=24)
    x, v = x0.float().requires_grad_(), u.float().requires_grad_()
    y = fast(x, v)
    y.square().sum().backward()
    assert y.dtype == x.grad.dtype == v.grad.dtype == torch.float32
    # Computed in float64 inside: the float32 result is the float64 one, rounded.
    torch.testing.assert_close(y.double(), ref(x0, u), atol=1e-6, rtol=1e-6)


def test_second_derivative_is_refused():
    x0, u = osc_case(b=2, steps=3)
    v = u.clone().requires_grad_()
    (g,) = torch.autograd.grad(oscillator_fast.simulate(x0, v).square().sum(), v, create_graph=True)
    with pytest.raises(RuntimeError, match="second derivative"):
        g.sum().backward()


@pytest.mark.parametrize("problem", ["oscillator", "dipole"])
def test_problem_solver_key_selects_the_implementation(problem):
    from hydra import compose, initialize_config_dir

    from higbench.config import config_dir
    from higbench.problems.base import build_problem

    built = {}
    for solver in ("fast", "reference"):
        with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
            cfg = compose(config_name="config", overrides=[f"problem={problem}", f"problem.solver={solver}"])
        built[solver] = build_problem(cfg.problem, F64, torch.device("cpu"), 0)
    batch = built["fast"].test_set()[:3]
    u = 0.1 * torch.randn(3, int(built["fast"].cfg.steps), generator=gen(5), dtype=F64)
    y_fast, y_ref = (built[s].physics(batch.inputs, u) for s in ("fast", "reference"))
    assert rel(y_fast, y_ref) < TOL
    assert built["reference"].physics_jacobian(batch.inputs, u) is None
    y, A = built["fast"].physics_jacobian(batch.inputs, u)
    y_auto, A_auto = solver_jacobian(built["reference"].physics, batch.inputs, u)
    assert rel(y, y_auto) < TOL and rel(A, A_auto) < TOL
