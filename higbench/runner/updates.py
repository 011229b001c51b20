"""One training update per mini-batch: ``optimizer.step(closure)``, with its phases timed.

Every optimizer goes through the same call. The closure is a ``LossClosure``
(``higbench.optim.closure``): torch.optim optimizers (Adam, L-BFGS, ...) call it like any
closure; the Jacobian-power optimizers (HIG, GN, LM) read its pieces and take their fast
path (per-sample outputs, batched solver Jacobians, the Gram route).

Phases, as in the paper's tables: ``jacobian_s`` (derivatives: the closure's backward
passes for first-order optimizers, the stacked Jacobian for GN/HIG/LM), ``inversion_s``
(SVD / Gram eigen-decomposition; zero for first-order optimizers) and ``apply_s`` (the rest
of the step: torch.optim's bookkeeping, L-BFGS's two-loop recursion, LM's trial steps).
What the runner reads back after the step is the step contract (``higbench.optim.contract``):
an optimizer of ours reports its phases, refusals, spectrum and own values in one
``StepReport``; any other optimizer reports nothing and is timed by the closure.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import torch
from hydra.utils import get_class
from omegaconf import DictConfig
from torch import nn

from higbench.optim.choice import OptimizerChoice, optimizer_kwargs  # the one rule for which optimizer keys are arguments
from higbench.optim.closure import LossClosure, NonFiniteStep
from higbench.optim.contract import PHASES, StepReporter, leave_threads_to_run, report_of
from higbench.problems.base import Batch, Problem


@dataclass
class UpdateResult:
    loss: float
    timings: dict[str, float] = field(default_factory=dict)
    finite: bool = True
    reason: str = ""
    spectrum: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)  # an optimizer's own per-update values (SIP: proxy_loss)


def synchronize(device: torch.device) -> None:
    """Wait for the device's queued work, so a clock read after it counts that work (GPU only)."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)


class Update:
    """``optimizer.step(closure)`` on one batch of the problem's objective (``problem.loss_reduction``).

    The logged loss is the batch mean of the per-sample losses before the update, whatever
    the reduction. A non-finite loss or gradient stops the step before any parameter moves
    (the closure is guarded); the Jacobian-power optimizers report their own refusals.
    """

    def __init__(self, problem: Problem, model: nn.Module, optimizer: torch.optim.Optimizer):
        self.problem, self.model, self.optimizer = problem, model, optimizer
        # A problem with its own ``outputs`` is differentiated through it generically.
        self.composed = type(problem).outputs is Problem.outputs

    @property
    def structured(self) -> bool:
        """Whether GN/HIG/LM compute J structured (solver and network apart), as the memory guard sizes it."""
        return self.composed and self.optimizer.param_groups[0].get("jacobian", "structured") == "structured"

    def closure(self, batch: Batch) -> LossClosure:
        problem, model = self.problem, self.model
        return LossClosure(
            model,
            batch.net_inputs,
            problem.physics,
            lambda y: problem.loss(y, batch.targets),
            batch.inputs,
            reduction=problem.cfg.get("loss_reduction", "mean"),  # poisson: sum, as the reference
            guard=True,
            outputs_fn=None if self.composed else (lambda: problem.outputs(model, batch)),
            inverse=(lambda y, u0: problem.inverse_simulator(batch.inputs, y, u0)) if problem.has_inverse_simulator() else None,
            physics_jacobian=problem.physics_jacobian,
        )

    def __call__(self, batch: Batch) -> UpdateResult:
        opt, closure = self.optimizer, self.closure(batch)
        before = report_of(opt)
        t0 = time.perf_counter()
        try:
            value = opt.step(closure)
        except NonFiniteStep as exc:
            loss = closure.first_mean
            return UpdateResult(math.nan if loss is None else loss.item(), finite=False, reason=str(exc))
        synchronize(self.problem.device)
        total = time.perf_counter() - t0
        loss = closure.first_mean if closure.first_mean is not None else value
        if not isinstance(opt, StepReporter):  # torch.optim or a package's optimizer: the closure timed the derivatives
            timings = {"jacobian_s": closure.derivative_s, "inversion_s": 0.0, "apply_s": total - closure.derivative_s}
            return UpdateResult(loss.item(), timings)
        report = report_of(opt)
        if report is None or report is before:
            raise TypeError(f"{type(opt).__name__}.step set no new StepReport (higbench.optim.contract)")
        if report.finite and set(report.timings) != set(PHASES):
            raise TypeError(f"{type(opt).__name__}.step reported timings {sorted(report.timings)}; expected {list(PHASES)}")
        return UpdateResult(
            loss.item(), dict(report.timings), report.finite, report.reason, dict(report.spectrum), dict(report.metrics)
        )


def build_update(problem: Problem, model: nn.Module, opt: OptimizerChoice | DictConfig) -> Update:
    """The optimizer of a plan (its class and arguments, resolved once), or of an ``optimizer``
    config node (the class from ``_target_``, its arguments from the rest)."""
    if isinstance(opt, OptimizerChoice):
        optimizer = opt.cls(model.parameters(), **opt.kwargs)
    else:
        optimizer = get_class(opt._target_)(model.parameters(), **optimizer_kwargs(opt))
    leave_threads_to_run(optimizer)  # the run's `threads` key sets them (train._setup), not the optimizer
    return Update(problem, model, optimizer)
