"""Learning problems. Each module registers one ``Problem`` subclass; see ``base.py``.
``registry()`` finds them by scanning this folder and conf/problem/ (no import list here).

The physics solvers are pure functions in ``higbench.physics`` and are re-exported by
the problem modules: ``higbench.problems.oscillator.simulate``,
``higbench.problems.poisson.laplace``, ``higbench.problems.dipole.simulate`` / ``eigenstate``.
"""

from higbench.problems.base import Batch, Problem, build_problem, register, registry

__all__ = ["Batch", "Problem", "build_problem", "register", "registry"]
