"""The Jacobian-power inversion against a plain NumPy float64 SVD, and Gram vs SVD routes."""

import numpy as np
import pytest
import torch

from higbench.optim import gram_coefficients, jacobian_power


def random_jacobian(rows, cols, rng, smin=1e-8, smax=1.0):
    """J = U diag(s) V^T with singular values log-spaced in [smin, smax]."""
    k = min(rows, cols)
    U, _ = np.linalg.qr(rng.standard_normal((rows, k)))
    V, _ = np.linalg.qr(rng.standard_normal((cols, k)))
    s = np.logspace(np.log10(smax), np.log10(smin), k)
    return (U * s) @ V.T


def numpy_reference(J, g, kappa, beta, tau, truncation):
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    cutoff = tau * s.max() if truncation == "relative" else tau
    keep = s >= cutoff
    powered = np.zeros_like(s)
    powered[keep] = s[keep] ** kappa
    return s.max() ** beta * (Vt.T @ (powered * (U.T @ g)))


SHAPES = [(12, 40), (40, 12), (30, 30), (2, 7)]  # wide (batch*|y| < |theta|), tall, square, tiny


@pytest.mark.parametrize("rows,cols", SHAPES)
@pytest.mark.parametrize("kappa", [-1.0, -0.5, 0.0, 0.5, 1.0])
@pytest.mark.parametrize("beta", [0.0, -0.5])
@pytest.mark.parametrize("tau", [0.0, 1e-6, 1e-3])
@pytest.mark.parametrize("truncation", ["relative", "absolute"])
def test_jacobian_power_matches_numpy_svd(rows, cols, kappa, beta, tau, truncation):
    rng = np.random.default_rng(rows * 1000 + cols)
    J = random_jacobian(rows, cols, rng)
    g = rng.standard_normal(rows)
    expected = numpy_reference(J, g, kappa, beta, tau, truncation)
    got = jacobian_power(torch.from_numpy(J), torch.from_numpy(g), kappa, beta=beta, tau=tau, truncation=truncation).numpy()
    scale = np.linalg.norm(expected)
    assert got.shape == (cols,)
    # Backward-stable SVDs agree up to eps * cond of the kept spectrum (1/smin at tau = 0).
    smin_kept = max(tau if truncation == "absolute" else tau * 1.0, 1e-8)
    assert np.linalg.norm(got - expected) <= max(1e-10, 100 * np.finfo(float).eps / smin_kept) * scale


def test_truncated_values_are_dropped_not_clamped():
    # Singular values 1 and 1e-3, tau = 1e-2: the second direction must vanish entirely.
    J = torch.diag(torch.tensor([1.0, 1e-3], dtype=torch.float64))
    g = torch.tensor([1.0, 1.0], dtype=torch.float64)
    d = jacobian_power(J, g, kappa=-0.5, tau=1e-2)
    assert torch.allclose(d, torch.tensor([1.0, 0.0], dtype=torch.float64))
    # Without truncation, the small direction is amplified by (1e-3)^-1/2.
    d = jacobian_power(J, g, kappa=-0.5, tau=0.0)
    assert torch.allclose(d, torch.tensor([1.0, 1e-3**-0.5], dtype=torch.float64))


@pytest.mark.parametrize("kappa", [-1.0, -0.5, 1.0])
@pytest.mark.parametrize("tau", [1e-6, 1e-5, 1e-4, 1e-2])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gram_route_matches_svd_route(kappa, tau, seed):
    """Gram (eigh of J J^T) agrees with the SVD of J up to its precision limit eps/tau^2.

    eigh is backward stable: eigenvalues err by ~eps*max(s)^2, so a kept singular value
    s >= tau*max(s) errs relatively by <= eps/tau^2 (2e-4 at tau=1e-6). The spectrum spans
    1e-8..1 with no value within a factor 2 of the cutoff (where keep/drop would flip).
    """
    rng = np.random.default_rng(seed)
    rows, cols = 24, 80
    J = random_jacobian(rows, cols, rng)
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    s = np.where(np.abs(np.log10(s / tau)) < 0.3, s * 4, s)  # keep clear of the cutoff
    J = torch.from_numpy((U * s) @ Vt)
    g = torch.from_numpy(rng.standard_normal(rows))
    svd = jacobian_power(J, g, kappa, tau=tau)
    gram = J.T @ gram_coefficients(J @ J.T, g, kappa, tau=tau)
    tolerance = max(1e-9, 10 * np.finfo(float).eps / tau**2)
    assert torch.linalg.norm(gram - svd) <= tolerance * torch.linalg.norm(svd)


def test_hig_is_between_gd_and_gn_on_scales():
    # Table 1 / eq. 17: with y-space change dy = J dtheta, HIG's dy = -J^{1/2} g, i.e. the
    # y-space step along singular direction i is s_i^(1/2) times the gradient component.
    rng = np.random.default_rng(3)
    J = torch.from_numpy(random_jacobian(6, 20, rng, smin=1e-2))
    g = torch.from_numpy(rng.standard_normal(6))
    U, s, _ = torch.linalg.svd(J, full_matrices=False)
    for kappa in (-1.0, -0.5, 1.0):
        dy = J @ jacobian_power(J, g, kappa, tau=0.0)
        assert torch.allclose(U.T @ dy, s ** (kappa + 1) * (U.T @ g), rtol=1e-8, atol=1e-12)
