"""Physics of the Poisson problem: the 5-point Dirichlet Laplacian and the random potentials."""

import math

import numpy as np
import pytest
import scipy.sparse as sp
import torch

from higbench.physics.poisson import laplace, laplace_matrix, sample_potential

F64 = torch.float64


def scipy_laplacian(n, m):
    """5-point Dirichlet Laplacian on row-major flattened (n, m) grids, spacing 1."""

    def second_difference(k):
        return sp.diags([np.ones(k - 1), -2.0 * np.ones(k), np.ones(k - 1)], [-1, 0, 1])

    return (sp.kron(second_difference(n), sp.identity(m)) + sp.kron(sp.identity(n), second_difference(m))).tocsr()


@pytest.mark.parametrize("shape", [(8, 8), (5, 7)])
def test_laplace_matches_scipy_sparse_matrix(shape):
    phi = torch.randn(6, *shape, generator=torch.Generator().manual_seed(0), dtype=F64)
    expected = (scipy_laplacian(*shape) @ phi.reshape(6, -1).numpy().T).T.reshape(6, *shape)
    np.testing.assert_allclose(laplace(phi).numpy(), expected, atol=1e-13, rtol=0)
    np.testing.assert_allclose(laplace_matrix(*shape).numpy(), scipy_laplacian(*shape).toarray(), atol=0, rtol=0)


@pytest.mark.parametrize("p,q", [(1, 1), (2, 3), (8, 5)])
def test_discrete_eigenfunctions(p, q):
    # sin(p pi (i+1)/9) sin(q pi (j+1)/9) vanishes at i, j = -1 and 8 (the Dirichlet ring),
    # with eigenvalue 2 cos(p pi/9) - 2 + 2 cos(q pi/9) - 2 of the discrete Laplacian.
    i = torch.arange(8, dtype=F64)
    phi = torch.outer(torch.sin(p * math.pi * (i + 1) / 9), torch.sin(q * math.pi * (i + 1) / 9))
    lam = 2 * math.cos(p * math.pi / 9) - 2 + 2 * math.cos(q * math.pi / 9) - 2
    torch.testing.assert_close(laplace(phi[None])[0], lam * phi, atol=1e-14, rtol=0)


def test_quadratic_is_exact_in_the_interior():
    i = torch.arange(8, dtype=F64)
    phi = 0.5 * i[:, None] ** 2 + 1.5 * i[None, :] ** 2 - 3.0 * i[:, None] + 2.0  # Laplacian 1 + 3 = 4
    out = laplace(phi[None])[0]
    torch.testing.assert_close(out[1:-1, 1:-1], torch.full((6, 6), 4.0, dtype=F64), atol=1e-12, rtol=0)


def test_laplace_matrix_properties():
    L = laplace_matrix()
    phi = torch.randn(3, 8, 8, generator=torch.Generator().manual_seed(1), dtype=F64)
    torch.testing.assert_close(laplace(phi).reshape(3, -1), phi.reshape(3, -1) @ L.T)
    torch.testing.assert_close(L, L.T, atol=0, rtol=0)
    eig = torch.linalg.eigvalsh(L)
    lam = torch.tensor([2 * math.cos(p * math.pi / 9) - 2 for p in range(1, 9)], dtype=F64)
    torch.testing.assert_close(eig, (lam[:, None] + lam[None, :]).reshape(-1).sort().values)
    assert eig.max() < 0  # negative definite: the Poisson problem has a unique solution


def test_laplace_any_leading_dims_and_dtype():
    phi = torch.randn(2, 3, 8, 8)
    out = laplace(phi)
    assert out.shape == phi.shape and out.dtype == torch.float32
    torch.testing.assert_close(out[1, 2], laplace(phi[1, 2][None])[0])


def test_laplace_per_sample_jacobian_is_the_matrix():
    phi = torch.randn(2, 8, 8, dtype=F64)
    jac = torch.func.vmap(torch.func.jacrev(lambda x: laplace(x[None]).reshape(-1)))(phi)
    torch.testing.assert_close(jac.reshape(2, 64, 64), laplace_matrix().expand(2, 64, 64))


def test_sample_potential_reproducible_and_zero_mean():
    a = sample_potential(16, torch.Generator().manual_seed(3))
    b = sample_potential(16, torch.Generator().manual_seed(3))
    c = sample_potential(16, torch.Generator().manual_seed(4))
    assert a.shape == (16, 8, 8) and a.dtype == torch.float32
    torch.testing.assert_close(a, b, atol=0, rtol=0)
    assert not torch.allclose(a, c)
    torch.testing.assert_close(a.mean(dim=(-2, -1)), torch.zeros(16), atol=1e-6, rtol=0)
    d = sample_potential(16, torch.Generator().manual_seed(3), dtype=F64)
    assert d.dtype == F64
    torch.testing.assert_close(d.float(), a, atol=0, rtol=0)  # same draws in every dtype


