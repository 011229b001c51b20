"""The step contract: every optimizer takes one update through ``optimizer.step(closure)``.

``LossClosure`` holds the pieces of a loss y = physics(inputs, model(net_inputs)),
per-sample ``loss(y)``, reduced by ``reduce_loss``. It is what torch.optim expects of a
closure (calling it clears the gradients, evaluates the objective, back-propagates and
returns the loss), so Adam or L-BFGS just call it, as often as they like. The
Jacobian-power optimizers (HIG, Gauss-Newton, Levenberg-Marquardt) see the pieces and take
their fast path instead: per-sample outputs, batched solver Jacobians, the Gram route.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import torch
from torch import nn

from higbench.losses import reduce_loss  # the one reduction rule, shared with the problems


class NonFiniteStep(ArithmeticError):
    """Raised by a guarded closure before a non-finite loss or gradient reaches the optimizer."""


@dataclass
class LossClosure:
    """A closure for ``optimizer.step(closure)`` that also carries the structure of its loss.

    model, net_inputs: the network and its inputs; physics: ``physics(inputs, u)`` (or
    ``physics(u)`` when ``inputs`` is None), batched, samples independent; loss:
    ``loss(y)`` -> per-sample losses (b,); reduction: ``mean`` or ``sum`` (``reduce_loss``).
    guard: raise ``NonFiniteStep`` on a non-finite loss or gradient, before any parameter
    moves (the runner sets it, so a diverging step is recorded and never applied).
    outputs_fn: y computed some other way (a problem with its own ``outputs``); the
    Jacobian-power optimizers then differentiate through it generically.
    physics_jacobian: the problem's own solver Jacobian, ``physics_jacobian(inputs, u)`` ->
    (y, A) or None (``Problem.physics_jacobian``: a hand-derived adjoint); None, or a None
    answer, means autograd through ``physics``. The Jacobian-power optimizers use it.
    inverse: the problem's inverse simulator with this batch's inputs bound,
    ``inverse(y_target, u0) -> u`` (``Problem.inverse_simulator``); None where the problem has
    none. The SIP optimizer (``higbench.optim.sip``) needs it; the others ignore it.

    Calling it returns the objective with its gradients set, as torch.optim expects (a line
    search compares these values). ``first_mean`` keeps the batch-mean loss of the first
    call (the loss before the update, what the runner logs); ``derivative_s`` sums the time
    spent in calls, ``calls`` counts them.
    """

    model: nn.Module
    net_inputs: torch.Tensor
    physics: Callable[..., torch.Tensor]
    loss: Callable[[torch.Tensor], torch.Tensor]
    inputs: torch.Tensor | None = None
    reduction: str = "mean"
    guard: bool = False
    outputs_fn: Callable[[], torch.Tensor] | None = None
    inverse: Callable[[torch.Tensor, torch.Tensor], torch.Tensor] | None = None
    physics_jacobian: Callable[..., tuple[torch.Tensor, torch.Tensor] | None] | None = None
    derivative_s: float = field(default=0.0, init=False)
    calls: int = field(default=0, init=False)
    first_mean: torch.Tensor | None = field(default=None, init=False)

    def outputs(self) -> torch.Tensor:
        if self.outputs_fn is not None:
            return self.outputs_fn()
        u = self.model(self.net_inputs)
        return self.physics(u) if self.inputs is None else self.physics(self.inputs, u)

    def per_sample(self) -> torch.Tensor:
        return self.loss(self.outputs())

    @torch.no_grad()
    def objective(self) -> torch.Tensor:
        """The objective at the current parameters, no gradients (e.g. to accept or reject a step)."""
        return reduce_loss(self.per_sample(), self.reduction)

    def __call__(self) -> torch.Tensor:
        t0 = time.perf_counter()
        with torch.enable_grad():
            for p in self.model.parameters():
                p.grad = None
            per_sample = self.per_sample()
            mean = per_sample.mean().detach()
            if self.first_mean is None:
                self.first_mean = mean
            if self.guard and not torch.isfinite(mean):
                raise NonFiniteStep("non-finite loss")
            objective = reduce_loss(per_sample, self.reduction)
            objective.backward()
        if self.guard and not all(torch.isfinite(p.grad).all() for p in self.model.parameters() if p.grad is not None):
            raise NonFiniteStep("non-finite gradient")
        self.derivative_s += time.perf_counter() - t0
        self.calls += 1
        return objective.detach()
