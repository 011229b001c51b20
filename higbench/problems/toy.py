"""Ill-conditioned toy example (paper section 2.1, appendix B.1).

Fit yhat(x) = (sin 6x, cos 9x) with a 1 -> 7 (tanh) -> 2 network under the loss
1/2 (y1 - yhat1)^2 + 1/2 (gamma*y2 - yhat2)^2. The "physics" is the scaling by gamma:
y = P(x, u) = (u1, gamma*u2), so the Jacobian sees the ill-conditioning.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from higbench.problems.base import Batch, FixedDataConfig, FixedDataProblem, register
from higbench.problems.networks import mlp
from higbench.schema import value


def target_function(x: torch.Tensor) -> torch.Tensor:
    """yhat(x) = (sin 6x, cos 9x) for x (b, 1) -> (b, 2)."""
    return torch.cat([torch.sin(6 * x), torch.cos(9 * x)], dim=1)


@register("toy")
class Toy(FixedDataProblem):
    @dataclass
    class Config(FixedDataConfig):
        gamma: float = value(gt=0)  # 1: well conditioned, 0.01: ill conditioned
        hidden: int = value(ge=1)
        probe_x: float = value()

    def __init__(self, cfg, dtype, device, seed):
        super().__init__(cfg, dtype, device, seed)
        self.sample_datasets()
        self.probe = torch.tensor([[float(cfg.probe_x)]], dtype=dtype, device=device)

    def _sample(self, n: int, gen: torch.Generator) -> Batch:
        x = (2 * torch.rand(n, 1, generator=gen, dtype=torch.float64) - 1).to(self.device, self.dtype)
        return Batch(net_inputs=x, inputs=x, targets=target_function(x))

    def make_model(self) -> nn.Module:
        return mlp([1, int(self.cfg.hidden), 2], activation="tanh")

    def physics(self, inputs: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        return torch.stack([u[:, 0], self.cfg.gamma * u[:, 1]], dim=1)

    def inverse_simulator(self, inputs: torch.Tensor, y_target: torch.Tensor, u0: torch.Tensor) -> torch.Tensor:
        """Exact: u = (y1, y2 / gamma)."""
        return torch.stack([y_target[:, 0], y_target[:, 1] / self.cfg.gamma], dim=1)

    def loss(self, y: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        return 0.5 * ((y - targets) ** 2).sum(dim=1)

    @torch.no_grad()
    def eval_logs(self, model: nn.Module) -> dict[str, np.ndarray]:
        """Neuron saturation on the validation inputs and the probe sample's trajectory."""
        hidden = model[:2](self.test.net_inputs)  # tanh activations (n, hidden)
        probe_y = self.physics(self.probe, model(self.probe))[0]
        return {
            "neuron_mean": hidden.mean(0).cpu().double().numpy(),
            "neuron_std": hidden.std(0).cpu().double().numpy(),
            "probe_output": probe_y.cpu().double().numpy(),
            "probe_target": target_function(self.probe)[0].cpu().double().numpy(),
        }
