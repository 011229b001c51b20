"""Networks of the paper's problems and their initialisation.

Initialisation follows the reference code (Keras defaults): Glorot-uniform weights and
zero biases. PyTorch's own default (Kaiming-uniform with fan-in biases) is available as
``init: torch``; it changes the toy curves noticeably.
"""

from __future__ import annotations

from torch import nn

ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU}
INIT_SCHEMES = ("glorot", "torch")


def mlp(sizes: list[int], activation: str) -> nn.Sequential:
    """Dense network sizes[0] -> ... -> sizes[-1]; activation on hidden layers, linear output."""
    if activation not in ACTIVATIONS:
        raise ValueError(f"activation={activation!r}: expected one of {tuple(ACTIVATIONS)}")
    layers: list[nn.Module] = []
    for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        layers.append(nn.Linear(n_in, n_out))
        if i < len(sizes) - 2:
            layers.append(ACTIVATIONS[activation]())
    return nn.Sequential(*layers)


def initialise(model: nn.Module, scheme: str) -> nn.Module:
    if scheme not in INIT_SCHEMES:
        raise ValueError(f"init={scheme!r}: expected one of {INIT_SCHEMES}")
    if scheme == "glorot":
        for m in model.modules():
            if isinstance(m, (nn.Linear, nn.Conv1d)):
                nn.init.xavier_uniform_(m.weight)
                nn.init.zeros_(m.bias)
    return model


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
