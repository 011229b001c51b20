"""What the shared tests run over, taken from where higbench keeps it (curvlinops' test/cases.py).

A new problem (a module in higbench/problems/ registering a ``Problem`` subclass, plus its YAML
in conf/problem/: ``registry()`` finds both by scanning) or a new optimizer (its card, a YAML in
conf/optimizer/: ``higbench.cards``) is picked up by every test parametrized from here, without
editing a test (tests/test_cards.py ships one of each in a scratch copy and checks it). Tests
that check a fact of one problem (its parameter count, its physics) keep their own tables.

Also here: the one tiny run (``TINY_RUN``) that the CLI tests add to their overrides.
"""

from __future__ import annotations

from higbench.cards import optimizer_cards, problem_configs
from higbench.problems.base import FixedDataProblem, registry

# A run of a few updates, an evaluation after each, one torch thread (the test machine's 2
# shared cores: 2 threads per process oversubscribe them), no progress bar. Later overrides
# on the same command line win (e.g. budget.max_updates=20 after it).
TINY_RUN = ("budget.max_updates=3", "budget.seconds=null", "eval_unit=updates", "eval_every=1", "progress=false", "threads=1")

# Problems: the registered classes (``higbench.problems.base.registry``) and the configs that
# ``problem=NAME`` takes (one class may have several: dipole and dipole_cnn).
PROBLEMS = sorted(registry())
PROBLEM_CONFIGS = sorted(problem_configs())
# Problems whose train and test sets are drawn once from ``problem.data_seed`` (Poisson draws
# its training samples from the run's seed).
FIXED_DATA_PROBLEMS = sorted(name for name, cls in registry().items() if issubclass(cls, FixedDataProblem))

# Optimizers: one card each in conf/optimizer/ (``optimizer=NAME``).
OPTIMIZERS = sorted(optimizer_cards())

# Overrides that keep a problem's run a fraction of a second: a small batch and test set
# (keys every problem's base config has).
SMALL_RUN = ("batch_size=4", "problem.test_size=16")
