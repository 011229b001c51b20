"""Optimizers: the Jacobian-power family (HIG, Gauss-Newton, Levenberg-Marquardt) and their inversion.

The family, each with ``step_structured(model, net_inputs, physics, loss, inputs=...)`` and
``step(closure)``: ``HIG`` (kappa = -1/2), ``GaussNewton`` (kappa = -1), ``LevenbergMarquardt``
(damped Gauss-Newton, its damping adapted by accepting or rejecting each trial step) and
``JacobianPower`` (any kappa and beta).

Every optimizer takes one update through ``optimizer.step(closure)``; ``LossClosure``
(``higbench.optim.closure``) is a torch.optim closure that also carries the structure of
the loss, so the Jacobian-power optimizers take their fast path. First-order optimizers
are plain ``torch.optim`` classes chosen by config. Structured derivatives (solver
Jacobians by batched reverse passes, network part from per-layer factors):
``higbench.optim.structured``.
"""

from higbench.optim.closure import LossClosure, reduce_loss
from higbench.optim.hig import HIG, GaussNewton, JacobianPower
from higbench.optim.inversion import gram_coefficients, jacobian_power
from higbench.optim.lm import LevenbergMarquardt
from higbench.optim.solver_choice import gram_is_accurate
from higbench.optim.structured import network_jacobian, solver_jacobian

__all__ = [
    "jacobian_power",
    "gram_coefficients",
    "gram_is_accurate",
    "JacobianPower",
    "HIG",
    "GaussNewton",
    "LevenbergMarquardt",
    "LossClosure",
    "reduce_loss",
    "solver_jacobian",
    "network_jacobian",
]
