"""Differentiable, batched physics solvers (pure torch functions, no per-sample loops).

* ``oscillator``: two coupled nonlinear oscillators, classic RK4 (paper B.2).
* ``poisson``: 5-point Dirichlet Laplacian on a small grid and the random potentials (B.3).
* ``dipole``: 1-D Schroedinger equation in an infinite well, Crank-Nicolson (B.4).
* ``oscillator_fast``, ``dipole_fast``: the same two time loops compiled (numba) with their
  hand-derived adjoints, behind torch.autograd.Functions (``_adjoint``): the default
  ``problem.solver=fast``; the plain-torch modules above are the reference.
"""
