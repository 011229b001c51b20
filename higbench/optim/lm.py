"""Levenberg-Marquardt in the Jacobian-power family: damped Gauss-Newton with an adaptive lambda.

The direction for the stacked per-sample Jacobian J and output gradient g is

    d = (J^T J + lambda I)^-1 J^T g = J^T (K + lambda I)^-1 g        (K = J J^T, push-through)

(g the gradient of the batch sum of per-sample losses, whose Gauss-Newton model has Hessian
I for l_i = |r_i|^2 / 2; a mean objective is scaled by b), so the Gram route of HIG/GN serves
it unchanged: one eigen-decomposition K = U diag(s^2) U^T
per update, after which the direction for any lambda costs one product,
d = J^T U diag(1 / (s^2 + lambda)) U^T g (on the SVD route, for tall J, V diag(s / (s^2 +
lambda)) U^T g). The step theta -= lr * d is tried on the same batch through the closure
and kept when the gain ratio

    rho = (L(theta) - L(theta - lr d)) / (predicted decrease of the model g^T J dt + |J dt|^2 / 2)

is positive (Nielsen's update: lambda *= max(1/3, 1 - (2 rho - 1)^3), nu = 2); otherwise the
parameters are restored and lambda *= nu, nu *= 2, up to ``max_tries`` trials. lambda and
nu live in the parameter group, so they are checkpointed with the optimizer.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import torch

from higbench.optim.hig import JacobianPower
from higbench.optim.inversion import gram_eigen
from higbench.optim.lapack import svd
from higbench.optim.structured import StructuredJacobian


class LevenbergMarquardt(JacobianPower):
    """Levenberg-Marquardt: ``d = J^T (K + lambda I)^-1 g`` with lambda adapted by accept/reject.

    Args:
        lr: step scale (1: the LM step itself).
        damping: the first lambda, relative to the largest eigenvalue of K (then absolute,
            carried from update to update).
        max_tries: trial steps per update; when all are rejected the parameters stay.
        solver, precision, jacobian, tau: as for ``JacobianPower`` (tau only picks the route).
    """

    def __init__(self, params, lr: float = 1.0, damping: float = 1e-3, max_tries: int = 10, **kwargs):
        if not 0 < damping < math.inf:
            raise ValueError(f"damping={damping}: must be a number > 0")
        if int(max_tries) != max_tries or max_tries < 1:
            raise ValueError(f"max_tries={max_tries}: must be an integer >= 1")
        if kwargs.get("solver") == "krylov":  # its trials reuse one eigen-decomposition of K
            raise ValueError("solver='krylov': Levenberg-Marquardt needs gram, svd or auto")
        super().__init__(params, lr=lr, kappa=-1.0, beta=0.0, **kwargs)
        self.group.update(damping=damping, max_tries=int(max_tries), lam=None, nu=2.0)

    def _spectral(self, route: str, J, K, g: torch.Tensor):
        """(eigenvalues s^2 of K, p = U^T g, direction(weights)) from one decomposition."""
        if route == "gram":
            lam, project, expand = gram_eigen(K, overwrite=True)  # tridiagonal for large K: U never formed

            def direction(w: torch.Tensor) -> torch.Tensor:
                c = expand(w)
                return J.transpose_apply(c) if isinstance(J, StructuredJacobian) else J.T @ c

            return lam.clamp_min(0), project(g.to(lam.dtype)), direction
        J = J.matrix().to(self.group["precision"]) if isinstance(J, StructuredJacobian) else J
        U, s, Vh = svd(J)
        return s * s, U.T @ g.to(s.dtype), lambda w: Vh.T @ (s * w)

    def _update(self, J, grad_y: torch.Tensor, t0: float, evaluate: Callable[[], torch.Tensor]) -> None:
        route, J, K = self._derivative_tail(J)
        if not torch.isfinite(K if K is not None else J).all():
            return self._refuse("non-finite Jacobian")
        self._sync()
        t1 = time.perf_counter()
        # The model is that of the batch *sum* of per-sample losses (for l_i = |r_i|^2 / 2 its
        # Hessian in y is I): with a mean objective g and the loss are scaled by b.
        scale = self.samples_averaged
        try:
            ev, p, direction = self._spectral(route, J, K, scale * grad_y.reshape(-1))
        except torch.linalg.LinAlgError as exc:
            return self._refuse(f"inversion failed: {exc}")
        floor = ev.numel() * torch.finfo(ev.dtype).eps * ev.max()
        # J has min(rows, params) singular values: a tall J's K has rows - params more
        # eigenvalues, zeros by structure, which no truncation dropped (as gram_coefficients).
        top = torch.topk(ev, min(ev.numel(), sum(q.numel() for q in self.params))).values
        self._record_spectrum(top.sqrt(), top > floor)
        self._sync()
        t2 = time.perf_counter()
        accepted = self._trials(ev, p, direction, lambda: scale * evaluate())
        if accepted is None:
            return self._refuse("non-finite update direction")
        timings = {"jacobian_s": t1 - t0, "inversion_s": t2 - t1, "apply_s": time.perf_counter() - t2}
        self.last_spectrum["lm_lambda"], self.last_spectrum["lm_accepted"] = self.group["lam"], accepted
        self._report(timings)

    @torch.no_grad()
    def _trials(self, ev: torch.Tensor, p: torch.Tensor, direction, evaluate) -> bool | None:
        """Trial steps with Nielsen's lambda update; whether one was kept (None: non-finite direction)."""
        group, lr = self.group, self.group["lr"]
        if group["lam"] is None:
            group["lam"] = group["damping"] * float(ev.max()) if ev.numel() and ev.max() > 0 else group["damping"]
        saved = [q.detach().clone() for q in self.params]
        before = float(evaluate())
        for _ in range(group["max_tries"]):
            lam = group["lam"]
            w = p / (ev + lam)
            d = direction(w)
            if not torch.isfinite(d).all():
                return None
            # The Gauss-Newton model's decrease for the step -lr*d: J d = U diag(ev) w in U's basis.
            jd = ev * w
            predicted = float(lr * (p * jd).sum() - 0.5 * lr * lr * (jd * jd).sum())
            self.apply(d)
            after = float(evaluate())
            rho = (before - after) / predicted if predicted > 0 else -math.inf
            if math.isfinite(after) and rho > 0:
                group["lam"] = lam * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                group["nu"] = 2.0
                return True
            for q, s in zip(self.params, saved):
                q.copy_(s)
            group["lam"], group["nu"] = lam * group["nu"], group["nu"] * 2.0
        return False
