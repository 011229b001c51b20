"""problem.loss_reduction: the objective is the batch mean (default) or the batch sum (Poisson).

The sum only scales g by b, so every update that is linear in g (GN/HIG's direction, SGD)
moves b times as far; the logged loss stays the per-sample mean.
"""

import pytest
import torch
from optim_helpers import flat, setup

from higbench.config import ConfigError, validate
from higbench.optim.hig import HIG
from higbench.problems.networks import count_parameters
from higbench.runner.updates import build_update

B = 4
SMALL = "problem.hidden=[16]"  # a small Poisson network keeps the SVD cheap


def _delta(reduction: str, optimizer: str, *overrides: str):
    cfg, p, model, batch = setup("poisson", B, SMALL, f"problem.loss_reduction={reduction}", *overrides, optimizer=optimizer)
    before = flat(model)
    result = build_update(p, model, cfg.optimizer)(batch)
    assert result.finite, result.reason
    with torch.no_grad():
        per_sample_mean = float(p.loss(p.outputs(p.build_model(), batch), batch.targets).mean())
    return flat(model) - before, result.loss, per_sample_mean


def test_poisson_defaults_to_the_reference_sum_and_others_to_the_mean():
    cfg, p, *_ = setup("poisson", B)
    assert cfg.problem.loss_reduction == "sum"
    per = torch.tensor([1.0, 2.0, 3.0])
    assert float(p.objective(per)) == 6.0
    _, q, *_ = setup("toy", B)
    assert q.cfg.loss_reduction == "mean" and float(q.objective(per)) == 2.0


@pytest.mark.parametrize("optimizer,extra", [("hig", ["optimizer.tau=1e-5"]), ("gn", ["optimizer.tau=1e-5"]), ("sgd", [])])
def test_sum_moves_b_times_as_far_as_mean(optimizer, extra):
    d_sum, loss_sum, mean0 = _delta("sum", optimizer, *extra)
    d_mean, loss_mean, _ = _delta("mean", optimizer, *extra)
    assert float(torch.linalg.norm(d_sum - B * d_mean) / torch.linalg.norm(B * d_mean)) < 1e-9
    # the logged loss is the per-sample mean under both reductions
    assert loss_sum == pytest.approx(loss_mean, rel=1e-12) and loss_sum == pytest.approx(mean0, rel=1e-9)


def test_step_structured_reduction_sum():
    cfg, p, model, batch = setup("poisson", B, SMALL)
    moved = {}
    for reduction in ("mean", "sum"):
        m = p.build_model()
        opt = HIG(m.parameters(), lr=1.0, tau=1e-5)
        before = flat(m)
        opt.step_structured(m, batch.net_inputs, p.physics, lambda y: p.loss(y, batch.targets), batch.inputs, reduction=reduction)
        moved[reduction] = flat(m) - before
    assert float(torch.linalg.norm(moved["sum"] - B * moved["mean"]) / torch.linalg.norm(moved["sum"])) < 1e-9
    with pytest.raises(ValueError, match="reduction"):
        HIG(model.parameters()).step_structured(model, batch.net_inputs, p.physics, lambda y: p.loss(y, batch.targets),
                                                batch.inputs, reduction="max")  # fmt: skip


def test_reference_poisson_network_has_24896_parameters():
    _, p, *_ = setup("poisson", B, "problem.hidden=[64,128,64]")
    assert count_parameters(p.build_model()) == 24896


def test_bad_loss_reduction_refused():
    cfg, *_ = setup("poisson", B)
    cfg.problem.loss_reduction = "max"
    with pytest.raises(ConfigError, match="problem.loss_reduction=max"):
        validate(cfg)
