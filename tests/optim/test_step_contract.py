"""The step contract: every optimizer takes an update through ``step(closure)``.

A ``LossClosure`` is a torch.optim closure (L-BFGS and Adam call it) that also carries the
loss's pieces (HIG/GN read them: the fast path). ``HIG.step`` also takes the closures a user
writes: ``(y, loss)`` with a per-sample or mean loss, ``(u, y, loss)``; a scalar alone gets
one error that says what to return.
"""

import pytest
import torch
from omegaconf import OmegaConf
from optim_helpers import flat, setup
from test_public_optimizer import damped, expected_delta, per_sample, problem
from torch import nn

from higbench.optim import HIG, LossClosure, reduce_loss
from higbench.optim.jacobians import full_jacobian
from higbench.runner.updates import build_update


def test_per_sample_loss_in_a_user_closure_is_the_mean():
    """Old code: 'grad can be implicitly created only for scalar outputs'."""
    model, z, target = problem()
    expected = expected_delta(model, z, target, 1.0, -0.5, 1e-5)
    opt = HIG(model.parameters(), lr=1.0, tau=1e-5)
    before = flat(model)

    def closure():
        y = damped(z, model(z))
        return y, per_sample(y, target)  # per-sample losses (b,), as in the step_structured example

    loss = opt.step(closure)
    assert loss.ndim == 0 and opt.last_finite
    assert torch.linalg.norm(flat(model) - before - expected) <= 1e-7 * torch.linalg.norm(expected)


def test_scalar_closure_names_what_to_return():
    """Old code: 'len() of a 0-d tensor'."""
    model, z, target = problem()
    opt = HIG(model.parameters())
    with pytest.raises(TypeError, match=r"must return \(y, loss\) or \(u, y, loss\).*got a \(\) tensor"):
        opt.step(lambda: per_sample(damped(z, model(z)), target).mean())
    with pytest.raises(TypeError, match="no closure"):
        opt.step(None)


def test_loss_closure_takes_the_fast_path_and_equals_the_reference():
    model, z, target = problem()
    expected = expected_delta(model, z, target, 1.0, -0.5, 1e-5)
    opt = HIG(model.parameters(), lr=1.0, tau=1e-5)
    before = flat(model)
    closure = LossClosure(model, z, damped, lambda y: per_sample(y, target), inputs=z)
    loss = opt.step(closure)
    assert closure.calls == 0, "HIG reads the pieces; it never needs the scalar backward pass"
    assert torch.linalg.norm(flat(model) - before - expected) <= 1e-7 * torch.linalg.norm(expected)
    torch.testing.assert_close(loss, per_sample(damped(z, problem()[0](z)), target).mean())


def test_loss_closure_is_a_torch_closure():
    model, z, target = problem()
    closure = LossClosure(model, z, damped, lambda y: per_sample(y, target), inputs=z, reduction="sum")
    value = closure()
    assert closure.calls == 1 and closure.first_mean is not None
    torch.testing.assert_close(value, closure.first_mean * z.shape[0])  # returns the objective (sum) ...
    grads = [p.grad.clone() for p in model.parameters()]
    closure()  # ... and clears the gradients before each call, as torch.optim expects
    for g, p in zip(grads, model.parameters()):
        torch.testing.assert_close(g, p.grad)


def test_reduce_loss_is_the_one_rule():
    per = torch.tensor([1.0, 2.0, 3.0])
    assert float(reduce_loss(per)) == 2.0 and float(reduce_loss(per, "sum")) == 6.0
    assert float(reduce_loss(torch.tensor(4.0), "sum")) == 4.0
    with pytest.raises(ValueError, match="loss_reduction='max'"):
        reduce_loss(per, "max")


def test_lbfgs_runs_through_the_runner_update():
    """Old code: FirstOrderUpdate called optimizer.step() without a closure; L-BFGS needs one."""
    cfg, p, model, batch = setup("toy", 64, optimizer="adam")
    opt_cfg = OmegaConf.create({"name": "lbfgs", "_target_": "torch.optim.LBFGS", "line_search_fn": "strong_wolfe"})
    update = build_update(p, model, opt_cfg)
    first = update(batch)
    losses = [update(batch).loss for _ in range(5)]
    assert first.finite and losses[-1] < 0.5 * first.loss
    assert set(first.timings) == {"jacobian_s", "inversion_s", "apply_s"} and first.timings["jacobian_s"] > 0


def test_spectrum_of_the_step_is_that_of_j():
    model, z, target = problem()
    J = full_jacobian(model, damped, z, z)
    s = torch.linalg.svdvals(J)
    tau = 0.05
    opt = HIG(model.parameters(), tau=tau, solver="gram")
    opt.step_structured(model, z, damped, lambda y: per_sample(y, target), inputs=z)
    spec = opt.last_spectrum
    torch.testing.assert_close(spec["sv_max"], float(s.max()), rtol=1e-8, atol=0)
    kept = s[s >= tau * s.max()]
    torch.testing.assert_close(spec["sv_min_kept"], float(kept.min()), rtol=1e-6, atol=0)
    assert spec["sv_dropped"] == J.shape[0] - kept.numel()


def test_a_torch_optimizer_step_is_refused_before_a_nan_gradient_moves_anything():
    cfg, p, model, batch = setup("toy", 16, optimizer="adam")
    update = build_update(p, model, cfg.optimizer)
    next(model.parameters()).register_hook(lambda g: g * float("nan"))
    before = flat(model)
    result = update(batch)
    assert not result.finite and result.reason == "non-finite gradient"
    assert torch.equal(flat(model), before)


def test_nn_module_closure_generic_path_equals_structured():
    model, z, target = problem(nn.GELU)
    twin = problem(nn.GELU)[0]
    a, b = HIG(model.parameters(), tau=1e-5), HIG(twin.parameters(), tau=1e-5)

    def closure():
        u = model(z)
        y = damped(z, u)
        return u, y, per_sample(y, target).mean()

    a.step(closure)
    b.step(LossClosure(twin, z, damped, lambda y: per_sample(y, target), inputs=z))
    torch.testing.assert_close(flat(model), flat(twin), rtol=1e-7, atol=1e-9)
