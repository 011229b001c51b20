"""Scale-invariant physics (SIP) updates: a Newton step in y, the inverse simulator, a network fit.

The physical-gradient update of the scale-invariance chapter of the Physics-based Deep
Learning book (Holl, Koltun, Thuerey, "Scale-invariant learning by physics inversion",
NeurIPS 2022), for network training. One update on a batch (z, x, y*):

1. u0 = f(z; theta), y0 = P(x, u0); a Newton step in y on the per-sample loss l(y):
   dy = -eta_y * g / c with g = dl/dy and c = g.H g / g.g, the curvature of l along g (one
   Hessian-vector product). For any L2 loss (H a multiple of I) this is the exact Newton
   step; for l = 1/2 |y - y*|^2 and eta_y = 1, y0 + dy = y*.
2. u* = P^-1(x, y0 + dy; u0): the problem's inverse simulator (``Problem.inverse_simulator``).
3. ``inner_steps`` steps of a first-order optimizer (``inner``, Adam by default) on the proxy
   loss mean_i 1/2 |f(z_i; theta) - u*_i|^2: the network is fitted to the inverted target.
4. ``step`` returns the problem's loss before the update (batch mean of l); its report
   (``last_report.metrics``) holds the proxy loss before the inner steps, which the runner
   records per update.

The runner hands the inverse simulator over through ``LossClosure.inverse``; a problem
without one is refused before any work (``needs_inverse_simulator``).
"""

from __future__ import annotations

import math
import time

import torch

from higbench.optim.closure import LossClosure, NonFiniteStep
from higbench.optim.contract import StepReport, StepReporter
from higbench.optim.split import build_optimizer

DEFAULT_INNER = {"_target_": "torch.optim.Adam"}


def newton_step_in_y(loss, y: torch.Tensor, eta_y: float) -> torch.Tensor:
    """dy = -eta_y g / c per sample, g = dl/dy, c = g.H g / g.g (exact Newton for an L2 loss).

    ``loss(y)`` -> per-sample losses (b,). A sample with a zero gradient gets dy = 0; one whose
    curvature along g is not positive (a non-convex loss there) gets the gradient step -eta_y g.
    """
    with torch.enable_grad():
        y = y.detach().requires_grad_(True)
        (g,) = torch.autograd.grad(loss(y).sum(), y, create_graph=True)
        (hg,) = torch.autograd.grad(g, y, grad_outputs=g.detach(), allow_unused=True)
    g = g.detach()
    dims = tuple(range(1, g.ndim))
    gg = (g * g).sum(dims, keepdim=True)
    ghg = (g * hg).sum(dims, keepdim=True) if hg is not None else torch.zeros_like(gg)
    curvature = torch.where((gg > 0) & (ghg > 0), ghg / gg.clamp_min(torch.finfo(g.dtype).tiny), torch.ones_like(gg))
    return -eta_y * g / curvature


class ScaleInvariantPhysics(torch.optim.Optimizer, StepReporter):
    """SIP training: invert a Newton step in y through ``P^-1``, fit the network to it.

    Args:
        params: the network's parameters (the inner optimizer updates them).
        lr: the inner optimizer's learning rate.
        eta_y: step in y as a fraction of the Newton step (1: the full step; for an L2 loss,
            straight to the target).
        inner: the first-order optimizer of the proxy loss, ``{_target_: CLASS, ARG: VALUE}``
            without lr (default Adam); its state lives across updates.
        inner_steps: its steps per update, on the same inverted target.
    """

    needs_inverse_simulator = True  # the step contract: the config check refuses a problem without one

    def __init__(self, params, lr: float = 1e-3, eta_y: float = 1.0, inner: dict | None = None, inner_steps: int = 1):
        params = list(params)
        if not (isinstance(eta_y, (int, float)) and 0 < eta_y < math.inf):
            raise ValueError(f"eta_y={eta_y}: must be a number > 0")
        if isinstance(inner_steps, bool) or int(inner_steps) != inner_steps or inner_steps < 1:
            raise ValueError(f"inner_steps={inner_steps}: must be an integer >= 1")
        self.eta_y, self.inner_steps = float(eta_y), int(inner_steps)
        spec = dict(DEFAULT_INNER if inner is None else inner)
        if "lr" in spec:
            raise ValueError("inner.lr: set the learning rate as lr (optimizer.lr), not inside inner")
        self.inner = build_optimizer("inner", {**spec, "lr": lr}, params)
        super().__init__(params, {})
        self.param_groups = self.inner.param_groups  # the inner optimizer's groups (its lr)
        self.last_report: StepReport | None = None
        self._newton_done = 0.0  # when target() finished the Newton step (the phase times)

    @torch.no_grad()
    def target(self, closure: LossClosure) -> tuple[torch.Tensor, torch.Tensor]:
        """Steps 1-2 on the closure's batch: (batch-mean problem loss, inverted target u*)."""
        if not isinstance(closure, LossClosure) or closure.inverse is None:
            raise TypeError("SIP needs a LossClosure with the problem's inverse simulator (LossClosure.inverse)")
        if closure.outputs_fn is not None:
            raise TypeError("SIP needs y = physics(inputs, model(net_inputs)); this problem computes y its own way")
        u0 = closure.model(closure.net_inputs)
        y0 = closure.physics(u0) if closure.inputs is None else closure.physics(closure.inputs, u0)
        loss = closure.loss(y0).mean()
        if closure.guard and not torch.isfinite(loss):
            raise NonFiniteStep("non-finite loss")
        y_target = y0 + newton_step_in_y(closure.loss, y0, self.eta_y)
        self._newton_done = time.perf_counter()
        u_target = closure.inverse(y_target, u0).detach()
        if not torch.isfinite(u_target).all():
            raise NonFiniteStep("non-finite inverse-simulator target")
        return loss.detach(), u_target

    @torch.no_grad()
    def step(self, closure: LossClosure):  # type: ignore[override]
        """One SIP update on the closure's batch; the batch-mean problem loss before it."""
        t0 = time.perf_counter()
        loss, u_target = self.target(closure)
        t1, t2 = self._newton_done, time.perf_counter()
        model, z = closure.model, closure.net_inputs
        proxy_before = math.nan
        for k in range(self.inner_steps):
            with torch.enable_grad():
                self.inner.zero_grad()
                proxy = 0.5 * ((model(z) - u_target) ** 2).reshape(len(z), -1).sum(1).mean()
                proxy.backward()
            if k == 0:
                proxy_before = float(proxy)
            self.inner.step()
        timings = {"jacobian_s": t1 - t0, "inversion_s": t2 - t1, "apply_s": time.perf_counter() - t2}
        self.last_report = StepReport(timings=timings, metrics={"proxy_loss": proxy_before})
        return loss

    def state_dict(self) -> dict:
        return {"inner": self.inner.state_dict()}

    def load_state_dict(self, state_dict: dict) -> None:
        self.inner.load_state_dict(state_dict["inner"])
