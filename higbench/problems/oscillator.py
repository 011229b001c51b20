"""Control of two coupled nonlinear oscillators (paper 3.1, appendix B.2).

The network sees the target state (= the initial state) and outputs one control value u
per RK4 step; the physics integrates the chain from that initial state, and the loss is
the squared distance of the final state to the target (sum over the 4 components).
The solver is ``higbench.physics.oscillator.simulate`` (the reference, re-exported here) or,
with ``problem.solver=fast`` (the default), ``higbench.physics.oscillator_fast.simulate``:
the same RK4 scheme compiled, with its hand-derived adjoint, and a direct route for the
structured path's solver Jacobians (``physics_jacobian``). On a GPU the compiled loop runs on the host.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from higbench.physics import oscillator_fast
from higbench.physics._adjoint import available
from higbench.physics.oscillator import energy, simulate
from higbench.problems.base import PHYSICS_SOLVERS, Batch, FixedDataConfig, FixedDataProblem, register
from higbench.problems.networks import ACTIVATIONS, mlp
from higbench.schema import value

__all__ = ["simulate", "energy", "Oscillator"]


@register("oscillator")
class Oscillator(FixedDataProblem):
    @dataclass
    class Config(FixedDataConfig):
        dt: float = value(gt=0)
        steps: int = value(ge=1)  # RK4 steps = network outputs
        coupling: float = value()
        control: list[float] = value(length=2)
        hidden: list[int] = value(ge=1)
        activation: str = value(choices=tuple(ACTIVATIONS))
        solver: str = value("fast", choices=PHYSICS_SOLVERS)

    def __init__(self, cfg, dtype, device, seed):
        super().__init__(cfg, dtype, device, seed)
        self.sample_datasets()

    def _sample(self, n: int, gen: torch.Generator) -> Batch:
        # Initial states uniform in [0, 1)^4; the target is the initial state itself.
        x0 = torch.rand(n, 4, generator=gen, dtype=torch.float64).to(self.device, self.dtype)
        return Batch(net_inputs=x0, inputs=x0, targets=x0)

    def make_model(self) -> nn.Module:
        return mlp([4, *self.cfg.hidden, int(self.cfg.steps)], activation=self.cfg.activation)

    @property
    def fast(self) -> bool:
        return self.cfg.get("solver", "fast") == "fast"

    def physics(self, inputs: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        solve = oscillator_fast.simulate if self.fast else simulate
        return solve(inputs, u, dt=self.cfg.dt, coupling=self.cfg.coupling, control=tuple(self.cfg.control))

    def physics_jacobian(self, inputs: torch.Tensor, u: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor] | None:
        """y (b, 4) and A_i = dy_i/du_i (b, 4, steps) from one adjoint sweep (None: use autograd)."""
        if not (self.fast and available(inputs, u)):
            return None
        return oscillator_fast.solver_jacobian(
            inputs, u, dt=self.cfg.dt, coupling=self.cfg.coupling, control=tuple(self.cfg.control)
        )

    def loss(self, y: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        return ((y - targets) ** 2).sum(dim=1)

    def trajectory(self, model: nn.Module, batch: Batch) -> tuple[torch.Tensor, torch.Tensor]:
        """States (b, steps+1, 4) and controls (b, steps) under the network (figure 2a)."""
        with torch.no_grad():
            u = model(batch.net_inputs)
            solve = oscillator_fast.simulate if self.fast else simulate
            states = solve(
                batch.inputs,
                u,
                dt=self.cfg.dt,
                coupling=self.cfg.coupling,
                control=tuple(self.cfg.control),
                return_trajectory=True,
            )
        return states, u