def test_sample_potential_spectrum():
    phi = sample_potential(4096, torch.Generator().manual_seed(5), dtype=F64)
    power = torch.fft.fft2(phi).abs().square().mean(0) / 64  # mean |DFT|^2, (8, 8)
    k = torch.fft.fftfreq(8, d=1 / 8).abs()  # |integer frequency|
    inside = (k[:, None] <= 3) & (k[None, :] <= 3)
    inside[0, 0] = False
    # Only |k1|, |k2| <= 3 carry power, and no mean.
    assert power[~inside].max() < 1e-20
    # Re(c_k e^{..}) puts power (|c_k|^2 + |c_{-k}|^2) / 4 * 64 on k: E = 64 * amp^2.
    amp2 = 1.0 / (1.0 + k[:, None] ** 2 + k[None, :] ** 2) ** 2
    ratio = power[inside] / (64 * amp2[inside])
    assert (ratio - 1.0).abs().max() < 0.15  # 4096 samples: a few % sampling error
    assert 1.0 < phi.std().item() < 2.0  # pointwise std ~ 1.4, as documented


# --- the authors' data: PhiFlow's Noise (phiflow is a dev dependency, imported here only) ---


def phiflow_noise(batch: int, seed: int) -> np.ndarray:
    """The reference script's potentials: CenteredGrid(Noise(batch), ZERO, x=8, y=8)."""
    from phi import flow

    flow.math.seed(seed)
    grid = flow.CenteredGrid(flow.Noise(flow.batch(batch=batch)), flow.extrapolation.ZERO, x=8, y=8)
    return grid.values.numpy("batch,x,y").astype(np.float64)


def mean_power(phi: np.ndarray) -> np.ndarray:
    return (np.abs(np.fft.fft2(phi)) ** 2).mean(axis=0)


def test_noise_potentials_have_phiflows_spectrum_and_moments():
    ours = sample_potential(8192, torch.Generator().manual_seed(0), dtype=F64, data="phiflow_noise").numpy()
    theirs = phiflow_noise(8192, seed=0)
    for phi in (ours, theirs):  # normalised per sample
        np.testing.assert_allclose(phi.mean(axis=(1, 2)), 0, atol=1e-6)
        np.testing.assert_allclose(phi.std(axis=(1, 2)), 1, atol=1e-6)
    p_ours, p_theirs = mean_power(ours), mean_power(theirs)
    assert p_ours[0, 0] < 1e-9 and p_theirs[0, 0] < 1e-9
    nonzero = np.ones((8, 8), bool)
    nonzero[0, 0] = False
    np.testing.assert_allclose(p_ours[nonzero], p_theirs[nonzero], rtol=0.1)
    # pointwise moments: variance 1 everywhere (periodic noise), same kurtosis
    np.testing.assert_allclose(ours.var(axis=0), theirs.var(axis=0), rtol=0.1)
    kurt = [float(((p**4).mean(axis=0) / (p**2).mean(axis=0) ** 2).mean()) for p in (ours, theirs)]
    assert abs(kurt[0] - kurt[1]) < 0.1


def test_fourier_potentials_differ_from_phiflows_noise():
    """The test above can fail: higbench's default data have another spectrum."""
    fourier = sample_potential(8192, torch.Generator().manual_seed(0), dtype=F64, data="fourier").numpy()
    fourier = fourier / fourier.std(axis=(1, 2), keepdims=True)
    ratio = mean_power(fourier)[1:, 1:] / mean_power(phiflow_noise(8192, seed=1))[1:, 1:]
    assert ratio.max() / ratio.min() > 3


def test_laplace_matches_phiflows_zero_extrapolation_laplace():
    from phi import flow

    phi = phiflow_noise(4, seed=2)
    grid = flow.CenteredGrid(flow.math.tensor(phi, flow.batch("batch"), flow.spatial("x,y")), flow.extrapolation.ZERO)
    expected = flow.field.laplace(grid).values.numpy("batch,x,y")
    np.testing.assert_allclose(laplace(torch.tensor(phi)).numpy(), expected, atol=1e-5)


def test_unknown_data_choice_names_the_key():
    with pytest.raises(ValueError, match="data=bogus"):
        sample_potential(2, data="bogus")
