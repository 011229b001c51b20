"""What a learning problem is: the contract between a problem and the rest of higbench.

The runner, the optimizers and the results only use this surface, so adding a problem is one
module (a ``Problem`` subclass with its ``Config`` schema) plus one YAML file in a ``problem``
config group whose ``_target_`` names the class (docs/recipe.md; a shipped one also registers
its name with ``@register``, and ``registry()`` finds it by scanning, so the shared tests pick
it up without an import line anywhere).

Required (abstract on ``Problem``; ``FixedDataProblem`` supplies the data methods from
``_sample``):

* ``make_model()``: the network, before initialisation (``build_model`` initialises it).
* ``physics(inputs, u) -> y``: the differentiable simulator y = P(x, u), batched (b, |y|),
  samples independent. Every optimizer differentiates through it.
* ``loss(y, targets) -> (b,)``: one value per sample (``objective`` reduces them by
  ``problem.loss_reduction``).
* ``train_size()``, ``epoch(batch_size, generator)``, ``test_set()``: the data as ``Batch``es
  (z into the network, x into the physics, targets into the loss).

Optional, each with a default that means "not declared":

* ``physics_jacobian(inputs, u) -> (y, A) | None``: y and the per-sample solver Jacobians
  A_i = dy_i/du_i (b, |y|, |u|) by the problem's own means (a hand-derived adjoint sweep);
  None (the default) lets autograd differentiate ``physics``. Only the Jacobian-power
  optimizers ask (through ``LossClosure.physics_jacobian``).
* ``inverse_simulator(inputs, y_target, u0) -> u``: P^-1 near ``u0``; a class that overrides
  it has ``has_inverse_simulator()`` True, and only then may ``optimizer=sip`` run on it.
* ``outputs(model, batch)``: y computed another way than ``physics(x, model(z))`` (the
  Jacobian-power optimizers then differentiate through it generically).
* ``metrics(y, batch)``, ``eval_logs(model)``, ``val_set()``: extra curves and arrays.

What the problem is judged by lives in its YAML file and is read through the problem (a
recorded or shipped config without a problem built: ``higbench.results.targets``):

* ``targets``: the test-loss targets of the time-to-target tables, the profile and the league;
* ``league_seconds``: the league's training-clock budget per run where no target-setting runs
  set one;
* ``target_seconds``: the budget of the league's target-setting runs (its budget is then 3x the
  reference optimizer's median time to the validation target).
"""

from __future__ import annotations

import abc
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Optional

import numpy as np
import torch
from torch import nn

from higbench.losses import LOSS_REDUCTIONS, reduce_loss
from higbench.problems.networks import INIT_SCHEMES, initialise
from higbench.schema import value

# problem.solver of the time-stepping problems: the compiled loop with its adjoint, or plain torch.
PHYSICS_SOLVERS = ("fast", "reference")
# Most samples a validation or fresh test set may ask for; the memory guard bounds them first.
MAX_SAMPLES = 10**9
LATER_DRAWS = ("val_size", "fresh_test_size")  # drawn after train and test, in this order, when first asked for


@dataclass
class ProblemConfig:
    """Keys every problem has. A problem's ``Config`` adds its own, each with its rule."""

    _target_: Optional[str] = None  # noqa: UP045 - OmegaConf reads Optional; the Problem class
    name: str = value()
    test_size: int = value(ge=1)
    data_seed: int = value(ge=0)
    init: str = value("glorot", choices=INIT_SCHEMES)
    loss_reduction: str = value("mean", choices=LOSS_REDUCTIONS)
    # The keys below change neither training nor the test loss (identity=False: a run keeps its
    # identity, results.index.config_id). The validation set is drawn after train and test, so
    # those draws stay what every earlier run had; 0: no validation curve.
    # Both are drawn when first used, after the runner checked them against memory (runner.train.check_data_memory).
    val_size: int = value(0, ge=0, le=MAX_SAMPLES, identity=False)
    # A second, large test draw (after every other set) evaluated once, at the end of a run
    # (the file's /final/fresh_test_losses): a mean over one finite test set can rest on a few
    # samples (the oscillator's heavy tail); 0: none.
    fresh_test_size: int = value(0, ge=0, le=MAX_SAMPLES, identity=False)
    # What the problem is judged by (the league, the profile, the progress line): test-loss targets,
    # the league's budget in training-clock seconds, and the held-out variants the league never tunes on
    # (each an override list, e.g. "problem.gamma=0.001").
    targets: Optional[list[float]] = value(None, gt=0, identity=False)  # noqa: UP045
    league_seconds: Optional[float] = value(None, gt=0, identity=False)  # noqa: UP045
    target_seconds: Optional[float] = value(None, gt=0, identity=False)  # noqa: UP045
    held_out: Optional[list[str]] = value(None, identity=False)  # noqa: UP045


