"""What the shared tests run over, taken from where higbench keeps it (curvlinops' test/cases.py).

A new problem (a ``Problem`` subclass registered in ``higbench.problems`` plus its YAML in
conf/problem/) or a new optimizer (a YAML in conf/optimizer/) is picked up by every test
parametrized from here, without editing a test. Tests that check a fact of one problem (its
parameter count, its physics) keep their own tables.

Also here: the one tiny run (``TINY_RUN``) that the CLI tests add to their overrides.
"""

from __future__ import annotations

from pathlib import Path

from higbench.problems.base import FixedDataProblem, registry

CONF = Path(__file__).resolve().parents[1] / "conf"

# A run of a few updates, an evaluation after each, one torch thread (the test machine's 2
# shared cores: 2 threads per process oversubscribe them), no progress bar. Later overrides
# on the same command line win (e.g. budget.max_updates=20 after it).
TINY_RUN = ("budget.max_updates=3", "budget.seconds=null", "eval_unit=updates", "eval_every=1", "progress=false", "threads=1")

# Problems: the registered classes (``higbench.problems.base.registry``) and the configs that
# ``problem=NAME`` takes (one class may have several: dipole and dipole_cnn).
PROBLEMS = sorted(registry())
PROBLEM_CONFIGS = sorted(p.stem for p in (CONF / "problem").glob("*.yaml"))
# Problems whose train and test sets are drawn once from ``problem.data_seed`` (Poisson draws
# its training samples from the run's seed).
FIXED_DATA_PROBLEMS = sorted(name for name, cls in registry().items() if issubclass(cls, FixedDataProblem))

# Optimizers: one YAML each in conf/optimizer/ (``optimizer=NAME``).
OPTIMIZERS = sorted(p.stem for p in (CONF / "optimizer").glob("*.yaml"))

# Overrides that keep a problem's run a fraction of a second: a small batch and test set
# (keys every problem's base config has).
SMALL_RUN = ("batch_size=4", "problem.test_size=16")
