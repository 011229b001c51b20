"""Quantum dipole control (paper 3.3, appendix B.4).

Schroedinger equation i dPsi/dt = (-Laplace + u(t) x) Psi in an infinite well on [0, 2]
(14 interior points), Crank-Nicolson with dt = 0.05 for 384 steps. The network sees the
target state (real and imaginary parts, 28 values) and outputs one u per step; the physics
evolves the ground state under u. Targets are real superpositions a*phi_2 + b*phi_3.
Loss: 1 - |<Psi, Psi_target>|^2; extra curves: the low- and high-energy losses of
figure 4c. Solver: ``higbench.physics.dipole.simulate`` (the reference, re-exported here) or,
with ``problem.solver=fast`` (the default), ``higbench.physics.dipole_fast.simulate``: the
same scheme compiled, with its hand-derived adjoint and a direct route for the structured
path's solver Jacobians (``physics_jacobian``). On a GPU the compiled loop runs on the host.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from higbench.physics import dipole_fast
from higbench.physics._adjoint import available
from higbench.physics.dipole import N, eigenstate, energy_overlap_loss, fidelity_loss, simulate
from higbench.problems.base import PHYSICS_SOLVERS, Batch, FixedDataConfig, FixedDataProblem, register
from higbench.problems.networks import ACTIVATIONS, mlp
from higbench.schema import value

__all__ = ["simulate", "eigenstate", "Dipole", "DipoleCNN"]

MODELS = ("mlp", "cnn")


class DipoleCNN(nn.Module):
    """Six valid 1-D convolutions over the 14 points (14 -> 2), then dense 40 -> steps."""

    def __init__(self, channels: int = 20, layers: int = 6, kernel: int = 3, steps: int = 384, activation: str = "tanh"):
        super().__init__()
        convs: list[nn.Module] = []
        for i in range(layers):
            convs += [nn.Conv1d(2 if i == 0 else channels, channels, kernel), ACTIVATIONS[activation]()]
        self.convs = nn.Sequential(*convs)
        width = N - layers * (kernel - 1)
        if width < 1:
            raise ValueError(f"problem.cnn_layers={layers}: {layers} valid convolutions of kernel {kernel} do not fit 14 points")
        self.out = nn.Linear(channels * width, steps)

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        # z: (b, 28) laid out as (14, 2) -> channels (re, im) over the 14 points.
        h = self.convs(z.reshape(-1, N, 2).transpose(1, 2))
        return self.out(h.flatten(1))


@register("dipole")
class Dipole(FixedDataProblem):
    @dataclass
    class Config(FixedDataConfig):
        model: str = value(choices=MODELS)
        dt: float = value(gt=0)
        steps: int = value(ge=1)  # Crank-Nicolson steps = network outputs
        hidden: list[int] = value(ge=1)
        cnn_channels: int = value(ge=1)
        cnn_layers: int = value(ge=1, le=(N - 1) // 2)  # valid convolutions of kernel 3 leave >= 1 of the 14 points
        activation: str = value(choices=tuple(ACTIVATIONS))
        solver: str = value("fast", choices=PHYSICS_SOLVERS)

    def __init__(self, cfg, dtype, device, seed):
        super().__init__(cfg, dtype, device, seed)
        if cfg.model not in MODELS:
            raise ValueError(f"problem.model={cfg.model!r}: expected one of {MODELS}")
        self.psi0 = eigenstate(1, dtype=dtype, device=device)
        self.sample_datasets()  # after psi0: _sample builds the targets from it

    def _sample(self, n: int, gen: torch.Generator) -> Batch:
        ab = torch.randn(n, 2, generator=gen, dtype=torch.float64)
        ab = ab / ab.norm(dim=1, keepdim=True)
        target = ab[:, :1, None] * eigenstate(2) + ab[:, 1:, None] * eigenstate(3)  # (n, 14, 2)
        target = target.to(self.device, self.dtype)
        flat = target.reshape(n, -1)
        return Batch(net_inputs=flat, inputs=flat, targets=flat)

    def make_model(self) -> nn.Module:
        steps = int(self.cfg.steps)
        if self.cfg.model == "cnn":
            return DipoleCNN(int(self.cfg.cnn_channels), int(self.cfg.cnn_layers), 3, steps, self.cfg.activation)
        return mlp([2 * N, *self.cfg.hidden, steps], activation=self.cfg.activation)

    @property
    def fast(self) -> bool:
        return self.cfg.get("solver", "fast") == "fast"

    def physics(self, inputs: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        psi0 = self.psi0.expand(u.shape[0], N, 2)
        solve = dipole_fast.simulate if self.fast else simulate
        return solve(psi0, u, dt=self.cfg.dt).reshape(u.shape[0], -1)

    def physics_jacobian(self, inputs: torch.Tensor, u: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor] | None:
        """y (b, 28) and A_i = dy_i/du_i (b, 28, steps) from one adjoint sweep (None: use autograd)."""
        if not (self.fast and available(u)):
            return None
        return dipole_fast.solver_jacobian(self.psi0.expand(u.shape[0], N, 2), u, dt=self.cfg.dt)

    def loss(self, y: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        return fidelity_loss(y.reshape(-1, N, 2), targets.reshape(-1, N, 2))

    def metrics(self, y: torch.Tensor, batch: Batch) -> dict[str, torch.Tensor]:
        psi, target = y.reshape(-1, N, 2), batch.targets.reshape(-1, N, 2)
        return {
            "low_energy_loss": energy_overlap_loss(psi, target, 2),
            "high_energy_loss": energy_overlap_loss(psi, target, 3),
        }

    def trajectory(self, model: nn.Module, batch: Batch) -> tuple[torch.Tensor, torch.Tensor]:
        """States (b, steps+1, 14, 2) and controls (b, steps) under the network (figure 4a)."""
        with torch.no_grad():
            u = model(batch.net_inputs)
            solve = dipole_fast.simulate if self.fast else simulate
            states = solve(self.psi0.expand(u.shape[0], N, 2), u, dt=self.cfg.dt, return_trajectory=True)
        return states, u
