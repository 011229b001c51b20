"""Stacked per-sample Jacobians J = d y_i / d theta of network + physics, shape (b*|y|, |theta|).

``per_sample_jacobian`` is the torch.func route: vmap over samples of jacrev of
theta -> P(x_i, f(z_i; theta)). It uses per-sample independence (never a Jacobian of the
whole batch w.r.t. the whole batch) and works for any problem whose physics is written with
batched torch ops. ``full_jacobian`` differentiates the whole batch output w.r.t. theta
with no structure at all: the brute-force ground truth used in tests.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import nn
from torch.func import functional_call, jacrev, vmap

PhysicsFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


def trainable_params(model: nn.Module) -> dict[str, torch.Tensor]:
    return {name: p for name, p in model.named_parameters() if p.requires_grad}


def flatten_rows(jac: dict[str, torch.Tensor], rows: int) -> torch.Tensor:
    """Concatenate a {name: (rows..., *param_shape)} Jacobian dict into (rows, |theta|)."""
    return torch.cat([j.reshape(rows, -1) for j in jac.values()], dim=1)


def per_sample_jacobian(model: nn.Module, physics: PhysicsFn, inputs: torch.Tensor, net_inputs: torch.Tensor) -> torch.Tensor:
    """J of y_i = physics(inputs_i, model(net_inputs_i)) w.r.t. the model's parameters.

    inputs, net_inputs: (b, ...). Returns (b * |y|, |theta|), rows ordered sample-major,
    parameter columns in ``named_parameters`` order (the order of ``flat_params``).
    """
    params = {k: v.detach() for k, v in trainable_params(model).items()}

    def y_single(p, x, z):
        u = functional_call(model, p, (z.unsqueeze(0),))
        return physics(x.unsqueeze(0), u).reshape(-1)

    jac = vmap(jacrev(y_single), in_dims=(None, 0, 0))(params, inputs, net_inputs)
    b, m = net_inputs.shape[0], next(iter(jac.values())).shape[1]
    return flatten_rows(jac, b * m)


def full_jacobian(model: nn.Module, physics: PhysicsFn, inputs: torch.Tensor, net_inputs: torch.Tensor) -> torch.Tensor:
    """Brute force: Jacobian of the whole flattened batch output (reference for tests)."""
    params = {k: v.detach() for k, v in trainable_params(model).items()}

    def y_all(p):
        return physics(inputs, functional_call(model, p, (net_inputs,))).reshape(-1)

    jac = jacrev(y_all)(params)
    rows = next(iter(jac.values())).shape[0]
    return flatten_rows(jac, rows)
