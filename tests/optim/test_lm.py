"""Levenberg-Marquardt: the direction against a dense reference, convergence on a linear
least-squares problem, Nielsen's accept/reject, and a run through the runner."""

import math

import pytest
import torch
from optim_helpers import CASES, flat, setup
from torch import nn

from higbench.optim import inversion
from higbench.optim.lm import LevenbergMarquardt
from higbench.optim.structured import network_jacobian, solver_jacobian
from higbench.runner.updates import build_update


def linear_problem(seed=0, b=6, n_in=3, n_out=4):
    torch.manual_seed(seed)
    model = nn.Sequential(nn.Linear(n_in, n_out)).double()
    z = torch.randn(b, n_in, dtype=torch.float64)
    target = torch.randn(b, n_out, dtype=torch.float64)
    return model, z, target


def half_squares(y, target):
    return 0.5 * ((y - target) ** 2).sum(1)


@pytest.mark.parametrize("route,tridiagonal", [("gram", False), ("gram", True), ("svd", False)])
def test_direction_is_the_dense_damped_gauss_newton_step(route, tridiagonal, monkeypatch):
    """d = J^T (K + lam I)^-1 g (what LM computes) = (J^T J + lam I)^-1 J^T g (push-through)."""
    if tridiagonal:  # the route large K takes (no U formed), on a small one
        monkeypatch.setattr(inversion, "TRIDIAGONAL_MIN_ROWS", 8)
    model, z, target = linear_problem()
    model.append(nn.Tanh()).append(nn.Linear(4, 5).double())
    opt = LevenbergMarquardt(model.parameters(), solver=route)
    y, A = solver_jacobian(lambda u: torch.sin(u), None, model(z))
    J = network_jacobian(model, opt.params, z, A)
    g = torch.randn(J.rows, dtype=torch.float64)
    Jm = J.matrix()
    route_, J_, K = opt._derivative_tail(J)
    assert route_ == route
    ev, p, direction = opt._spectral(route, J_, K, g)
    for lam in (1e-3, 0.1, 10.0):
        d = direction(p / (ev + lam))
        dense = torch.linalg.solve(Jm.T @ Jm + lam * torch.eye(Jm.shape[1], dtype=Jm.dtype), Jm.T @ g)
        torch.testing.assert_close(d, dense, rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize("route", ["gram", "svd"])
def test_a_tall_jacobian_records_only_its_singular_values(route):
    """b * |y| = 160 rows, 16 parameters: K = J J^T has 144 structural zeros, which are no
    singular values of J and none that the damping or a truncation dropped."""
    model, z, target = linear_problem(b=40, n_in=3, n_out=4)
    opt = LevenbergMarquardt(model.parameters(), solver=route)
    J = network_jacobian(model, opt.params, z, solver_jacobian(lambda u: u, None, model(z))[1]).matrix()
    opt.step_structured(model, z, lambda u: u, lambda y: half_squares(y, target), reduction="sum")
    spectrum = opt.last_spectrum
    assert spectrum["sv_dropped"] == 0
    torch.testing.assert_close(
        torch.as_tensor(sorted(spectrum["singular_values"], reverse=True)), torch.linalg.svdvals(J), rtol=1e-8, atol=1e-10
    )


def test_converges_on_linear_least_squares_in_a_few_steps():
    model, z, target = linear_problem()
    X = torch.cat([z, torch.ones(len(z), 1, dtype=z.dtype)], 1)
    best = half_squares(X @ torch.linalg.lstsq(X, target).solution, target).sum()
    opt = LevenbergMarquardt(model.parameters(), damping=1e-3)
    losses = [
        float(opt.step_structured(model, z, lambda u: u, lambda y: half_squares(y, target), reduction="sum")) for _ in range(4)
    ]
    with torch.no_grad():
        final = half_squares(model(z), target).sum()
    assert float(final - best) <= 1e-6 * float(best), (losses, float(final), float(best))
    assert opt.group["lam"] < 1e-3 * opt.last_spectrum["sv_max"] ** 2  # accepted steps shrink lambda
    assert opt.last_spectrum["lm_accepted"]


def test_rejected_steps_restore_the_parameters_and_grow_lambda():
    model, z, target = linear_problem()
    opt = LevenbergMarquardt(model.parameters(), max_tries=3, lr=50.0)  # lr=50 overshoots: every trial rejected
    before = flat(model)
    opt.step_structured(model, z, lambda u: u, lambda y: half_squares(y, target), reduction="sum")
    assert torch.equal(flat(model), before)
    lam0 = 1e-3 * opt.last_spectrum["sv_max"] ** 2
    assert opt.group["lam"] == pytest.approx(lam0 * 2 * 4 * 8) and opt.group["nu"] == 16.0
    assert opt.last_finite and not opt.last_spectrum["lm_accepted"]


def test_lambda_is_checkpointed_with_the_optimizer():
    model, z, target = linear_problem()
    opt = LevenbergMarquardt(model.parameters())
    opt.step_structured(model, z, lambda u: u, lambda y: half_squares(y, target), reduction="sum")
    other = LevenbergMarquardt(model.parameters())
    other.load_state_dict(opt.state_dict())
    assert other.group["lam"] == opt.group["lam"] and math.isfinite(other.group["lam"])


@pytest.mark.parametrize("case", ["toy", "oscillator"])
def test_runner_update_reduces_the_loss(case):
    cfg, p, model, batch = setup(case, 16, optimizer="lm")
    update = build_update(p, model, cfg.optimizer)
    results = [update(batch) for _ in range(4)]
    assert all(r.finite for r in results)
    assert results[-1].loss < results[0].loss
    assert {"sv_max", "sv_min_kept", "sv_dropped"} <= set(results[-1].spectrum)


@pytest.mark.parametrize("optimizer", ["lm", "lbfgs"])
@pytest.mark.parametrize("case", sorted(CASES))  # every problem config (tests/test_problems.py checks)
def test_runs_on_every_problem(case, optimizer):
    extra = ["problem.hidden=[16]"] if case == "poisson" else []
    if optimizer == "lbfgs":
        extra.append("optimizer.max_iter=3")
    cfg, p, model, batch = setup(case, 4, *extra, optimizer=optimizer)
    update = build_update(p, model, cfg.optimizer)
    before = flat(model)
    results = [update(batch) for _ in range(2)]
    assert all(r.finite for r in results), [r.reason for r in results]
    assert not torch.equal(flat(model), before)
    assert set(results[0].timings) == {"jacobian_s", "inversion_s", "apply_s"}
