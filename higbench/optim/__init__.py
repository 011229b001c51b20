"""Optimizers: the Jacobian-power family (HIG, Gauss-Newton) and their inversion.

First-order optimizers are plain ``torch.optim`` classes chosen by config; see
``higbench.runner.updates``. Structured derivatives (solver Jacobians by batched reverse
passes, network part from per-layer factors): ``higbench.optim.structured``.
"""

from higbench.optim.hig import HIG, GaussNewton, JacobianPower
from higbench.optim.inversion import gram_coefficients, gram_is_accurate, jacobian_power
from higbench.optim.structured import network_jacobian, solver_jacobian

__all__ = [
    "jacobian_power",
    "gram_coefficients",
    "gram_is_accurate",
    "JacobianPower",
    "HIG",
    "GaussNewton",
    "solver_jacobian",
    "network_jacobian",
]
