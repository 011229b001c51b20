"""Poisson problem (paper 3.2, appendix B.3): infer the potential phi from a source rho.

8x8 grid on [0, 8]^2, spacing 1, phi = 0 on all four sides, 5-point Laplacian. The
network maps rho (64) to phi (64); the physics applies the Laplacian to the predicted phi
and the loss is 1/2 ||Laplace(phi_pred) - rho||^2. Data are sampled on the fly: smooth
random potentials phi_gt (``higbench.physics.poisson.sample_potential``, spectrum in its
docstring) and rho = Laplace(phi_gt). Training batches are always fresh samples; the
curves use a fixed evaluation set drawn from a separate seeded stream (also unseen).

Two settings follow the authors' Poisson script rather than the paper's text (both keys):
the training objective is the batch *sum* of the per-sample losses
(``problem.loss_reduction: sum``; the other problems use the mean), and the reference
network [64, 128, 64] (24,896 parameters) is ``problem.hidden=[64,128,64]`` (default: the
paper's stated 41,408, [64, 256, 64]). The data: ``problem.data=fourier`` (default) draws the
band-limited Fourier fields of ``sample_fourier_potential``; ``problem.data=phiflow_noise``
draws the reference's PhiFlow ``Noise`` fields (power-law spectrum, std 1 per sample,
``sample_noise_potential``). ``conf/experiment/poisson_authors.yaml`` sets all of the
reference's choices at once.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import torch
from torch import nn

from higbench.physics.poisson import DATA, laplace, laplace_matrix, sample_potential
from higbench.problems.base import Batch, Problem, ProblemConfig, register
from higbench.problems.networks import ACTIVATIONS, mlp
from higbench.schema import value

__all__ = ["laplace", "laplace_matrix", "sample_potential", "Poisson"]


@register("poisson")
class Poisson(Problem):
    @dataclass
    class Config(ProblemConfig):
        grid: int = value(ge=2)
        modes: int = value(ge=1)  # fourier data only
        data: str = value("fourier", choices=DATA)
        epoch_size: int = value(ge=1)  # samples per "epoch" (data are sampled on the fly)
        hidden: list[int] = value(ge=1)
        activation: str = value(choices=tuple(ACTIVATIONS))

    def __init__(self, cfg, dtype, device, seed):
        super().__init__(cfg, dtype, device, seed)
        self.n = int(cfg.grid)
        # The evaluation sets come from data_seed (test first, then validation); training samples
        # from the run seed.
        gen = torch.Generator().manual_seed(int(cfg.data_seed))
        self.test = self._sample(int(cfg.test_size), gen)
        self.keep_later_draws(gen)  # the validation set next, when first asked for

    def _sample(self, n: int, gen: torch.Generator) -> Batch:
        phi = sample_potential(n, gen, n=self.n, modes=int(self.cfg.modes), dtype=torch.float64, data=str(self.cfg.data))
        rho = laplace(phi).reshape(n, -1).to(self.device, self.dtype)
        return Batch(net_inputs=rho, inputs=rho, targets=rho)

    def make_model(self) -> nn.Module:
        cells = self.n * self.n
        return mlp([cells, *self.cfg.hidden, cells], activation=self.cfg.activation)

    def physics(self, inputs: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        b = u.shape[0]
        return laplace(u.reshape(b, self.n, self.n)).reshape(b, -1)

    def inverse_simulator(self, inputs: torch.Tensor, y_target: torch.Tensor, u0: torch.Tensor) -> torch.Tensor:
        """Exact: the potential whose Laplacian is y_target, one linear Poisson solve (phi = 0 on
        the boundary, as ``physics``); -Laplace is symmetric positive definite: one Cholesky factor."""
        if getattr(self, "_neg_laplace_factor", None) is None:
            minus_l = -laplace_matrix(self.n, self.n, dtype=torch.float64)
            self._neg_laplace_factor = torch.linalg.cholesky(minus_l).to(self.device)
        rhs = -y_target.reshape(len(y_target), -1).to(torch.float64).T  # (n*n, b)
        return torch.cholesky_solve(rhs, self._neg_laplace_factor).T.to(y_target.dtype)

    def loss(self, y: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        return 0.5 * ((y - targets) ** 2).sum(dim=1)

    def train_size(self) -> None:
        return None  # infinite: sampled on the fly

    def epoch(self, batch_size: int, generator: torch.Generator) -> Iterator[Batch]:
        """``epoch_size`` fresh samples in batches (an epoch is a bookkeeping unit here)."""
        for _ in range(int(self.cfg.epoch_size) // batch_size):
            yield self._sample(batch_size, generator)

    def test_set(self) -> Batch:
        return self.test
