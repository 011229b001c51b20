"""Compile before the clock: the fast solvers (numba) compile, or load their on-disk cache, on
first use, which took 3.8 s of a 10 s dipole budget inside the first update.

``warm_up`` runs the problem's solver once on two test samples, forward, reverse (what a
first-order optimizer's backward pass calls) and, for the Jacobian-power family, the batched
solver Jacobian, through the run's own network, under a forked RNG, leaving no gradient
behind (the run's weights, initialisation and data order stay exactly as without it). The
seconds it took are recorded apart, as the run file's ``/env`` attribute ``warmup_s``.
"""

from __future__ import annotations

import time

import torch

from higbench.optim.structured import solver_jacobian
from higbench.problems.base import Problem


def warm_up(problem: Problem, model: torch.nn.Module, jacobian: bool) -> float:
    """Seconds spent calling the solver once each way on a tiny batch (nothing else changes)."""
    t0 = time.perf_counter()
    with torch.random.fork_rng(devices=[]):
        batch = problem.test_set()[:2]
        with torch.enable_grad():
            loss = problem.loss(problem.outputs(model, batch), batch.targets).sum()
            if loss.requires_grad:
                loss.backward()
        if jacobian and type(problem).outputs is Problem.outputs:
            with torch.no_grad():
                u = model(batch.net_inputs)
            solver_jacobian(problem.physics, batch.inputs, u, "batched", problem.physics_jacobian)  # its adjoint, where declared
    model.zero_grad(set_to_none=True)  # the run's first update starts from no gradient, as without it
    return time.perf_counter() - t0
