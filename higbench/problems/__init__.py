"""Learning problems. Each module registers one ``Problem`` subclass; see ``base.py``.

The physics solvers are pure functions in ``higbench.physics`` and are re-exported by
the problem modules: ``higbench.problems.oscillator.simulate``,
``higbench.problems.poisson.laplace``, ``higbench.problems.dipole.simulate`` / ``eigenstate``.
"""

from higbench.problems import dipole, oscillator, poisson, toy  # noqa: F401  (registers them)
from higbench.problems.base import Batch, Problem, build_problem, register, registry

__all__ = ["Batch", "Problem", "build_problem", "register", "registry"]
