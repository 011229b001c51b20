"""Your own problem for higbench: the whole of it is this module and conf/problem/heat.yaml.

Inverse heat equation on a rod: the network sees the temperature after ``steps`` explicit
diffusion steps and proposes the initial temperature; the physics diffuses the proposal
and the loss compares it with what was observed.

higbench finds the YAML through ``hydra.searchpath=[file://examples/heat/conf]`` and this
module through ``PYTHONPATH=examples/heat`` (the YAML's ``problem._target_`` is
``heat_problem.Heat``). The recipe in docs/recipe.md compares optimizers on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from higbench.problems.base import Batch, FixedDataConfig, FixedDataProblem
from higbench.problems.networks import mlp
from higbench.schema import value


class Heat(FixedDataProblem):
    name = "heat"

    @dataclass
    class Config(FixedDataConfig):
        points: int = value(ge=3)
        steps: int = value(ge=1)
        alpha: float = value(gt=0, le=0.5)  # explicit Euler is stable up to 1/2
        hidden: list[int] = value(ge=1)
        inverse_regularization: float = value(1e-3, gt=0)  # lambda of the inverse simulator (SIP)

    def __init__(self, cfg, dtype, device, seed):
        super().__init__(cfg, dtype, device, seed)
        self.sample_datasets()

    def _sample(self, n: int, gen: torch.Generator) -> Batch:
        x = torch.linspace(0, 1, self.cfg.points, dtype=torch.float64)
        k = torch.arange(1, 4, dtype=torch.float64)
        initial = (torch.randn(n, 3, generator=gen, dtype=torch.float64) / k) @ torch.sin(torch.pi * k[:, None] * x)
        observed = self.physics(None, initial.to(self.dtype)).to(self.device)
        return Batch(net_inputs=observed, inputs=observed, targets=observed)

    def make_model(self) -> torch.nn.Module:
        return mlp([self.cfg.points, *self.cfg.hidden, self.cfg.points], activation="tanh")

    def physics(self, inputs, u: torch.Tensor) -> torch.Tensor:
        for _ in range(self.cfg.steps):  # u_i += alpha (u_{i-1} - 2 u_i + u_{i+1}), ends held at 0
            inner = u[:, :-2] - 2 * u[:, 1:-1] + u[:, 2:]
            u = torch.nn.functional.pad(u[:, 1:-1] + self.cfg.alpha * inner, (1, 1))
        return u

    def loss(self, y: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        return 0.5 * ((y - targets) ** 2).sum(dim=1)

    def inverse_simulator(self, inputs, y_target: torch.Tensor, u0: torch.Tensor) -> torch.Tensor:
        """A regularised local inverse (for optimizer=sip): diffusion damps the high modes by
        factors down to (1 - 4 alpha)^steps, so an exact inverse would amplify noise as much.
        Tikhonov towards the current guess u0 instead, with lambda = inverse_regularization:

            u = argmin |A u - y*|^2 + lambda |u - u0|^2 = u0 + (A^T A + lambda I)^-1 A^T (y* - A u0)

        (A: the linear diffusion operator of ``physics``). Modes with singular value well above
        sqrt(lambda) are inverted exactly; the others stay near u0.
        """
        if getattr(self, "_inverse_parts", None) is None:
            eye = torch.eye(self.cfg.points, dtype=torch.float64)
            a = self.physics(None, eye).T  # physics is linear: row i of physics(I) is A e_i
            normal = a.T @ a + self.cfg.inverse_regularization * eye
            self._inverse_parts = (a.to(self.device), torch.linalg.cholesky(normal).to(self.device))
        a, factor = self._inverse_parts
        u0 = u0.to(torch.float64)
        residual = y_target.to(torch.float64) - u0 @ a.T
        return (u0 + torch.cholesky_solve(a.T @ residual.T, factor).T).to(y_target.dtype)
