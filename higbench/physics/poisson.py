"""Discrete Poisson problem on an 8x8 grid (spacing 1, phi = 0 outside the grid).

``laplace`` is the 5-point stencil with zero Dirichlet values beyond the grid;
``laplace_matrix`` is the same operator as a dense matrix on row-major flattened grids;
``sample_potential`` draws the smooth random potentials of the data set (rho = laplace(phi)):
band-limited Fourier fields (``fourier``, higbench's default) or the power-law noise of the
authors' Poisson script (``phiflow_noise``, ``sample_noise_potential``).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

N = 8
MODES = 3
DATA = ("fourier", "phiflow_noise")  # problem.data


def laplace(phi: torch.Tensor) -> torch.Tensor:
    """5-point Laplacian, spacing 1, zero values outside the grid. phi (..., n, m) -> (..., n, m).

    out[i, j] = phi[i-1, j] + phi[i+1, j] + phi[i, j-1] + phi[i, j+1] - 4 phi[i, j].
    """
    p = F.pad(phi, (1, 1, 1, 1))  # zero ring = Dirichlet boundary
    neighbours = p[..., :-2, 1:-1] + p[..., 2:, 1:-1] + p[..., 1:-1, :-2] + p[..., 1:-1, 2:]
    return torch.sub(neighbours, phi, alpha=4.0)


def _second_difference(n: int, dtype: torch.dtype) -> torch.Tensor:
    return (
        torch.diag(torch.full((n,), -2.0, dtype=dtype))
        + torch.diag(torch.ones(n - 1, dtype=dtype), 1)
        + torch.diag(torch.ones(n - 1, dtype=dtype), -1)
    )


def laplace_matrix(n: int = N, m: int = N, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """Dense (n*m, n*m) matrix L with laplace(phi).reshape(-1) == L @ phi.reshape(-1) (row-major)."""
    return torch.kron(_second_difference(n, dtype), torch.eye(m, dtype=dtype)) + torch.kron(
        torch.eye(n, dtype=dtype), _second_difference(m, dtype)
    )


def sample_potential(
    batch: int,
    generator: torch.Generator | None = None,
    n: int = N,
    modes: int = MODES,
    dtype: torch.dtype = torch.float32,
    data: str = "fourier",
) -> torch.Tensor:
    """Potentials phi (batch, n, n) of the chosen data distribution (``DATA``)."""
    if data == "phiflow_noise":
        return sample_noise_potential(batch, generator, n=n, dtype=dtype)
    if data != "fourier":
        raise ValueError(f"data={data}: must be one of {', '.join(DATA)}")
    return sample_fourier_potential(batch, generator, n=n, modes=modes, dtype=dtype)


def sample_fourier_potential(
    batch: int,
    generator: torch.Generator | None = None,
    n: int = N,
    modes: int = MODES,
    dtype: torch.dtype = torch.float32,
) -> torch.Tensor:
    """Smooth random potentials phi, (batch, n, n), zero mean over each grid.

    Spectrum: for every integer frequency pair k = (k1, k2) with |k1|, |k2| <= ``modes`` and
    k != 0, an independent complex coefficient c_k = (a_k + i b_k) / (1 + k1^2 + k2^2) with
    a_k, b_k ~ N(0, 1). The field is the real part of the inverse DFT without 1/n^2 factor,

        phi[j1, j2] = Re sum_k c_k exp(2 pi i (k1 j1 + k2 j2) / n),   j1, j2 = 0 .. n-1,

    minus its grid mean (zero up to rounding, as k = 0 is excluded; needs n > 2 * modes so
    no frequency aliases onto k = 0). Pointwise std is about 1.4 for modes = 3.
    Draws in float64 on the CPU and casts, so a seed gives the same fields in every dtype.
    """
    if n <= 2 * modes:
        raise ValueError(f"n={n} must exceed 2*modes={2 * modes}")
    k = torch.arange(-modes, modes + 1, dtype=torch.float64)
    k2 = k[:, None] ** 2 + k[None, :] ** 2
    amp = 1.0 / (1.0 + k2)
    amp[modes, modes] = 0.0  # drop the mean mode
    shape = (batch, 2 * modes + 1, 2 * modes + 1)
    re = torch.randn(shape, generator=generator, dtype=torch.float64)
    im = torch.randn(shape, generator=generator, dtype=torch.float64)
    coeff = torch.complex(re * amp, im * amp)
    j = torch.arange(n, dtype=torch.float64)
    basis = torch.exp(1j * (2 * math.pi / n) * j[:, None] * k[None, :])  # (n, 2*modes+1)
    phi = (basis @ coeff @ basis.T).real
    phi = phi - phi.mean(dim=(-2, -1), keepdim=True)
    return phi.to(dtype)


def sample_noise_potential(
    batch: int,
    generator: torch.Generator | None = None,
    n: int = N,
    smoothness: float = 1.0,
    scale: float = 10.0,
    dtype: torch.dtype = torch.float32,
) -> torch.Tensor:
    """Power-law noise potentials, (batch, n, n): the distribution of PhiFlow's ``Noise()``
    sampled on an n x n ``CenteredGrid`` of spacing 1 (the authors' Poisson data).

    Every DFT coefficient c_k (all n x n frequencies, Nyquist included) is (a_k + i b_k) / |k|^(2 s)
    with a_k, b_k ~ N(0, 1), k = scale * fftfreq(n) per axis and s = ``smoothness``; |k|^2 <= 0.1
    (only k = 0 here) is dropped. phi = Re(inverse DFT), then divided by its grid standard
    deviation and shifted to zero grid mean: every sample has mean 0 and std 1. ``scale``
    enters only through that cut-off (a common factor of 1/|k|^2 is normalised away): any
    scale > sqrt(0.1) n keeps every k != 0, so PhiFlow's default 10 on an 8x8 grid does.
    Draws in float64 on the CPU and casts, so a seed gives the same fields in every dtype.
    """
    f = torch.fft.fftfreq(n, dtype=torch.float64) * scale
    k2 = f[:, None] ** 2 + f[None, :] ** 2
    amp = torch.where(k2 > 0.1, 1.0 / k2.clamp_min(1e-300), torch.zeros_like(k2)) ** smoothness
    re = torch.randn((batch, n, n), generator=generator, dtype=torch.float64)
    im = torch.randn((batch, n, n), generator=generator, dtype=torch.float64)
    phi = torch.fft.ifft2(torch.complex(re, im) * amp).real
    phi = phi / phi.std(dim=(-2, -1), correction=0, keepdim=True)
    phi = phi - phi.mean(dim=(-2, -1), keepdim=True)
    return phi.to(dtype)
