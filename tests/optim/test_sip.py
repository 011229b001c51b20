"""The SIP optimizer (higbench.optim.sip) and the problems' inverse simulators.

Against hand computations: on the toy, with its exact inverse and the full Newton step in
y, the SIP target is the true target mapped back through u = (y1, y2 / gamma); at gamma = 1
the SIP update is Adam's. Poisson's inverse is exact (P(P^-1(y)) = y on random y); the heat
example's is the Tikhonov-regularised least-squares solution it documents.
"""

from __future__ import annotations

import copy
import sys
from pathlib import Path

import pytest
import torch
from optim_helpers import flat, setup

from higbench.config import config_dir
from higbench.optim.sip import ScaleInvariantPhysics, newton_step_in_y
from higbench.problems.base import Problem, registry
from higbench.runner.updates import Update, build_update

HEAT = Path(__file__).resolve().parents[2] / "examples" / "heat"


def toy(gamma: float, optimizer: str = "sip", batch_size: int = 8):
    cfg, problem, model, batch = setup("toy", batch_size, f"problem.gamma={gamma}", optimizer=optimizer)
    return cfg, problem, model, batch


@pytest.mark.parametrize("gamma", [0.01, 1.0])
def test_full_newton_step_with_the_exact_inverse_targets_the_true_solution(gamma):
    cfg, problem, model, batch = toy(gamma)
    update = build_update(problem, model, cfg.optimizer)
    loss, u_target = update.optimizer.target(update.closure(batch))
    # By hand: l = 1/2 |y - t|^2, so the full Newton step lands on t, and u = (t1, t2 / gamma).
    t = batch.targets
    torch.testing.assert_close(u_target, torch.stack([t[:, 0], t[:, 1] / gamma], dim=1), rtol=1e-12, atol=1e-12)
    u = model(batch.net_inputs).detach()
    y = torch.stack([u[:, 0], gamma * u[:, 1]], dim=1)
    torch.testing.assert_close(loss, (0.5 * ((y - t) ** 2).sum(1)).mean())


def test_a_partial_newton_step_moves_y_by_that_fraction():
    cfg, problem, model, batch = toy(0.01)
    cfg.optimizer.eta_y = 0.25
    update = build_update(problem, model, cfg.optimizer)
    _, u_target = update.optimizer.target(update.closure(batch))
    u = model(batch.net_inputs).detach()
    y = torch.stack([u[:, 0], 0.01 * u[:, 1]], dim=1)
    y_star = y + 0.25 * (batch.targets - y)
    torch.testing.assert_close(u_target, torch.stack([y_star[:, 0], y_star[:, 1] / 0.01], dim=1))


def test_the_newton_step_measures_the_losses_curvature():
    y, t = torch.randn(5, 3, dtype=torch.float64), torch.randn(5, 3, dtype=torch.float64)
    for scale in (0.5, 3.0):  # l = scale |y - t|^2: H = 2 scale I, one Newton step reaches t
        dy = newton_step_in_y(lambda y, s=scale: s * ((y - t) ** 2).sum(1), y, eta_y=1.0)
        torch.testing.assert_close(y + dy, t)


def test_at_gamma_one_sip_is_adam():
    """The toy's physics is then the identity: SIP's proxy loss is the problem's loss."""
    steps = []
    for name in ("sip", "adam"):
        cfg, problem, model, batch = toy(1.0, optimizer=name, batch_size=16)
        update = build_update(problem, model, cfg.optimizer)
        losses = [update(batch).loss for _ in range(4)]
        steps.append((flat(model), losses))
    torch.testing.assert_close(steps[0][0], steps[1][0], rtol=1e-10, atol=1e-12)
    assert steps[0][1] == pytest.approx(steps[1][1], rel=1e-12)


def test_an_update_reports_the_problem_loss_and_the_proxy_loss():
    cfg, problem, model, batch = toy(0.01)
    update = build_update(problem, model, cfg.optimizer)
    before = flat(model)
    result = update(batch)
    u = model(batch.net_inputs)  # after the update
    assert result.finite and set(result.timings) == {"jacobian_s", "inversion_s", "apply_s"}
    assert set(result.metrics) == {"proxy_loss"} and result.metrics["proxy_loss"] > 0
    assert not torch.equal(before, flat(model)) and u.shape == (8, 2)
    # The proxy loss is in u: at gamma = 0.01 it weighs x2 by 1/gamma^2 against the problem's loss.
    assert result.metrics["proxy_loss"] > 10 * result.loss


