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

The kernels run on the host. Tensors of a run on another device (a GPU) are copied to the
host and the results back (``on_host``; autograd follows the copies): a time loop of a few
hundred tiny steps is thousands of kernel launches on a GPU, which measured 5-8x slower than
the compiled loop (docs/benchmarks.md, "On a GPU"). ``problem.solver=reference`` runs the torch
solver on the run's device instead.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from dataclasses import dataclass

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
    return numba.njit(cache=cache, nogil=True, error_model="numpy")(fn)


def available(*tensors: torch.Tensor) -> bool:
    """Whether the fast path can take these tensors: numba is present (tensors on any device
    are taken, through ``on_host``)."""
    return HAVE_NUMBA


HOST = torch.device("cpu")


def on_host(fn: Callable) -> Callable:
    """``fn`` (a fast solver's entry point) for tensor arguments on any device: they are copied
    to the host, ``fn`` runs there, and its tensor results are copied back to the device of the
    first argument. The copies are differentiable, so gradients reach the device's tensors."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        device = next((a.device for a in args if isinstance(a, torch.Tensor)), HOST)
        if device.type == HOST.type:
            return fn(*args, **kwargs)
        out = fn(*(a.to(HOST) if isinstance(a, torch.Tensor) else a for a in args), **kwargs)
        if isinstance(out, tuple):
            return tuple(o.to(device) for o in out)
        return out.to(device)

    return wrapper


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


@dataclass(frozen=True)
class Kernels:
    """A fast solver: ``forward(x0, u, params)`` -> all states (b, steps + 1, *state) float64;
    ``adjoint(traj, u, params, seeds, full)`` -> (dL/dx0 (m, b, *state), dL/du (m, b, steps))
    for m cotangents per sample, on the final state (m, b, *state) or, if ``full``, on every
    state (m, b, steps + 1, *state). ``batch_dim``: where the sample dimension of the
    kernels' trajectory is (its layout is theirs; ``states`` gives (b, steps + 1, *state))."""

    name: str
    forward: Callable
    adjoint: Callable
    batch_dim: int = 0

    def states(self, traj: torch.Tensor) -> torch.Tensor:
        return traj.movedim(self.batch_dim, 0)


def run(kernels: Kernels, x0: torch.Tensor, u: torch.Tensor, params: tuple, full: bool) -> torch.Tensor:
    """The final state (b, *state), or every state (b, steps + 1, *state) if ``full``, in x0's dtype, differentiable."""
    out, _ = _Simulate.apply(x0, u, kernels, params, full)
    return out


class _Simulate(torch.autograd.Function):
    """(x0, u) -> final state (or all states if ``full``), plus the float64 trajectory (saved, no gradient)."""

    @staticmethod
    def forward(x0, u, kernels, params, full):
        traj = kernels.forward(x0, u, params)
        states = kernels.states(traj)
        out = states if full else states[:, -1]
        return out.to(x0.dtype).clone(), traj

    @staticmethod
    def setup_context(ctx, inputs, output):
        x0, u, kernels, params, full = inputs
        ctx.kernels, ctx.params, ctx.full = kernels, params, full
        ctx.dtypes = (x0.dtype, u.dtype)
        ctx.mark_non_differentiable(output[1])
        ctx.save_for_backward(output[1], u)

    @staticmethod
    def backward(ctx, g_out, _g_traj):
        traj, u = ctx.saved_tensors
        gx, gu = _Adjoint.apply(g_out.unsqueeze(0), traj, u, ctx.kernels, ctx.params, ctx.full)
        return gx[0].to(ctx.dtypes[0]), gu[0].to(ctx.dtypes[1]), None, None, None

    @staticmethod
    def vmap(info, in_dims, x0, u, kernels, params, full):
        # Samples are independent: fold the vmapped dimension into the solver's batch.
        n = info.batch_size
        x0, u = batch_first(x0, in_dims[0], n), batch_first(u, in_dims[1], n)
        b = x0.shape[1]
        out, traj = _Simulate.apply(x0.reshape(n * b, *x0.shape[2:]), u.reshape(n * b, -1), kernels, params, full)
        bd = kernels.batch_dim
        return (out.reshape(n, b, *out.shape[1:]), traj.unflatten(bd, (n, b))), (0, bd)


class _Adjoint(torch.autograd.Function):
    """m cotangents per sample (m, b, ...) -> cotangents of x0 (m, b, *state) and u (m, b, steps), float64.

    Not differentiable again. Its vmap rule calls ``apply`` again (not the kernel), so nested
    transforms (vmap of jacrev) unwrap one level at a time.
    """

    @staticmethod
    def forward(seeds, traj, u, kernels, params, full):
        return kernels.adjoint(traj, u, params, seeds, full)

    @staticmethod
    def setup_context(ctx, inputs, output):
        ctx.name = inputs[3].name

    @staticmethod
    def backward(ctx, *grads):
        raise RuntimeError(f"the fast {ctx.name} solver has no second derivative: use problem.solver=reference")

    @staticmethod
    def vmap(info, in_dims, seeds, traj, u, kernels, params, full):
        n = info.batch_size
        s = batch_first(seeds, in_dims[0], n)  # (n, m, b, ...)
        m, b = s.shape[1], s.shape[2]
        if in_dims[1] is None and in_dims[2] is None:
            # More cotangents for the same trajectories (jacrev, is_grads_batched): more seeds.
            gx, gu = _Adjoint.apply(s.reshape(n * m, *s.shape[2:]), traj, u, kernels, params, full)
            return (gx.reshape(n, m, *gx.shape[1:]), gu.reshape(n, m, *gu.shape[1:])), (0, 0)
        # Different trajectories: fold the vmapped dimension into the batch.
        bd = kernels.batch_dim
        traj = batch_first(traj, in_dims[1], n).movedim(0, bd).flatten(bd, bd + 1)
        u = batch_first(u, in_dims[2], n)
        s = s.transpose(0, 1).reshape(m, n * b, *s.shape[3:])
        gx, gu = _Adjoint.apply(s, traj, u.reshape(n * b, -1), kernels, params, full)
        return (gx.reshape(m, n, b, *gx.shape[2:]), gu.reshape(m, n, b, -1)), (1, 1)
