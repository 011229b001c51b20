"""Learning problems. Each module registers one ``Problem`` subclass; see ``base.py``."""

from higbench.problems import toy  # noqa: F401
from higbench.problems.base import Batch, Problem, build_problem, register, registry

__all__ = ["Batch", "Problem", "build_problem", "register", "registry"]