def test_checkpointed_state_continues_identically():
    cfg, problem, model, batch = toy(0.01)
    update = build_update(problem, model, cfg.optimizer)
    update(batch)
    state = copy.deepcopy(update.optimizer.state_dict())  # as a checkpoint file holds it (torch.load: no shared tensors)
    cfg2, problem2, model2, _ = toy(0.01)
    model2.load_state_dict(model.state_dict())
    update2 = build_update(problem2, model2, cfg2.optimizer)
    update2.optimizer.load_state_dict(state)
    update(batch)
    update2(batch)
    torch.testing.assert_close(flat(model), flat(model2))


def test_bad_arguments_name_the_key():
    p = [torch.nn.Parameter(torch.zeros(2))]
    with pytest.raises(ValueError, match="eta_y=0"):
        ScaleInvariantPhysics(p, eta_y=0)
    with pytest.raises(ValueError, match="inner_steps=0"):
        ScaleInvariantPhysics(p, inner_steps=0)
    with pytest.raises(ValueError, match="inner.lr"):
        ScaleInvariantPhysics(p, inner={"_target_": "torch.optim.Adam", "lr": 1.0})
    with pytest.raises(ValueError, match="inner._target_=torch.nn.Linear: is not a torch.optim.Optimizer"):
        ScaleInvariantPhysics(p, inner={"_target_": "torch.nn.Linear"})


def test_which_problems_declare_an_inverse_simulator():
    declared = {name for name, cls in registry().items() if cls.has_inverse_simulator()}
    assert declared == {"toy", "poisson"}
    assert not Problem.has_inverse_simulator()


def test_poisson_inverse_is_exact():
    _, problem, _, _ = setup("poisson", 2)
    y = torch.randn(6, 64, dtype=torch.float64)
    u = problem.inverse_simulator(None, y, torch.zeros_like(y))
    torch.testing.assert_close(problem.physics(None, u), y, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(problem.inverse_simulator(None, problem.physics(None, u), u), u)


@pytest.fixture
def heat(monkeypatch):
    monkeypatch.syspath_prepend(str(HEAT))
    from hydra import compose, initialize_config_dir

    from higbench.problems.base import build_problem

    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        cfg = compose("config", overrides=[f"hydra.searchpath=[file://{HEAT / 'conf'}]", "problem=heat"])
    problem = build_problem(cfg.problem, dtype=torch.float64, device=torch.device("cpu"), seed=0)
    yield problem
    sys.modules.pop("heat_problem", None)


def test_heat_inverse_is_the_documented_tikhonov_solution(heat):
    n, lam = heat.cfg.points, heat.cfg.inverse_regularization
    a = torch.stack([heat.physics(None, e[None])[0] for e in torch.eye(n, dtype=torch.float64)], dim=1)
    y, u0 = torch.randn(4, n, dtype=torch.float64), torch.randn(4, n, dtype=torch.float64)
    u = heat.inverse_simulator(None, y, u0)
    # Reference: the stacked least-squares problem [A; sqrt(lam) I] u = [y; sqrt(lam) u0].
    stacked = torch.cat([a, lam**0.5 * torch.eye(n, dtype=torch.float64)])
    rhs = torch.cat([y.T, lam**0.5 * u0.T])
    reference = torch.linalg.lstsq(stacked, rhs).solution.T
    torch.testing.assert_close(u, reference, rtol=1e-8, atol=1e-8)
    # It undoes the diffusion of a smooth initial state (whose modes diffusion keeps) inside the
    # rod; the end values barely reach y (held at 0 after the first step) and stay near u0.
    x = torch.linspace(0, 1, n, dtype=torch.float64)
    smooth = torch.sin(torch.pi * x)[None]
    observed = heat.physics(None, smooth)
    recovered = heat.inverse_simulator(None, observed, torch.zeros_like(smooth))
    inner = slice(1, -1)
    assert torch.linalg.norm(recovered[:, inner] - smooth[:, inner]) < 0.02 * torch.linalg.norm(smooth)
    assert torch.linalg.norm(heat.physics(None, recovered) - observed) < 1e-2 * torch.linalg.norm(
        observed
    )  # lambda shrinks it by ~lambda / s_max^2


def test_sip_refuses_a_problem_without_an_inverse(higbench, tmp_path):
    code, _, err = higbench("problem=oscillator", "optimizer=sip")
    assert code == 2 and err.strip() == "higbench: error: optimizer=sip: problem oscillator has no inverse simulator", err
    assert sorted(tmp_path.rglob("*")) == []


def test_sip_needs_the_inverse_on_its_closure():
    cfg, problem, model, batch = toy(0.01)
    opt = build_update(problem, model, cfg.optimizer).optimizer
    bare = Update(problem, model, torch.optim.SGD(model.parameters())).closure(batch)
    bare.inverse = None
    with pytest.raises(TypeError, match="inverse simulator"):
        opt.step(bare)
