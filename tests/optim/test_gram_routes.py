"""Gram-route eigen-solvers: eigh vs the tridiagonal reduction (reflectors applied to g only)."""

import numpy as np
import pytest
import torch

from higbench.optim import HIG, gram_coefficients, jacobian_power
from higbench.optim import tridiagonal as tri
from higbench.optim.inversion import TRIDIAGONAL_MIN_ROWS, resolved_eigen_method

pytestmark = pytest.mark.skipif(not tri.available(), reason="needs SciPy's LAPACK")


def jacobian(rows, cols, seed, smin=1e-7):
    with tri.blas_threads(1):  # numpy's OpenBLAS: no oversubscription on a shared machine
        return _jacobian(rows, cols, seed, smin)


def _jacobian(rows, cols, seed, smin):
    rng = np.random.default_rng(seed)
    U, _ = np.linalg.qr(rng.standard_normal((rows, rows)))
    V, _ = np.linalg.qr(rng.standard_normal((cols, rows)))
    s = np.logspace(0, np.log10(smin), rows)
    return torch.from_numpy((U * s) @ V.T), torch.from_numpy(rng.standard_normal(rows))


@pytest.mark.parametrize("rows", [1, 2, 3, 40, 120])
@pytest.mark.parametrize("kappa", [-1.0, -0.5, 1.0])
def test_tridiagonal_route_matches_svd(rows, kappa):
    # smin=2e-7 keeps every singular value >= 2% away from the cutoff tau*max(s): with the
    # default 1e-7, s_85 of 120 sits exactly on 1e-5 and keep/drop flipped with round-off.
    J, g = jacobian(rows, rows + 20, rows, smin=2e-7)
    tau = 1e-5
    svd = jacobian_power(J, g, kappa, tau=tau)
    for method in ("eigh", "tridiagonal"):
        d = J.T @ gram_coefficients(J @ J.T, g, kappa, tau=tau, method=method)
        assert torch.linalg.norm(d - svd) <= 10 * np.finfo(float).eps / tau**2 * torch.linalg.norm(svd), method


def test_tridiagonal_eigenvalues_and_basis():
    J, g = jacobian(50, 60, 0, smin=1e-3)
    K = J @ J.T
    eig = tri.TridiagonalEigen(K)
    lam_ref, U = torch.linalg.eigh(K)
    torch.testing.assert_close(eig.values.sort().values, lam_ref, rtol=1e-10, atol=1e-14)
    x = torch.randn(50, dtype=torch.float64)
    # U^T and U are inverse orthogonal maps; and K = U diag(lam) U^T.
    torch.testing.assert_close(eig.expand(eig.project(x)), x, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(eig.expand(eig.values * eig.project(x)), K @ x, rtol=1e-10, atol=1e-12)


def test_auto_picks_tridiagonal_for_large_float64_cpu_matrices():
    assert resolved_eigen_method(TRIDIAGONAL_MIN_ROWS, torch.float64) == "tridiagonal"
    assert resolved_eigen_method(TRIDIAGONAL_MIN_ROWS - 1, torch.float64) == "eigh"
    assert resolved_eigen_method(4096, torch.float32) == "eigh"
    with pytest.raises(ValueError, match="method"):
        resolved_eigen_method(10, torch.float64, method="qr")


def test_without_scipy_auto_falls_back_to_eigh(monkeypatch):
    monkeypatch.setattr(tri, "available", lambda: False)
    assert resolved_eigen_method(4096, torch.float64) == "eigh"


def test_blas_threads_are_set_and_restored():
    from threadpoolctl import threadpool_info

    def blas_threads():
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    with tri.blas_threads(1):
        inside = blas_threads()
    before = blas_threads()
    if not before:
        pytest.skip("no BLAS found by threadpoolctl")
    assert inside and all(n == 1 for n in inside)
    with tri.blas_threads(1):
        pass
    assert blas_threads() == before


def test_overwrite_gives_the_same_coefficients():
    J, g = jacobian(300, 320, 7)
    K = J @ J.T
    kept = gram_coefficients(K, g, -0.5, tau=1e-5, method="tridiagonal")
    K_copy = K.clone()
    assert torch.equal(K, K_copy)  # the default leaves K alone
    scratch = K.clone()
    torch.testing.assert_close(
        gram_coefficients(scratch, g, -0.5, tau=1e-5, method="tridiagonal", overwrite=True), kept, rtol=0, atol=0
    )


@pytest.mark.parametrize("rows", [40, 300])  # eigh, and the tridiagonal route (>= TRIDIAGONAL_MIN_ROWS)
@pytest.mark.parametrize("truncation,tau", [("relative", 1e-6), ("absolute", 1e-10)])
def test_gram_forced_on_a_tall_jacobian_has_only_its_singular_values(rows, truncation, tau):
    """``solver=gram`` on a tall J (rows > params): K = J J^T has rows - params zero
    eigenvalues by structure. J has only min(rows, params) singular values: those are
    recorded (none of the structural zeros counted as dropped by tau) and inverted, as on
    the SVD route; round-off in the structural zeros never enters the direction."""
    gen = torch.Generator().manual_seed(rows)
    J = 1e3 * torch.randn(rows, 7, dtype=torch.float64, generator=gen)
    g = torch.randn(rows, dtype=torch.float64, generator=gen)
    spectra, directions = {}, {}
    for solver in ("gram", "svd"):
        opt = HIG([torch.nn.Parameter(torch.zeros(7, dtype=torch.float64))], tau=tau, truncation=truncation, solver=solver)
        directions[solver], spectra[solver] = opt.direction(J, g), opt.last_spectrum
    gram, svd = spectra["gram"], spectra["svd"]
    assert gram["sv_dropped"] == svd["sv_dropped"] == 0, gram["sv_dropped"]
    np.testing.assert_allclose(np.sort(gram["singular_values"])[::-1], torch.linalg.svdvals(J).numpy(), rtol=1e-9)
    assert gram["sv_min_kept"] == pytest.approx(svd["sv_min_kept"], rel=1e-9)
    gap = torch.linalg.norm(directions["gram"] - directions["svd"])
    assert gap <= 1e-8 * torch.linalg.norm(directions["svd"]), gap
