"""Optimizers: the Jacobian-power family (HIG, Gauss-Newton) and their inversion.

First-order optimizers are plain ``torch.optim`` classes chosen by config; see
``higbench.runner.updates``.
"""

from higbench.optim.inversion import gram_coefficients, gram_is_accurate, jacobian_power
from higbench.optim.hig import HIG, GaussNewton, JacobianPower

__all__ = ["jacobian_power", "gram_coefficients", "gram_is_accurate", "JacobianPower", "HIG", "GaussNewton"]
