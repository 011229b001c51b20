"""The runner's GN/HIG update: structured vs naive Jacobian, Gram vs SVD inversion, on every problem.

The reference is the naive path (torch.func J of network + solver) with the SVD of J. In
float64, the structured path with the SVD agrees to round-off. The Gram route agrees to its
precision limit: eigh(K) errs by ~eps*max(s)^2 per eigenvalue, i.e. relatively by ~eps/tau^2
at the cutoff (2e-6 at tau=1e-5, 2e-4 at tau=1e-6); below 1e-6 for tau >= 1e-5 on every
problem here, and within that bound at tau = 1e-6 (the dipole, whose unitary solver makes
J exactly rank-deficient per sample, shows ~1e-6..1e-5 there).
"""

import numpy as np
import pytest
import torch
from optim_helpers import CASES, flat, setup

from higbench.optim.hig import JacobianPower
from higbench.problems.toy import Toy
from higbench.runner.updates import build_update

EPS = float(np.finfo(np.float64).eps)


BATCH = {"poisson": 1, "dipole_cnn": 1}  # keep the naive reference (and its SVD) fast


def update_delta(case, tau, jacobian, solver, batch_size=None, *overrides, optimizer="hig"):
    batch_size = batch_size or BATCH.get(case, 3)
    cfg, p, model, batch = setup(
        case,
        batch_size,
        f"optimizer.tau={tau}",
        f"optimizer.jacobian={jacobian}",
        f"optimizer.solver={solver}",
        "optimizer.lr=1",
        *overrides,
        optimizer=optimizer,
    )
    before = flat(model)
    update = build_update(p, model, cfg.optimizer)
    result = update(batch)
    assert result.finite, result.reason
    assert set(result.timings) == {"jacobian_s", "inversion_s", "apply_s"}
    return flat(model) - before, update


def rel(a, b):
    return float(torch.linalg.norm(a - b) / torch.linalg.norm(b))


@pytest.mark.parametrize("case", list(CASES))
def test_all_paths_agree(case):
    # Poisson's spectrum spans 4 decades only: no truncation at either tau, one is enough.
    for tau in (1e-6,) if case == "poisson" else (1e-6, 1e-5):
        ref, update = update_delta(case, tau, "naive", "svd")
        assert not update.structured
        struct_svd, update = update_delta(case, tau, "structured", "svd")
        assert update.structured
        assert rel(struct_svd, ref) < 1e-9
        for jacobian in ("structured", "naive"):
            gram, _ = update_delta(case, tau, jacobian, "gram")
            # Measured here: <= 1.4e-7 (dipole, naive J); see the module docstring.
            assert rel(gram, ref) < 1e-6, (tau, jacobian, rel(gram, ref))


def test_gram_route_at_tau_1e6_within_its_precision_bound():
    """A case where the Gram route's eps/tau^2 limit shows: the dipole over 24 steps, b = 2.

    Measured 1.5e-5 relative (structured) at tau = 1e-6 (5.9e-9 at tau = 1e-5): above 1e-6,
    far inside the bound eps/tau^2 = 2.2e-4 of eigh in float64.
    """
    tau = 1e-6
    ref, _ = update_delta("dipole", tau, "naive", "svd", 2, "problem.steps=24")
    gram, _ = update_delta("dipole", tau, "structured", "gram", 2, "problem.steps=24")
    assert rel(gram, ref) < EPS / tau**2


def test_gauss_newton_paths_agree():
    ref, _ = update_delta("oscillator", 1e-4, "naive", "svd", optimizer="gn")
    gram, _ = update_delta("oscillator", 1e-4, "structured", "gram", optimizer="gn")
    assert rel(gram, ref) < 1e-6


def test_auto_solver_choice():
    params = [torch.nn.Parameter(torch.zeros(3))]
    opt = JacobianPower(params, tau=1e-6)
    assert opt.resolved_solver(rows=10, n_params=100) == "gram"  # wide: eigh of 10 x 10
    assert opt.resolved_solver(rows=512, n_params=30) == "svd"  # tall: thin SVD of J
    assert JacobianPower(params, tau=1e-8).resolved_solver(rows=10, n_params=100) == "svd"  # tau^2 near eps


def test_problem_with_its_own_outputs_uses_the_naive_path():
    class Custom(Toy):
        def outputs(self, model, batch):
            return super().outputs(model, batch)

    cfg, p, model, batch = setup("toy")
    custom = Custom(cfg.problem, dtype=torch.float64, device=torch.device("cpu"), seed=0)
    update = build_update(custom, model, cfg.optimizer)
    assert not update.structured
    assert update(batch).finite


def test_non_finite_weights_are_reported_not_applied():
    cfg, p, model, batch = setup("oscillator")
    with torch.no_grad():
        model[0].weight[0, 0] = float("nan")
    before = flat(model)
    result = build_update(p, model, cfg.optimizer)(batch)
    assert not result.finite and "non-finite" in result.reason
    torch.testing.assert_close(flat(model), before, equal_nan=True)


def test_runner_update_is_the_public_optimizer_step():
    """The runner calls JacobianPower.step_structured: same weights, timings and finiteness as a user's call."""
    cfg, p, model, batch = setup("oscillator")
    import copy

    from higbench.runner.updates import optimizer_kwargs

    user_model = copy.deepcopy(model)
    result = build_update(p, model, cfg.optimizer)(batch)
    opt = JacobianPower(user_model.parameters(), **optimizer_kwargs(cfg.optimizer))
    loss = lambda y: p.loss(y, batch.targets)  # noqa: E731
    opt.step_structured(user_model, batch.net_inputs, p.physics, loss, inputs=batch.inputs, physics_jacobian=p.physics_jacobian)
    torch.testing.assert_close(flat(user_model), flat(model), rtol=0, atol=0)
    assert result.finite and opt.last_finite
    assert set(result.timings) == set(opt.last_timings) == {"jacobian_s", "inversion_s", "apply_s"}


@pytest.mark.parametrize("solver", ["auto", "gram", "svd"])
@pytest.mark.parametrize("tau", [1e-4, 1e-6, 1e-8])
@pytest.mark.parametrize("rows,n_params", [(10, 100), (512, 30), (100, 100)])
def test_memory_guard_sizes_the_route_the_optimizer_takes(solver, tau, rows, n_params):
    from higbench.optim.memory_guard import estimate_bytes

    opt = JacobianPower([torch.nn.Parameter(torch.zeros(3))], tau=tau, solver=solver)
    assert estimate_bytes(rows, 1, n_params, solver=solver, tau=tau).solver == opt.resolved_solver(rows, n_params)


def test_public_optimizer_reports_a_non_finite_update_and_leaves_the_weights():
    cfg, p, model, batch = setup("oscillator")
    with torch.no_grad():
        model[0].weight[0, 0] = float("nan")
    before = flat(model)
    opt = JacobianPower(model.parameters(), tau=1e-6)
    opt.step_structured(model, batch.net_inputs, p.physics, lambda y: p.loss(y, batch.targets), inputs=batch.inputs)
    assert not opt.last_finite and "non-finite" in opt.last_reason and opt.last_timings == {}
    torch.testing.assert_close(flat(model), before, equal_nan=True)