@dataclass
class FixedDataConfig(ProblemConfig):
    train_size: int = value(ge=1)


@dataclass
class Batch:
    """net_inputs z go into the network; inputs x go into the physics; targets into the loss."""

    net_inputs: torch.Tensor
    inputs: torch.Tensor
    targets: torch.Tensor

    def __len__(self) -> int:
        return self.net_inputs.shape[0]

    def __getitem__(self, idx) -> Batch:
        return Batch(self.net_inputs[idx], self.inputs[idx], self.targets[idx])


class Problem(abc.ABC):
    """A physics-based learning problem. ``cfg`` is the ``problem`` config node."""

    name: str = "?"  # the problem.name its runs record (set by @register)
    Config: type = ProblemConfig  # the schema of the problem node (higbench.schema)

    def __init__(self, cfg, dtype: torch.dtype, device: torch.device, seed: int):
        self.cfg = cfg
        self.dtype = dtype
        self.device = device
        self.seed = seed

    # -- model --
    @abc.abstractmethod
    def make_model(self) -> nn.Module:
        """The network, before initialisation."""

    def build_model(self, generator_seed: int | None = None) -> nn.Module:
        torch.manual_seed(self.seed if generator_seed is None else generator_seed)
        model = initialise(self.make_model(), self.cfg.get("init", "glorot"))
        return model.to(device=self.device, dtype=self.dtype)

    # -- physics and loss --
    @abc.abstractmethod
    def physics(self, inputs: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        """y = P(x, u): (b, |y|) physical outputs from network outputs u (b, |u|)."""

    @abc.abstractmethod
    def loss(self, y: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        """Per-sample loss (b,)."""

    def objective(self, per_sample: torch.Tensor) -> torch.Tensor:
        """The scalar every optimizer differentiates: the batch mean (default) or sum of the
        per-sample losses (``problem.loss_reduction``; the reference's Poisson script sums).
        Curves and logged losses stay per-sample means either way."""
        return reduce_loss(per_sample, self.cfg.get("loss_reduction", "mean"))

    def metrics(self, y: torch.Tensor, batch: Batch) -> dict[str, torch.Tensor]:
        """Extra per-sample metrics (name -> (b,)) logged as curves next to the loss."""
        return {}

    def outputs(self, model: nn.Module, batch: Batch) -> torch.Tensor:
        return self.physics(batch.inputs, model(batch.net_inputs))

    # -- optional: the solver's Jacobian by the problem's own means (GN/HIG/LM ask for it) --
    def physics_jacobian(self, inputs: torch.Tensor, u: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor] | None:
        """y (b, |y|) and A_i = dy_i/du_i (b, |y|, |u|) of ``physics(inputs, u)``, or None: use autograd.

        Optional. Override it where the problem has a faster route than autograd's batched
        reverse passes (the compiled oscillator and dipole solvers' adjoint sweeps); it may
        answer None case by case (e.g. on a device its compiled solver cannot run on).
        """
        return None

    # -- optional: an inverse simulator (the SIP optimizer needs one) --
    def inverse_simulator(self, inputs: torch.Tensor, y_target: torch.Tensor, u0: torch.Tensor) -> torch.Tensor:
        """u with physics(inputs, u) = y_target, or as close as the problem's inverse gets: P^-1(x, y*; u0).

        Optional. A problem that overrides it declares an inverse simulator: exact where P is
        invertible (toy, Poisson), else a local or regularised inverse near the current guess
        ``u0`` (b, |u>) (the heat example). Batched like ``physics``: y_target (b, |y|) -> (b, |u|).
        ``optimizer=sip`` refuses a problem that does not override it (``has_inverse_simulator``).
        """
        raise NotImplementedError(f"problem {self.name} has no inverse simulator")

    @classmethod
    def has_inverse_simulator(cls) -> bool:
        return cls.inverse_simulator is not Problem.inverse_simulator

    # -- data --
    @abc.abstractmethod
    def train_size(self) -> int | None:
        """Number of training samples (None for an infinite, sampled-on-the-fly set)."""

    @abc.abstractmethod
    def epoch(self, batch_size: int, generator: torch.Generator) -> Iterator[Batch]:
        """One epoch of shuffled mini-batches."""

    @abc.abstractmethod
    def test_set(self) -> Batch:
        """Held-out data for the curves (fixed for the run)."""

    @property
    def val(self) -> Batch | None:
        """The validation set (``problem.val_size``; None: none). Drawn at first use where the
        problem kept its generator after the test set (``keep_later_draws``): the runner has
        checked its size against memory by then (``runner.train.check_data_memory``)."""
        if "_val" not in vars(self):
            state = getattr(self, "_state_after_test", None)
            if state is None:
                return None
            gen = torch.Generator()
            gen.set_state(state)
            self._val = draw_validation(self, gen)
            self.keep_fresh_draw(gen)
        return self._val

    @val.setter
    def val(self, batch: Batch | None) -> None:  # a problem that draws it itself (``draw_validation``)
        self._val = batch

    def val_set(self) -> Batch | None:
        """Validation data, disjoint from train and test (``val``; None: none). Tuning reads
        only its curve (``val_loss``); the test loss is read for the table."""
        return self.val

    def fresh_test_set(self) -> Batch | None:
        """``problem.fresh_test_size`` samples drawn from ``data_seed``'s generator after every
        other set (so those stay as they were), drawn when asked: the run evaluates it once, at
        its end. None when the size is 0 or the problem keeps no generator state to draw from."""
        n = int(self.cfg.get("fresh_test_size") or 0)
        self.val  # noqa: B018 - drawn first: the fresh draw follows the validation set's
        state = getattr(self, "_state_after_draws", None)
        if not n or state is None:
            return None
        gen = torch.Generator()
        gen.set_state(state)
        return self._sample(n, gen)

    def keep_later_draws(self, gen: torch.Generator) -> None:
        """Remember ``gen`` after the test set was drawn: the validation set and then the fresh
        test set are drawn from there when first asked for (``val_set``, ``fresh_test_set``),
        after the runner has checked their sizes against memory (``runner.train.check_data_memory``)."""
        self._state_after_test = gen.get_state()

    def keep_fresh_draw(self, gen: torch.Generator) -> None:
        """Remember ``gen`` after the last fixed set was drawn: ``fresh_test_set`` draws from there
        (for a problem that draws its validation set itself, with ``draw_validation``)."""
        self._state_after_draws = gen.get_state()

    def sample_bytes(self) -> int:
        """Bytes one sample of this problem's data holds (its test set's first), for the memory guard."""
        one = self.test_set()[:1]
        return sum(t.numel() * t.element_size() for t in (one.net_inputs, one.inputs, one.targets))

    def eval_logs(self, model: nn.Module) -> dict[str, np.ndarray]:
        """Extra fixed-shape arrays recorded at every evaluation (e.g. neuron saturation)."""
        return {}

    # -- what it is judged by (its YAML file's ``targets`` and ``league_seconds``) --
    @property
    def targets(self) -> tuple[float, ...]:
        """Test-loss targets, largest first as written (empty: the YAML names none)."""
        return tuple(float(t) for t in (self.cfg.get("targets") or ()))

    @property
    def league_seconds(self) -> float | None:
        """The league's training-clock budget per run (None: the YAML names none)."""
        seconds = self.cfg.get("league_seconds")
        return None if seconds is None else float(seconds)


class FixedDataProblem(Problem):
    """A problem with finite train and test tensors built once from the seed."""

    Config = FixedDataConfig

    train: Batch
    test: Batch

    def _sample(self, n: int, gen: torch.Generator) -> Batch:
        """``n`` samples drawn with ``gen``: each fixed-data problem's own."""
        raise NotImplementedError

    def sample_datasets(self) -> None:
        """Set ``self.train``, ``self.test`` and ``self.val`` from ``self._sample``, with one generator
        seeded by ``data_seed``: train drawn first, then test (the order every run so far was made
        with), then, when first asked for, the validation set (``problem.val_size``; after the
        others, so they stay as they were)."""
        gen = torch.Generator().manual_seed(int(self.cfg.data_seed))
        self.train = self._sample(int(self.cfg.train_size), gen)
        self.test = self._sample(int(self.cfg.test_size), gen)
        self.keep_later_draws(gen)

    def train_size(self) -> int:
        return len(self.train)

    def epoch(self, batch_size: int, generator: torch.Generator) -> Iterator[Batch]:
        order = torch.randperm(len(self.train), generator=generator).to(self.device)
        # Drop the last partial batch: the Jacobian-power step's cost depends on b.
        for start in range(0, len(order) - batch_size + 1, batch_size):
            yield self.train[order[start : start + batch_size]]

    def test_set(self) -> Batch:
        return self.test


def draw_validation(problem: Problem, gen: torch.Generator) -> Batch | None:
    """``problem.val_size`` samples from ``gen`` (the generator that drew the test set, after it), or None."""
    n = int(problem.cfg.get("val_size") or 0)
    return problem._sample(n, gen) if n else None


_REGISTRY: dict[str, type[Problem]] = {}


def register(name: str):
    def wrap(cls: type[Problem]) -> type[Problem]:
        cls.name = name
        _REGISTRY[name] = cls
        return cls

    return wrap


ENTRY_POINT_GROUP = "higbench.problems"  # an installed package's problems: NAME = "module" or "module:Class"


def registry() -> dict[str, type[Problem]]:
    """Every problem class by name, found, not listed: the modules of higbench/problems/, the
    classes the shipped problem configs name (conf/problem/*.yaml's ``_target_``:
    ``higbench.cards.problem_targets``) and the modules or classes installed packages declare
    in the ``higbench.problems`` entry-point group. A module that fails to import raises: a
    problem is never silently missing (tests/cases.py parametrises the shared tests from here)."""
    import importlib
    import pkgutil
    from importlib.metadata import entry_points

    import higbench.problems
    from higbench.cards import problem_targets

    for module in pkgutil.iter_modules(higbench.problems.__path__, "higbench.problems."):
        importlib.import_module(module.name)
    for target, name in problem_targets().items():  # a class no decorator registered: by its config's name
        module, _, qualname = target.rpartition(".")
        found = getattr(importlib.import_module(module), qualname)
        if found not in _REGISTRY.values():
            register(name)(found)
    for entry in entry_points(group=ENTRY_POINT_GROUP):
        found = entry.load()
        if isinstance(found, type) and issubclass(found, Problem) and found not in _REGISTRY.values():
            register(entry.name)(found)
    return dict(_REGISTRY)


def build_problem(cfg, dtype: torch.dtype, device: torch.device, seed: int) -> Problem:
    """The problem of a ``problem`` node: its ``_target_`` class (as optimizers are built),
    else, for configs stored before problems had one, the class registered under its name."""
    from hydra.utils import get_class

    target = cfg.get("_target_")
    if target is None:
        problems = registry()
        if cfg.name not in problems:
            raise ValueError(f"problem.name={cfg.name!r}: expected one of {sorted(problems)}")
        return problems[cfg.name](cfg, dtype=dtype, device=device, seed=seed)
    return get_class(target)(cfg, dtype=dtype, device=device, seed=seed)
