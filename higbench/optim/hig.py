"""HIG and Gauss-Newton as a torch.optim-style optimizer.

One class, ``JacobianPower``, implements the update of paper eq. 21-22:

    theta <- theta - lr * max(s)^beta * V diag(s^kappa) U^T g

for the stacked per-sample Jacobian J = U diag(s) V^T of the outputs y (b, |y|) and the
gradient g of the batch-mean loss w.r.t. y. ``HIG`` (kappa = -1/2) and ``GaussNewton``
(kappa = -1) only change the defaults.

Usable without the runner, three ways (fastest first):

* ``step_structured(model, net_inputs, physics, loss, inputs=None)``: the network, the
  differentiable solver and the per-sample loss as separate callables. Derivatives are
  structured (solver Jacobians by batched reverse passes, network part from per-layer
  factors for MLPs, torch.func otherwise) and J is never formed on the Gram route.
* ``step(closure)`` with a closure returning ``(u, y, loss)``: the network outputs u are
  known, so the solver part and the network part are still differentiated apart.
* ``step(closure)`` with a closure returning ``(y, loss)``: generic, every row of J by a
  batched reverse pass through everything.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable

import torch
from torch import nn

from higbench.dtypes import DTYPES
from higbench.optim.closure import LossClosure, reduce_loss
from higbench.optim.contract import StepReport, StepReporter
from higbench.optim.inversion import TRUNCATION_MODES, gram_coefficients, jacobian_power
from higbench.optim.jacobians import per_sample_jacobian
from higbench.optim.krylov import krylov_direction
from higbench.optim.solver_choice import choose_solver
from higbench.optim.structured import (
    GraphJacobian,
    StructuredJacobian,
    network_jacobian,
    output_jacobian,
    solver_jacobian,
)
from higbench.optim.threads import check_threads, update_threads

SOLVERS = ("auto", "gram", "svd", "krylov")
JACOBIANS = ("structured", "naive")


class JacobianPower(torch.optim.Optimizer, StepReporter):
    """Update theta -= lr * J^<beta,kappa> g (HIG for kappa=-1/2, GN for kappa=-1).

    Each step sets ``last_report`` (``higbench.optim.contract.StepReport``: phase timings,
    whether it was finite and why not, the spectrum); ``last_timings``, ``last_finite`` and
    ``last_reason`` read it. ``last_spectrum`` is what the last inversion saw (also one run
    through ``direction`` alone).

    Args:
        params: parameters to optimise (one group).
        lr: learning rate eta.
        kappa: exponent of the singular values (-1/2 HIG, -1 GN, 1 gradient descent).
        beta: exponent of the prefactor max(s)^beta (paper appendix C).
        tau: truncation; singular values s < tau*max(s) (relative) or s < tau (absolute) dropped.
        truncation: "relative" (default, as the reference code) or "absolute".
        solver: "gram" (eigh of J J^T + one J^T product), "svd" (SVD of J), "auto"
            (gram for wide J unless tau is too small for it in float64; svd for tall J) or
            "krylov" (Lanczos on products with J J^T, K never formed: ``higbench.optim.krylov``;
            approximate unless krylov_steps reaches the rows of J).
        precision: dtype of the inversion ("float64" by default; float32 cannot resolve
            tau below ~1e-3 on the Gram route).
        jacobian: "structured" (solver and network differentiated apart, see
            ``higbench.optim.structured``) or "naive" (torch.func Jacobian through
            network and solver per sample, J always materialised; the reference). Used by
            ``step`` given a ``LossClosure`` (what the runner passes) and ``step_structured``.
        krylov_steps: solver="krylov": most Lanczos steps per update (memory rows x steps).
        krylov_tol: solver="krylov": stop early once the estimated relative error of the
            direction is below it (0: always take krylov_steps).
        threads: torch's threads during an update (``higbench.optim.threads``): "auto"
            (default) runs updates of fewer than 1,536 Gram rows (b·|y|) on one thread,
            which is faster for them even on an idle machine and avoids the collapse of
            torch's default thread count on a shared one (22x on a loaded 2-core machine);
            an integer; or None for torch's count as it is. Restored after each update.
    """

    uses_jacobian = True  # the step contract (optim.contract): J is built; memory guard, spectrum, warm-up
    sets_threads = True  # its `threads` (the Gram eigen-solve's BLAS threads); a run's own key wins

    def __init__(
        self,
        params,
        lr: float = 1.0,
        kappa: float = -0.5,
        beta: float = 0.0,
        tau: float = 1e-6,
        truncation: str = "relative",
        solver: str = "auto",
        precision: str | torch.dtype = "float64",
        jacobian: str = "structured",
        krylov_steps: int = 200,
        krylov_tol: float = 0.0,
        threads: int | str | None = "auto",
    ):
        check_threads(threads)
        if not 0 < lr < math.inf:
            raise ValueError(f"lr={lr}: must be a number > 0")
        if not -1.0 <= kappa <= 1.0:
            raise ValueError(f"kappa={kappa}: must be a number in [-1, 1]")
        if not -1.0 <= beta <= 1.0:
            raise ValueError(f"beta={beta}: must be a number in [-1, 1]")
        if not tau >= 0 or (truncation == "relative" and tau > 1):
            raise ValueError(f"tau={tau}: must be in [0, 1] with truncation=relative (tau > 1 drops every singular value)")
        if truncation not in TRUNCATION_MODES:
            raise ValueError(f"truncation={truncation!r}: expected one of {TRUNCATION_MODES}")
        if solver not in SOLVERS:
            raise ValueError(f"solver={solver!r}: expected one of {SOLVERS}")
        if jacobian not in JACOBIANS:
            raise ValueError(f"jacobian={jacobian!r}: expected one of {JACOBIANS}")
        if isinstance(krylov_steps, bool) or int(krylov_steps) != krylov_steps or krylov_steps < 1:
            raise ValueError(f"krylov_steps={krylov_steps}: must be an integer >= 1")
        if not 0 <= krylov_tol < 1:
            raise ValueError(f"krylov_tol={krylov_tol}: must be a number in [0, 1)")
        if isinstance(precision, str):
            if precision not in DTYPES:
                raise ValueError(f"precision={precision!r}: expected one of {tuple(DTYPES)}")
            precision = DTYPES[precision]
        defaults = dict(
            lr=lr,
            kappa=kappa,
            beta=beta,
            tau=tau,
            truncation=truncation,
            solver=solver,
            precision=precision,
            jacobian=jacobian,
            krylov_steps=int(krylov_steps),
            krylov_tol=float(krylov_tol),
        )
        super().__init__(params, defaults)
        if len(self.param_groups) != 1:
            raise ValueError("JacobianPower supports a single parameter group")
        # What the last update did (the step contract, ``higbench.optim.contract``): phase
        # timings (jacobian_s: all derivatives incl. K or J itself; inversion_s: eigh/SVD and
        # the product back to parameters; apply_s), whether it was finite (a non-finite loss,
        # Jacobian or direction, or a failed inversion, leaves the parameters untouched), why
        # not, and the spectrum. None before the first step.
        self.last_report: StepReport | None = None
        # The spectrum of the last inversion: sv_max, sv_min_kept, sv_dropped, singular_values;
        # on the Krylov route also step_error (estimated relative error of the direction).
        self.last_spectrum: dict = {}
        # b when the objective is the batch mean, 1 for the sum (Levenberg-Marquardt models the sum).
        self.samples_averaged: int = 1
        # Not a param-group key (a checkpoint's state dict stays as it was): where the run
        # sets the threads (the runner), it passes None.
        self.threads = threads
        self._gram_rows: int | None = None  # b·|y| of the last update: what "auto" threads go by

    @property
    def last_timings(self) -> dict[str, float]:
        """Seconds per phase of the last step (empty: refused, or no step yet)."""
        return dict(self.last_report.timings) if self.last_report else {}

    @property
    def last_finite(self) -> bool:
        return self.last_report.finite if self.last_report else True

    @property
    def last_reason(self) -> str:
        return self.last_report.reason if self.last_report else ""

    # -- the pieces, so callers with their own Jacobians (the runner) can time each phase --

    @property
    def group(self) -> dict:
        return self.param_groups[0]

    @property
    def params(self) -> list[torch.Tensor]:
        return self.group["params"]

    def _opts(self) -> dict:
        g = self.group
        return dict(kappa=g["kappa"], beta=g["beta"], tau=g["tau"], truncation=g["truncation"])

    def resolved_solver(self, rows: int | None = None, n_params: int | None = None) -> str:
        """``gram``, ``svd`` or ``krylov`` for a J of rows x n_params (``higbench.optim.solver_choice.choose_solver``)."""
        g = self.group
        return choose_solver(g["solver"], rows, n_params, g["tau"], g["precision"], g["truncation"])

    def _derivative_tail(self, J: torch.Tensor | StructuredJacobian):
        """(route, J, K): the end of the derivative phase, K = J J^T for the Gram route, J
        as it is for the Krylov route (products only), else J as a matrix."""
        precision = self.group["precision"]
        if isinstance(J, StructuredJacobian):
            route = self.resolved_solver(J.rows, J.n_params)
            if route == "krylov":
                return route, J, None
            return (route, J, J.gram()) if route == "gram" else (route, J.matrix().to(precision), None)
        J = J.to(precision)
        route = self.resolved_solver(*J.shape)
        return (route, J, J @ J.T) if route == "gram" else (route, J, None)

    def _inversion(self, route: str, J, K, grad_y: torch.Tensor) -> torch.Tensor:
        g = grad_y.reshape(-1)
        if route == "krylov":
            return self._krylov(J, g)
        if route == "gram":
            try:
                n_params = J.n_params if isinstance(J, StructuredJacobian) else J.shape[1]
                c = gram_coefficients(
                    K, g.to(K.dtype), **self._opts(), overwrite=True, on_spectrum=self._record_spectrum, n_params=n_params
                )
                return J.transpose_apply(c) if isinstance(J, StructuredJacobian) else J.T @ c
            except torch.linalg.LinAlgError as exc:
                # K may be destroyed (overwrite=True); J is intact: retry on the SVD route.
                warnings.warn(f"Gram route failed ({exc}); retrying with the SVD of J", RuntimeWarning, stacklevel=2)
                J = J.matrix().to(self.group["precision"]) if isinstance(J, StructuredJacobian) else J
        return jacobian_power(J, g.to(J.dtype), **self._opts(), on_spectrum=self._record_spectrum)

    def _krylov(self, J, g: torch.Tensor) -> torch.Tensor:
        """The direction from Lanczos on J J^T; its estimated relative error joins ``last_spectrum``."""
        group = self.group
        d, result = krylov_direction(
            J,
            g.to(group["precision"]),
            **self._opts(),
            steps=group["krylov_steps"],
            tol=group["krylov_tol"],
            on_spectrum=self._record_spectrum,
        )
        self.last_spectrum["step_error"] = result.step_error
        self.last_spectrum["krylov_steps"] = result.steps
        return d

    def direction(self, J: torch.Tensor | StructuredJacobian, grad_y: torch.Tensor) -> torch.Tensor:
        """max(s)^beta V diag(s^kappa) U^T g in ``precision``.

        J: the materialised Jacobian (rows, |theta|) or a ``StructuredJacobian`` (then the
        Gram route never forms J); grad_y: (rows,) or anything with rows elements.
        """
        return self._inversion(*self._derivative_tail(J), grad_y)

    @torch.no_grad()
    def apply(self, direction: torch.Tensor) -> None:
        """theta -= lr * direction, direction flat in parameter order."""
        lr, offset = self.group["lr"], 0
        for p in self.params:
            n = p.numel()
            p.sub_(lr * direction[offset : offset + n].view_as(p).to(p.dtype))
            offset += n

    def _sync(self) -> None:
        device = self.params[0].device
        if device.type == "cuda":
            torch.cuda.synchronize(device)

    def _refuse(self, reason: str, inverted: bool = False) -> None:
        """Leave the parameters as they are; say why. ``inverted``: the inversion ran, so
        ``last_spectrum`` is this update's own (kept: it may say why the direction blew up)."""
        if not inverted:
            self.last_spectrum = {}
        self.last_report = StepReport.refused(reason, self.last_spectrum)

    def _report(self, timings: dict[str, float]) -> None:
        """A step taken: its phase times and the spectrum its inversion recorded."""
        self.last_report = StepReport(timings=timings, spectrum=dict(self.last_spectrum))

    def _record_spectrum(self, s: torch.Tensor, keep: torch.Tensor) -> None:
        """What the last inversion saw: largest and smallest kept singular value, how many tau dropped.

        In NumPy: one copy of a few hundred values, then microseconds (torch's per-op overhead
        on such small tensors cost ~1.7% of a toy update).
        """
        values, kept = s.detach().cpu().numpy(), keep.detach().cpu().numpy()
        n_kept = int(kept.sum())
        self.last_spectrum = {
            "sv_max": float(values.max()) if values.size else math.nan,
            "sv_min_kept": float(values[kept].min()) if n_kept else math.nan,
            "sv_dropped": values.size - n_kept,
            "singular_values": values,
        }

    def _update(self, J, grad_y: torch.Tensor, t0: float, evaluate: Callable[[], torch.Tensor]) -> None:
        """The rest of one update from its derivatives: K or J, inversion, apply; timed and checked.

        evaluate: the objective at the current parameters (unused here; Levenberg-Marquardt
        accepts or rejects its step with it).
        """
        route, J, K = self._derivative_tail(J)
        # (The Krylov route never forms K or J: a non-finite J shows in the direction.)
        if route != "krylov" and not torch.isfinite(K if K is not None else J).all():
            return self._refuse("non-finite Jacobian")
        self._sync()
        t1 = time.perf_counter()
        try:
            d = self._inversion(route, J, K, grad_y)
        except torch.linalg.LinAlgError as exc:  # e.g. SVD or eigh failed to converge
            return self._refuse(f"inversion failed: {exc}")
        self._sync()
        t2 = time.perf_counter()
        if not torch.isfinite(d).all():
            return self._refuse("non-finite update direction", inverted=True)
        self.apply(d)
        self._sync()
        self._report({"jacobian_s": t1 - t0, "inversion_s": t2 - t1, "apply_s": time.perf_counter() - t2})

    # -- torch.optim-style entry points for user code --

    def step(self, closure: Callable[[], object]) -> torch.Tensor:  # type: ignore[override]
        """One update through ``closure``; returns the batch-mean loss before it (detached).

        closure, one of:

        * a ``LossClosure`` (``higbench.optim.closure``): the network, solver and per-sample
          loss as pieces, taken by the structured fast path (what the runner passes).
        * a callable returning ``(y, loss)``: y the per-sample physical outputs (b, ...)
          computed from the parameters with autograd enabled, loss the per-sample losses
          (b,) or their scalar mean. Every row of J is one batched reverse pass through
          network and solver.
        * a callable returning ``(u, y, loss)``: as above, with u (b, |u|) the network
          outputs y was computed from; solver part dy_i/du_i and network part are then
          differentiated apart (faster when |u| or the solver is large).

        Samples must be independent. g is the gradient of the batch mean (a ``LossClosure``
        may ask for the sum). A closure returning the scalar loss alone (torch.optim's
        style) raises TypeError: the update needs the per-sample outputs y.
        ``last_timings``, ``last_finite``, ``last_reason`` and ``last_spectrum`` say how the
        update went (a non-finite loss, Jacobian or direction leaves the parameters as they were).
        """
        if isinstance(closure, LossClosure) and closure.outputs_fn is None:
            return self.step_structured(
                closure.model,
                closure.net_inputs,
                closure.physics,
                closure.loss,
                closure.inputs,
                closure.reduction,
                physics_jacobian=closure.physics_jacobian,
            )
        with update_threads(self.threads, self._gram_rows):
            return self._step(closure)

    def _step(self, closure: Callable[[], object]) -> torch.Tensor:
        t0 = time.perf_counter()
        with torch.enable_grad():
            u, y, objective, mean = _closure_outputs(closure)
            (grad_y,) = torch.autograd.grad(objective, y, retain_graph=True)
            if not torch.isfinite(mean):
                self._refuse("non-finite loss")
                return mean.detach()
            y2 = y.reshape(y.shape[0], -1)
            if u is None:  # every output is its own "network output": A_i = I
                u, A = y2, torch.eye(y2.shape[1], dtype=y.dtype, device=y.device).expand(y2.shape[0], -1, -1)
            else:
                A = output_jacobian(y2, u)
            J = GraphJacobian(u, self.params, A, self.group["precision"])
        self._gram_rows = y2.numel()
        reduction = closure.reduction if isinstance(closure, LossClosure) else "mean"
        self.samples_averaged = y.shape[0] if reduction == "mean" else 1

        def evaluate() -> torch.Tensor:
            with torch.no_grad():
                return _closure_outputs(closure)[2]

        self._update(J, grad_y, t0, evaluate)
        return mean.detach()

    def step_structured(
        self,
        model: nn.Module,
        net_inputs: torch.Tensor,
        physics: Callable[..., torch.Tensor],
        loss: Callable[[torch.Tensor], torch.Tensor],
        inputs: torch.Tensor | None = None,
        reduction: str = "mean",
        physics_jacobian: Callable[..., tuple[torch.Tensor, torch.Tensor] | None] | None = None,
    ) -> torch.Tensor:
        """One update for y = physics(inputs, model(net_inputs)) and per-sample loss(y).

        model: the network whose trainable parameters are exactly this optimizer's; an
            ``nn.Sequential`` of ``nn.Linear`` and Tanh/ReLU/Sigmoid/Identity gets the
            per-layer-factor route (no J on the Gram route), anything else torch.func.
        physics: ``physics(inputs, u)`` (or ``physics(u)`` when ``inputs`` is None),
            differentiable, batched, samples independent; returns y (b, ...).
        loss: ``loss(y)`` -> per-sample losses (b,) (or a scalar); g is the gradient of
            their mean, or of their sum with ``reduction="sum"`` (``closure.reduce_loss``).
        physics_jacobian: optional ``physics_jacobian(inputs, u)`` -> (y, A_i = dy_i/du_i) or
            None, e.g. a problem's hand-derived adjoint (``Problem.physics_jacobian``); without
            it (or when it answers None) the solver is differentiated by autograd.
        With ``jacobian="naive"`` J comes from torch.func through network and solver per
        sample (the reference). Returns the batch-mean loss before the update (detached),
        whatever the reduction; ``last_timings``, ``last_finite``, ``last_reason`` and
        ``last_spectrum`` say how the update went.
        """
        with update_threads(self.threads, self._gram_rows):
            return self._step_structured(model, net_inputs, physics, loss, inputs, reduction, physics_jacobian)

    def _step_structured(self, model, net_inputs, physics, loss, inputs, reduction, physics_jacobian) -> torch.Tensor:
        t0 = time.perf_counter()
        naive = self.group["jacobian"] == "naive"
        closure = LossClosure(model, net_inputs, physics, loss, inputs, reduction)
        self.samples_averaged = net_inputs.shape[0] if reduction == "mean" else 1
        with torch.no_grad():
            u = model(net_inputs)
            if naive:
                y = physics(u) if inputs is None else physics(inputs, u)
        if not naive:
            y, A = solver_jacobian(physics, inputs, u, physics_jacobian=physics_jacobian)
        with torch.enable_grad():
            per_sample = loss(y.requires_grad_(True))
            (grad_y,) = torch.autograd.grad(reduce_loss(per_sample, reduction), y)
            value = per_sample.mean().detach()
        self._gram_rows = y.numel()
        if not torch.isfinite(value):
            self._refuse("non-finite loss")
            return value
        if naive:  # the reference: torch.func Jacobian through network and solver per sample, J materialised
            if inputs is None:
                inputs, physics_xu = torch.zeros(u.shape[0], 0, dtype=u.dtype, device=u.device), lambda _x, v: physics(v)
            else:
                physics_xu = physics
            J = per_sample_jacobian(model, physics_xu, inputs, net_inputs)
        elif not torch.isfinite(A).all():
            self._refuse("non-finite Jacobian")
            return value
        else:
            J = network_jacobian(model, self.params, net_inputs, A, self.group["precision"])
        self._update(J, grad_y, t0, closure.objective)
        return value


