"""The objective's one reduction rule, shared by the problems (their loss) and the optimizers
(the closure they differentiate): neither package knows the other."""

from __future__ import annotations

import torch

LOSS_REDUCTIONS = ("mean", "sum")


def reduce_loss(per_sample: torch.Tensor, reduction: str = "mean") -> torch.Tensor:
    """The objective: the batch mean (default) or the batch sum of the per-sample losses.

    The sum scales the gradient by b (the convention of the reference's Poisson script).
    A scalar ``per_sample`` is returned as it is.
    """
    if reduction not in LOSS_REDUCTIONS:
        raise ValueError(f"loss_reduction={reduction!r}: expected one of {LOSS_REDUCTIONS}")
    if per_sample.ndim == 0:
        return per_sample
    return per_sample.sum() if reduction == "sum" else per_sample.mean()
