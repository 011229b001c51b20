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
from omegaconf import DictConfig, OmegaConf
from torch import nn

from higbench.optim.hig import JacobianPower
from higbench.optim.jacobians import per_sample_jacobian
from higbench.problems.base import Batch, Problem

# Config keys that describe the optimizer but are not constructor arguments.
_META_KEYS = ("name", "_target_", "kind")


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
    """Any torch.optim optimizer on the batch-mean loss."""

    def __init__(self, problem: Problem, model: nn.Module, optimizer: torch.optim.Optimizer):
        self.problem, self.model, self.optimizer = problem, model, optimizer

    def __call__(self, batch: Batch) -> UpdateResult:
        dev = self.problem.device
        t0 = time.perf_counter()
        self.optimizer.zero_grad(set_to_none=True)
        loss = self.problem.loss(self.problem.outputs(self.model, batch), batch.targets).mean()
        loss.backward()
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
    """GN / HIG: stacked per-sample Jacobian, inversion, plain SGD application."""

    def __init__(self, problem: Problem, model: nn.Module, optimizer: JacobianPower):
        self.problem, self.model, self.optimizer = problem, model, optimizer

    def __call__(self, batch: Batch) -> UpdateResult:
        dev = self.problem.device
        t0 = time.perf_counter()
        y = self.problem.outputs(self.model, batch)
        loss = self.problem.loss(y, batch.targets).mean()  # g is the gradient of the batch mean
        (grad_y,) = torch.autograd.grad(loss, y)
        value = loss.item()
        if not torch.isfinite(loss):
            return UpdateResult(value, finite=False, reason="non-finite loss")
        J = per_sample_jacobian(self.model, self.problem.physics, batch.inputs, batch.net_inputs)
        _sync(dev)
        t1 = time.perf_counter()
        if not torch.isfinite(J).all():
            return UpdateResult(value, finite=False, reason="non-finite Jacobian")
        try:
            direction = self.optimizer.direction(J, grad_y)
        except torch.linalg.LinAlgError as exc:  # e.g. SVD failed to converge
            return UpdateResult(value, finite=False, reason=f"inversion failed: {exc}")
        _sync(dev)
        t2 = time.perf_counter()
        if not torch.isfinite(direction).all():
            return UpdateResult(value, finite=False, reason="non-finite update direction")
        self.optimizer.apply(direction)
        _sync(dev)
        t3 = time.perf_counter()
        return UpdateResult(value, {"jacobian_s": t1 - t0, "inversion_s": t2 - t1, "apply_s": t3 - t2})


def optimizer_kwargs(opt_cfg: DictConfig) -> dict:
    kwargs = OmegaConf.to_container(opt_cfg, resolve=True)
    for key in _META_KEYS:
        kwargs.pop(key, None)
    for key, value in list(kwargs.items()):
        if isinstance(value, list):
            kwargs[key] = tuple(value)  # e.g. Adam's betas
    return kwargs


def build_update(problem: Problem, model: nn.Module, opt_cfg: DictConfig):
    """The optimizer class comes from ``optimizer._target_``; its arguments from the rest."""
    cls = get_class(opt_cfg._target_)
    optimizer = cls(model.parameters(), **optimizer_kwargs(opt_cfg))
    if isinstance(optimizer, JacobianPower):
        return JacobianPowerUpdate(problem, model, optimizer)
    return FirstOrderUpdate(problem, model, optimizer)