_CLOSURE_CONTRACT = (
    "a Jacobian-power step needs the per-sample outputs: the closure must return (y, loss) or "
    "(u, y, loss) with y (b, ...) the physical outputs and loss the per-sample losses (b,) or "
    "their mean, or be a higbench.optim.LossClosure; got {}"
)


def _closure_outputs(closure) -> tuple[torch.Tensor | None, torch.Tensor, torch.Tensor, torch.Tensor]:
    """(u or None, y, objective, batch-mean loss) from any closure ``step`` accepts."""
    if closure is None:
        raise TypeError(_CLOSURE_CONTRACT.format("no closure"))
    if isinstance(closure, LossClosure):
        y = closure.outputs()
        per_sample = closure.loss(y)
        return None, y, reduce_loss(per_sample, closure.reduction), per_sample.mean()
    out = closure()
    if not isinstance(out, (tuple, list)) or len(out) not in (2, 3):
        got = f"a {tuple(out.shape)} tensor" if isinstance(out, torch.Tensor) else type(out).__name__
        raise TypeError(_CLOSURE_CONTRACT.format(got))
    *u, y, loss = out
    if loss.ndim > 1 or (loss.ndim == 1 and loss.shape[0] != y.shape[0]):
        raise TypeError(_CLOSURE_CONTRACT.format(f"loss of shape {tuple(loss.shape)} for y of shape {tuple(y.shape)}"))
    mean = reduce_loss(loss, "mean")
    return (u[0] if u else None), y, mean, mean


class HIG(JacobianPower):
    """Half-inverse gradients (Schnell, Holl, Thuerey, ICLR 2022): kappa = -1/2."""

    def __init__(self, params, lr: float = 1.0, tau: float = 1e-6, kappa: float = -0.5, beta: float = 0.0, **kwargs):
        super().__init__(params, lr=lr, kappa=kappa, beta=beta, tau=tau, **kwargs)


class GaussNewton(JacobianPower):
    """Gauss-Newton through the truncated pseudo-inverse of J: kappa = -1."""

    def __init__(self, params, lr: float = 1.0, tau: float = 1e-6, kappa: float = -1.0, beta: float = 0.0, **kwargs):
        super().__init__(params, lr=lr, kappa=kappa, beta=beta, tau=tau, **kwargs)
