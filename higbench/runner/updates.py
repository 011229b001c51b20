"""One training update per mini-batch, with its phases timed.

Phases, as in the paper's tables: ``jacobian_s`` (derivatives: the backward pass for
first-order optimizers, the stacked Jacobian for GN/HIG), ``inversion_s`` (SVD / Gram
eigen-decomposition; zero for first-order optimizers) and ``apply_s`` (the parameter
update, including torch.optim's own moment bookkeeping).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import torch
from hydra.utils import get_class
from omegaconf import DictConfig
from torch import nn

from higbench.config import optimizer_kwargs  # the one rule for which optimizer keys are arguments
from higbench.optim.hig import JacobianPower
from higbench.problems.base import Batch, Problem


@dataclass
class UpdateResult:
    loss: float
    timings: dict[str, float] = field(default_factory=dict)
    finite: bool = True
    reason: str = ""


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


class FirstOrderUpdate:
    """Any torch.optim optimizer on the problem's objective (batch mean or sum, ``problem.loss_reduction``)."""

    def __init__(self, problem: Problem, model: nn.Module, optimizer: torch.optim.Optimizer):
        self.problem, self.model, self.optimizer = problem, model, optimizer

    def __call__(self, batch: Batch) -> UpdateResult:
        dev = self.problem.device
        t0 = time.perf_counter()
        self.optimizer.zero_grad(set_to_none=True)
        per_sample = self.problem.loss(self.problem.outputs(self.model, batch), batch.targets)
        loss = per_sample.mean()  # logged; the gradient is that of the problem's objective (mean or sum)
        self.problem.objective(per_sample).backward()
        _sync(dev)
        t1 = time.perf_counter()
        value = loss.item()
        if not torch.isfinite(loss):
            return UpdateResult(value, finite=False, reason="non-finite loss")
        grads_finite = all(torch.isfinite(p.grad).all() for p in self.model.parameters() if p.grad is not None)
        if not grads_finite:
            return UpdateResult(value, finite=False, reason="non-finite gradient")
        self.optimizer.step()
        _sync(dev)
        t2 = time.perf_counter()
        return UpdateResult(value, {"jacobian_s": t1 - t0, "inversion_s": 0.0, "apply_s": t2 - t1})


class JacobianPowerUpdate:
    """GN / HIG: one call of the optimizer's public ``step_structured`` per batch.

    The update itself (derivatives, Gram-or-SVD route, inversion, finiteness checks, phase
    timings) lives in ``higbench.optim.hig.JacobianPower``, the class researchers use, so
    the runner's timings and results are those of the public optimizer. Here only the
    problem is unpacked: y = physics(inputs, model(net_inputs)) (``Problem.outputs``) and
    the per-sample ``problem.loss``.

    Phases (``JacobianPower.last_timings``): ``jacobian_s`` all derivatives (solver
    Jacobians, network factors or J, and K or J itself), ``inversion_s`` eigh/SVD and the
    product mapping the coefficients back to parameters, ``apply_s`` the parameter update.
    """

    def __init__(self, problem: Problem, model: nn.Module, optimizer: JacobianPower):
        self.problem, self.model, self.optimizer = problem, model, optimizer
        # A problem with its own ``outputs`` goes through the optimizer's generic step(closure).
        self.composed = type(problem).outputs is Problem.outputs

    @property
    def structured(self) -> bool:
        """Whether J is computed structured (solver and network apart), as the memory guard sizes it."""
        return self.composed and self.optimizer.group.get("jacobian", "structured") == "structured"

    def __call__(self, batch: Batch) -> UpdateResult:
        opt, problem = self.optimizer, self.problem
        if self.composed:
            value = opt.step_structured(
                self.model,
                batch.net_inputs,
                physics=problem.physics,
                loss=lambda y: problem.loss(y, batch.targets),
                inputs=batch.inputs,
                reduction=problem.cfg.get("loss_reduction", "mean"),  # poisson: sum, as the reference
            )
        else:

            def closure():
                y = problem.outputs(self.model, batch)
                # g is the gradient of the objective (problem.loss_reduction); for a summing
                # problem the logged batch loss is then that sum, not the mean.
                return y, problem.objective(problem.loss(y, batch.targets))

            value = opt.step(closure)
        return UpdateResult(value.item(), dict(opt.last_timings), opt.last_finite, opt.last_reason)


def build_update(problem: Problem, model: nn.Module, opt_cfg: DictConfig):
    """The optimizer class comes from ``optimizer._target_``; its arguments from the rest."""
    cls = get_class(opt_cfg._target_)
    optimizer = cls(model.parameters(), **optimizer_kwargs(opt_cfg))
    if isinstance(optimizer, JacobianPower):
        return JacobianPowerUpdate(problem, model, optimizer)
    return FirstOrderUpdate(problem, model, optimizer)
