"""Shared plumbing of the fast solvers: a compiled time loop with its hand-derived adjoint.

A fast solver is two compiled kernels (``forward``: all states of the time loop, no autograd
graph; ``adjoint``: the discrete adjoint recursion for any number of cotangent seeds per
sample at once) wrapped in ``torch.autograd.Function`` s written in the torch.func-compatible
style (``setup_context`` + ``vmap`` static methods), so that

* plain ``backward`` / ``torch.autograd.grad`` run one adjoint sweep;
* ``torch.func.vmap`` / ``jacrev`` / ``vjp`` work: the samples of a vmapped call are folded
  into the solver's batch (samples are independent), and a vmapped backward (the cotangents
  of ``jacrev``) becomes several seeds of one adjoint sweep;
* the structured HIG/GN path gets every solver Jacobian A_i from one sweep with |y| seeds
  per sample (``solver_jacobian`` of the problem, see ``higbench.optim.structured``).

The kernels always compute in float64 (complex128): the result is cast back to the caller's
dtype, so a float32 run gets float32 outputs and gradients that are float64-accurate.

Only CPU tensors are handled here; the problems fall back to the reference torch solvers
on other devices (``higbench.problems``: ``problem.solver``).
"""

from __future__ import annotations

import os

import numpy as np
import torch

try:  # numba compiles the time loops; without it only the reference solvers are available.
    import numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - numba is a dependency; this keeps imports working
    numba = None
    HAVE_NUMBA = False


def njit(fn):
    """numba.njit with an on-disk cache (first use compiles, ~1-3 s; later processes load it)."""
    if not HAVE_NUMBA:
        return fn
    cache = os.environ.get("HIGBENCH_NUMBA_CACHE", "1") != "0"
    return numba.njit(cache=cache, nogil=True)(fn)


def available(*tensors: torch.Tensor) -> bool:
    """Whether the fast path can take these tensors (numba present, all on the CPU)."""
    return HAVE_NUMBA and all(t.device.type == "cpu" for t in tensors)


def as_numpy64(t: torch.Tensor) -> np.ndarray:
    """A C-contiguous float64 (or complex128) NumPy copy/view of a CPU tensor without graph."""
    t = t.detach()
    if t.is_complex():
        t = t.to(torch.complex128)
    else:
        t = t.to(torch.float64)
    return np.ascontiguousarray(t.numpy())


def batch_first(x: torch.Tensor | None, dim: int | None, size: int) -> torch.Tensor | None:
    """Move a vmapped dimension to the front (or expand an unbatched tensor to ``size``)."""
    if x is None:
        return None
    if dim is None:
        return x.unsqueeze(0).expand(size, *x.shape)
    return x.movedim(dim, 0)
