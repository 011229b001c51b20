"""The runner's GN/HIG update against brute force: torch.func Jacobian of the whole batch + SVD."""

import pytest
import torch
from cases import PROBLEMS
from hydra import compose, initialize_config_dir

from higbench.config import config_dir
from higbench.optim import jacobian_power
from higbench.optim.jacobians import full_jacobian, per_sample_jacobian
from higbench.problems import build_problem
from higbench.runner.updates import build_update


def setup(problem, optimizer, *overrides):
    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        cfg = compose(config_name="config", overrides=[f"problem={problem}", f"optimizer={optimizer}", *overrides])
    p = build_problem(cfg.problem, dtype=torch.float64, device=torch.device("cpu"), seed=0)
    model = p.build_model()
    batch = next(p.epoch(3, torch.Generator().manual_seed(0)))
    return cfg, p, model, batch


SHORT = {"oscillator": "problem.steps=8", "dipole": "problem.steps=8"}  # short horizons: the full Jacobian stays small


@pytest.mark.parametrize("problem", PROBLEMS)
def test_per_sample_jacobian_is_the_block_rows_of_the_full_jacobian(problem):
    _, p, model, batch = setup(problem, "hig", SHORT.get(problem, "seed=0"))
    J = per_sample_jacobian(model, p.physics, batch.inputs, batch.net_inputs)
    J_full = full_jacobian(model, p.physics, batch.inputs, batch.net_inputs)
    assert J.shape == J_full.shape
    torch.testing.assert_close(J, J_full, rtol=1e-9, atol=1e-12)


def test_full_jacobian_matches_finite_differences():
    _, p, model, batch = setup("oscillator", "hig", "problem.steps=8")
    J = full_jacobian(model, p.physics, batch.inputs, batch.net_inputs)
    params = list(model.parameters())
    h = 1e-6
    for tensor, index in ((params[0], (3, 1)), (params[-1], (5,)), (params[2], (0, 7))):
        with torch.no_grad():
            base = p.outputs(model, batch).reshape(-1)
            tensor[index] += h
            bumped = p.outputs(model, batch).reshape(-1)
            tensor[index] -= h
        flat = (
            sum(q.numel() for q in params[: [id(q) for q in params].index(id(tensor))])
            + torch.tensor(index).dot(torch.tensor(tensor.stride()[: len(index)])).item()
        )
        torch.testing.assert_close((bumped - base) / h, J[:, flat], rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize(
    "problem,optimizer,extra",
    [
        ("toy", "hig", ["problem.gamma=0.01"]),  # tall J (6 x 30)
        ("toy", "gn", []),
        ("oscillator", "hig", ["problem.steps=8", "optimizer.tau=1e-4"]),  # wide J (12 x ~700)
        ("dipole", "hig", ["problem.steps=6"]),
    ],
)
def test_one_update_equals_brute_force_jacobian_power(problem, optimizer, extra):
    cfg, p, model, batch = setup(problem, optimizer, "optimizer.lr=0.5", *extra)
    y = p.outputs(model, batch)
    loss = p.loss(y, batch.targets).mean()
    (g,) = torch.autograd.grad(loss, y)
    J = full_jacobian(model, p.physics, batch.inputs, batch.net_inputs)
    o = cfg.optimizer
    expected = -0.5 * jacobian_power(J, g.reshape(-1), o.kappa, beta=o.beta, tau=o.tau, truncation=o.truncation)
    before = torch.cat([q.detach().reshape(-1).clone() for q in model.parameters()])
    result = build_update(p, model, cfg.optimizer)(batch)
    after = torch.cat([q.detach().reshape(-1) for q in model.parameters()])
    assert result.finite
    # Relative to the whole direction (the Gram route errs by ~eps/tau^2 on the smallest kept modes).
    assert torch.linalg.norm(after - before - expected) <= 1e-6 * torch.linalg.norm(expected)
