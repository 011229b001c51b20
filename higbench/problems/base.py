"""What a learning problem is: data, a network, physics y = P(x, u), a per-sample loss.

The runner and the optimizers only use this interface, so adding a problem is one module
(a ``Problem`` subclass registered with ``@register``) plus one YAML file in conf/problem/.
"""

from __future__ import annotations

import abc
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from higbench.problems.networks import initialise

# problem.loss_reduction: how the per-sample losses of a batch become the training objective.
LOSS_REDUCTIONS = ("mean", "sum")


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

    name: str = "?"

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
        reduction = self.cfg.get("loss_reduction", "mean")
        if reduction not in LOSS_REDUCTIONS:
            raise ValueError(f"loss_reduction={reduction!r}: expected one of {LOSS_REDUCTIONS}")
        return per_sample.sum() if reduction == "sum" else per_sample.mean()

    def metrics(self, y: torch.Tensor, batch: Batch) -> dict[str, torch.Tensor]:
        """Extra per-sample metrics (name -> (b,)) logged as curves next to the loss."""
        return {}

    def outputs(self, model: nn.Module, batch: Batch) -> torch.Tensor:
        return self.physics(batch.inputs, model(batch.net_inputs))

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

    def eval_logs(self, model: nn.Module) -> dict[str, np.ndarray]:
        """Extra fixed-shape arrays recorded at every evaluation (e.g. neuron saturation)."""
        return {}

    @classmethod
    def config_rules(cls) -> dict:
        """Schema of this problem's config keys, ``{key: higbench.config.Check}``.

        Used by ``higbench.config.validate`` for a problem without a table in
        ``higbench.config.PROBLEM_RULES``: keys outside it are refused, each value checked.
        Empty (the default): the problem's keys are not checked.
        """
        return {}


class FixedDataProblem(Problem):
    """A problem with finite train and test tensors built once from the seed."""

    train: Batch
    test: Batch

    def train_size(self) -> int:
        return len(self.train)

    def epoch(self, batch_size: int, generator: torch.Generator) -> Iterator[Batch]:
        order = torch.randperm(len(self.train), generator=generator).to(self.device)
        # Drop the last partial batch: the Jacobian-power step's cost depends on b.
        for start in range(0, len(order) - batch_size + 1, batch_size):
            yield self.train[order[start : start + batch_size]]

    def test_set(self) -> Batch:
        return self.test


_REGISTRY: dict[str, type[Problem]] = {}


def register(name: str):
    def wrap(cls: type[Problem]) -> type[Problem]:
        cls.name = name
        _REGISTRY[name] = cls
        return cls

    return wrap


def registry() -> dict[str, type[Problem]]:
    import higbench.problems  # noqa: F401  (imports every problem module)

    return dict(_REGISTRY)


def build_problem(cfg, dtype: torch.dtype, device: torch.device, seed: int) -> Problem:
    problems = registry()
    name = cfg.name
    if name not in problems:
        raise ValueError(f"problem.name={name!r}: expected one of {sorted(problems)}")
    return problems[name](cfg, dtype=dtype, device=device, seed=seed)
