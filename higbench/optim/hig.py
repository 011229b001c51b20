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

import time
from collections.abc import Callable

import torch
from torch import nn

from higbench.optim.inversion import TRUNCATION_MODES, gram_coefficients, gram_is_accurate, jacobian_power
from higbench.optim.structured import GraphJacobian, StructuredJacobian, network_jacobian, solver_jacobian

SOLVERS = ("auto", "gram", "svd")
JACOBIANS = ("structured", "naive")
_DTYPES = {"float32": torch.float32, "float64": torch.float64}


class JacobianPower(torch.optim.Optimizer):
    """Update theta -= lr * J^<beta,kappa> g (HIG for kappa=-1/2, GN for kappa=-1).

    Args:
        params: parameters to optimise (one group).
        lr: learning rate eta.
        kappa: exponent of the singular values (-1/2 HIG, -1 GN, 1 gradient descent).
        beta: exponent of the prefactor max(s)^beta (paper appendix C).
        tau: truncation; singular values s < tau*max(s) (relative) or s < tau (absolute) dropped.
        truncation: "relative" (default, as the reference code) or "absolute".
        solver: "gram" (eigh of J J^T + one J^T product), "svd" (SVD of J) or "auto"
            (gram for wide J unless tau is too small for it in float64; svd for tall J).
        precision: dtype of the inversion ("float64" by default; float32 cannot resolve
            tau below ~1e-3 on the Gram route).
        jacobian: "structured" (solver and network differentiated apart, see
            ``higbench.optim.structured``) or "naive" (torch.func Jacobian through
            network and solver per sample, J always materialised; the reference). Used by
            the runner; ``step_structured`` and ``step`` follow their own inputs.
    """

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
    ):
        if not lr > 0:
            raise ValueError(f"lr={lr}: must be > 0")
        if not -1.0 <= kappa <= 1.0:
            raise ValueError(f"kappa={kappa}: must lie in [-1, 1]")
        if not tau >= 0:
            raise ValueError(f"tau={tau}: must be >= 0")
        if truncation not in TRUNCATION_MODES:
            raise ValueError(f"truncation={truncation!r}: expected one of {TRUNCATION_MODES}")
        if solver not in SOLVERS:
            raise ValueError(f"solver={solver!r}: expected one of {SOLVERS}")
        if jacobian not in JACOBIANS:
            raise ValueError(f"jacobian={jacobian!r}: expected one of {JACOBIANS}")
        if isinstance(precision, str):
            if precision not in _DTYPES:
                raise ValueError(f"precision={precision!r}: expected one of {tuple(_DTYPES)}")
            precision = _DTYPES[precision]
        defaults = dict(
            lr=lr, kappa=kappa, beta=beta, tau=tau, truncation=truncation, solver=solver, precision=precision, jacobian=jacobian
        )
        super().__init__(params, defaults)
        if len(self.param_groups) != 1:
            raise ValueError("JacobianPower supports a single parameter group")
        self.last_timings: dict[str, float] = {}

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
        """``auto``: the Gram route when J is wide (rows < params) and tau is resolvable.

        For tall J (more rows than parameters, e.g. the toy's 512 x 30) the thin SVD of J is
        cheaper than eigh of the rows x rows Gram matrix.
        """
        g = self.group
        if g["solver"] != "auto":
            return g["solver"]
        if rows is not None and n_params is not None and rows >= n_params:
            return "svd"
        return "gram" if gram_is_accurate(g["tau"], g["precision"], g["truncation"]) else "svd"

    def direction(self, J: torch.Tensor | StructuredJacobian, grad_y: torch.Tensor) -> torch.Tensor:
        """max(s)^beta V diag(s^kappa) U^T g in ``precision``.

        J: the materialised Jacobian (rows, |theta|) or a ``StructuredJacobian`` (then the
        Gram route never forms J); grad_y: (rows,) or anything with rows elements.
        """
        g = self.group
        grad_y = grad_y.reshape(-1).to(g["precision"])
        if isinstance(J, StructuredJacobian):
            if self.resolved_solver(J.rows, J.n_params) == "svd":
                return jacobian_power(J.matrix().to(g["precision"]), grad_y, **self._opts())
            return J.transpose_apply(gram_coefficients(J.gram().to(g["precision"]), grad_y, **self._opts(), overwrite=True))
        J = J.to(g["precision"])
        if self.resolved_solver(*J.shape) == "svd":
            return jacobian_power(J, grad_y, **self._opts())
        return J.T @ gram_coefficients(J @ J.T, grad_y, **self._opts())

    @torch.no_grad()
    def apply(self, direction: torch.Tensor) -> None:
        """theta -= lr * direction, direction flat in parameter order."""
        lr, offset = self.group["lr"], 0
        for p in self.params:
            n = p.numel()
            p.sub_(lr * direction[offset : offset + n].view_as(p).to(p.dtype))
            offset += n

    def _finish(self, J, grad_y: torch.Tensor, t0: float) -> None:
        t1 = time.perf_counter()
        d = self.direction(J, grad_y)
        t2 = time.perf_counter()
        self.apply(d)
        self.last_timings = {"jacobian_s": t1 - t0, "inversion_s": t2 - t1, "apply_s": time.perf_counter() - t2}

    # -- torch.optim-style entry points for user code --

    def step(self, closure: Callable[[], tuple]):  # type: ignore[override]
        """One update. ``closure()`` returns ``(y, loss)`` or ``(u, y, loss)``.

        y: per-sample physical outputs (b, |y|) (or (b, ...), flattened per sample),
        computed from the parameters with autograd enabled; loss: the scalar batch-mean
        loss computed from y. With u (b, |u|), the network outputs y was computed from,
        the solver part dy_i/du_i and the network part are differentiated apart (faster
        when |u| or the solver is large); otherwise every row of J is one batched reverse
        pass through network and solver. Samples must be independent. Returns the loss.
        """
        t0 = time.perf_counter()
        with torch.enable_grad():
            out = closure()
            if len(out) == 3:
                u, y, loss = out
                b = y.shape[0]
                (grad_y,) = torch.autograd.grad(loss, y, retain_graph=True)
                seed = torch.eye(y[0].numel(), dtype=y.dtype, device=y.device)
                m = seed.shape[0]
                (A,) = torch.autograd.grad(
                    y.reshape(b, m), u, seed[:, None, :].expand(m, b, m), is_grads_batched=True, retain_graph=True
                )
                J = GraphJacobian(u, self.params, A.reshape(m, b, -1).transpose(0, 1), self.group["precision"])
            else:
                y, loss = out
                (grad_y,) = torch.autograd.grad(loss, y, retain_graph=True)
                rows = y.numel()
                eye = torch.eye(rows, dtype=y.dtype, device=y.device).reshape(rows, *y.shape)
                jac = torch.autograd.grad(y, self.params, grad_outputs=eye, is_grads_batched=True, allow_unused=True)
                J = torch.cat(
                    [
                        (j if j is not None else torch.zeros(rows, *p.shape, dtype=y.dtype)).reshape(rows, -1)
                        for j, p in zip(jac, self.params)
                    ],
                    dim=1,
                )
        self._finish(J, grad_y, t0)
        return loss.detach()

    def step_structured(
        self,
        model: nn.Module,
        net_inputs: torch.Tensor,
        physics: Callable[..., torch.Tensor],
        loss: Callable[[torch.Tensor], torch.Tensor],
        inputs: torch.Tensor | None = None,
        reduction: str = "mean",
    ) -> torch.Tensor:
        """One update for y = physics(inputs, model(net_inputs)) and per-sample loss(y).

        model: the network whose trainable parameters are exactly this optimizer's; an
            ``nn.Sequential`` of ``nn.Linear`` and Tanh/ReLU/Sigmoid/Identity gets the
            per-layer-factor route (no J on the Gram route), anything else torch.func.
        physics: ``physics(inputs, u)`` (or ``physics(u)`` when ``inputs`` is None),
            differentiable, batched, samples independent; returns y (b, ...).
        loss: ``loss(y)`` -> per-sample losses (b,) (or a scalar); g is the gradient of
            their mean, or of their sum with ``reduction="sum"`` (a b-times larger g: the
            convention of the reference's Poisson script).
        Returns the batch-mean loss before the update (detached).
        """
        t0 = time.perf_counter()
        with torch.no_grad():
            u = model(net_inputs)
        y, A = solver_jacobian(physics, inputs, u)
        with torch.enable_grad():
            y_leaf = y.requires_grad_(True)
            per_sample = loss(y_leaf)
            if reduction not in ("mean", "sum"):
                raise ValueError(f"reduction={reduction!r}: expected 'mean' or 'sum'")
            objective = per_sample.sum() if reduction == "sum" and per_sample.ndim > 0 else per_sample.mean()
            value = per_sample.mean()
            (grad_y,) = torch.autograd.grad(objective, y_leaf)
        J = network_jacobian(model, self.params, net_inputs, A, self.group["precision"])
        self._finish(J, grad_y, t0)
        return value.detach()


class HIG(JacobianPower):
    """Half-inverse gradients (Schnell, Holl, Thuerey, ICLR 2022): kappa = -1/2."""

    def __init__(self, params, lr: float = 1.0, tau: float = 1e-6, kappa: float = -0.5, beta: float = 0.0, **kwargs):
        super().__init__(params, lr=lr, kappa=kappa, beta=beta, tau=tau, **kwargs)


class GaussNewton(JacobianPower):
    """Gauss-Newton through the truncated pseudo-inverse of J: kappa = -1."""

    def __init__(self, params, lr: float = 1.0, tau: float = 1e-6, kappa: float = -1.0, beta: float = 0.0, **kwargs):
        super().__init__(params, lr=lr, kappa=kappa, beta=beta, tau=tau, **kwargs)
