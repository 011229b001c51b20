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
from higbench.optim.inversion import gram_coefficients
from higbench.optim.jacobians import per_sample_jacobian
from higbench.optim.structured import StructuredJacobian, network_jacobian, solver_jacobian
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
    """GN / HIG: structured (or naive) Jacobian, inversion, plain SGD application.

    Structured (``optimizer.jacobian: structured``, the default): u = f(z; theta), then the
    solver Jacobians A_i = dy_i/du_i by |y| batched reverse passes through the physics, then
    the network part (per-layer factors for MLPs, torch.func for other networks), and on
    the Gram route K = J J^T and one J^T c product without forming J
    (``higbench.optim.structured``). Naive (``optimizer.jacobian: naive``): torch.func
    Jacobian of network + physics per sample, materialised J (``per_sample_jacobian``).

    Phases: ``jacobian_s`` all derivatives (A, network factors or J, and K), ``inversion_s``
    eigh/SVD and the product mapping the coefficients back to parameters, ``apply_s`` the
    parameter update.
    """

    def __init__(self, problem: Problem, model: nn.Module, optimizer: JacobianPower):
        self.problem, self.model, self.optimizer = problem, model, optimizer

    @property
    def structured(self) -> bool:
        if self.optimizer.group.get("jacobian", "structured") != "structured":
            return False
        # The structured path assumes outputs = physics(inputs, model(net_inputs)).
        return type(self.problem).outputs is Problem.outputs

    def derivatives(self, batch: Batch):
        """(loss, g, J): the batch-mean loss, g = d objective / d y (rows,), J (structured or a tensor)."""
        opt = self.optimizer
        if self.structured:
            with torch.no_grad():
                u = self.model(batch.net_inputs)
            y, A = solver_jacobian(self.problem.physics, batch.inputs, u)
            y = y.requires_grad_(True)
            per_sample = self.problem.loss(y, batch.targets)
            loss = per_sample.mean()  # logged; g is the gradient of the objective (problem.loss_reduction)
            (grad_y,) = torch.autograd.grad(self.problem.objective(per_sample), y)
            if not torch.isfinite(loss) or not torch.isfinite(A).all():
                return loss, grad_y, None
            J = network_jacobian(self.model, opt.params, batch.net_inputs, A, opt.group["precision"])
            return loss, grad_y, J
        y = self.problem.outputs(self.model, batch)
        per_sample = self.problem.loss(y, batch.targets)
        loss = per_sample.mean()
        (grad_y,) = torch.autograd.grad(self.problem.objective(per_sample), y)
        if not torch.isfinite(loss):
            return loss, grad_y, None
        J = per_sample_jacobian(self.model, self.problem.physics, batch.inputs, batch.net_inputs)
        return loss, grad_y, J

    def __call__(self, batch: Batch) -> UpdateResult:
        dev = self.problem.device
        t0 = time.perf_counter()
        loss, grad_y, J = self.derivatives(batch)
        value = loss.item()
        if not torch.isfinite(loss):
            return UpdateResult(value, finite=False, reason="non-finite loss")
        if J is None:
            return UpdateResult(value, finite=False, reason="non-finite Jacobian")
        # Gram route: K (part of the derivatives), then eigen-solve + one J^T c in the inversion.
        # Otherwise J itself (formed here if structured), then SVD (or Gram of J) in the inversion.
        K = None
        if isinstance(J, StructuredJacobian):
            if self.optimizer.resolved_solver(J.rows, J.n_params) == "gram":
                K = J.gram()
            else:
                J = J.matrix()
        finite = bool(torch.isfinite(K if K is not None else J).all())
        _sync(dev)
        t1 = time.perf_counter()
        if not finite:
            return UpdateResult(value, finite=False, reason="non-finite Jacobian")
        try:
            if K is not None:
                coeff = gram_coefficients(K, grad_y.reshape(-1).to(K.dtype), **self.optimizer._opts(), overwrite=True)
                direction = J.transpose_apply(coeff)
            else:
                direction = self.optimizer.direction(J, grad_y)
        except torch.linalg.LinAlgError as exc:  # e.g. SVD or eigh failed to converge
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
