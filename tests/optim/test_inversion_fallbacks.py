"""A failing LAPACK driver is retried with another one before a run counts as diverged.

Failures are injected by replacing torch.linalg.svd / eigh with functions that raise
LinAlgError (as gesdd / syevd do when they fail to converge); the direction must then
come out as without the failure, and only when every route fails is LinAlgError raised.
"""

import copy

import numpy as np
import pytest
import torch

from higbench.optim import inversion, lapack
from higbench.optim.inversion import gram_coefficients, jacobian_power


def _problem(rows=12, cols=40, seed=0):
    gen = torch.Generator().manual_seed(seed)
    J = torch.randn(rows, cols, generator=gen, dtype=torch.float64)
    J[:, :3] *= 1e-3  # some spread in the singular values
    g = torch.randn(rows, generator=gen, dtype=torch.float64)
    return J, g


def _failing(real, fail_first: int):
    calls = {"n": 0}

    def fake(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] <= fail_first:
            raise torch.linalg.LinAlgError("injected: failed to converge")
        return real(*args, **kwargs)

    return fake, calls


@pytest.mark.parametrize("shape", [(12, 40), (40, 12)])  # wide (SVD of J^T) and tall J
def test_svd_failure_retries_with_gesvd(monkeypatch, shape):
    J, _ = _problem(*shape)
    g = torch.randn(shape[0], dtype=torch.float64)
    want = jacobian_power(J, g, kappa=-0.5, tau=1e-6)
    fake, calls = _failing(torch.linalg.svd, fail_first=1)
    monkeypatch.setattr(torch.linalg, "svd", fake)
    with pytest.warns(RuntimeWarning, match="used gesvd"):
        got = jacobian_power(J, g, kappa=-0.5, tau=1e-6)
    assert calls["n"] == 1
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


def test_svd_without_gesvd_uses_the_gram_route(monkeypatch):
    J, g = _problem()
    want = jacobian_power(J, g, kappa=-1.0, tau=1e-4)
    monkeypatch.setattr(torch.linalg, "svd", _failing(torch.linalg.svd, fail_first=10)[0])
    monkeypatch.setattr(lapack, "_scipy_svd", _failing(None, fail_first=10)[0])
    with pytest.warns(RuntimeWarning, match="eigh of the Gram matrix"):
        got = jacobian_power(J, g, kappa=-1.0, tau=1e-4)
    np.testing.assert_allclose(got, want, rtol=1e-7)


def test_every_route_failing_raises_linalgerror(monkeypatch):
    J, g = _problem()
    monkeypatch.setattr(torch.linalg, "svd", _failing(None, fail_first=99)[0])
    monkeypatch.setattr(torch.linalg, "eigh", _failing(None, fail_first=99)[0])
    monkeypatch.setattr(lapack, "_scipy_svd", _failing(None, fail_first=99)[0])
    monkeypatch.setattr(lapack, "_scipy_eigh", _failing(None, fail_first=99)[0])
    with pytest.raises(torch.linalg.LinAlgError, match="every driver"):
        jacobian_power(J, g, kappa=-0.5)


@pytest.mark.parametrize("fail_first", [1, 3])  # syevd fails; syevd, syevr and syev fail (SVD of K)
def test_eigh_failure_retries(monkeypatch, fail_first):
    J, g = _problem()
    K = J @ J.T
    want = gram_coefficients(K.clone(), g, kappa=-0.5, tau=1e-5, method="eigh")
    real_scipy = lapack._scipy_eigh
    count = {"n": 0}

    def scipy_maybe_failing(K, driver):
        count["n"] += 1
        if count["n"] + 1 <= fail_first:
            raise np.linalg.LinAlgError("injected")
        return real_scipy(K, driver)

    monkeypatch.setattr(torch.linalg, "eigh", _failing(torch.linalg.eigh, fail_first=1)[0])
    monkeypatch.setattr(lapack, "_scipy_eigh", scipy_maybe_failing)
    with pytest.warns(RuntimeWarning, match="eigh failed"):
        got = gram_coefficients(K.clone(), g, kappa=-0.5, tau=1e-5, method="eigh")
    np.testing.assert_allclose(got, want, rtol=1e-8, atol=1e-12)


def test_runner_update_survives_an_svd_failure(monkeypatch):
    """The toy GN update (tall J, SVD route) completes when gesdd fails once."""
    from optim_helpers import setup

    from higbench.runner.updates import build_update

    cfg, p, model, batch = setup("toy", 16, optimizer="gn")
    update = build_update(p, model, cfg.optimizer)
    monkeypatch.setattr(torch.linalg, "svd", _failing(torch.linalg.svd, fail_first=1)[0])
    with pytest.warns(RuntimeWarning):
        result = update(batch)
    assert result.finite, result.reason


# -- the tridiagonal route (Gram matrices of >= 256 rows) and a K destroyed by overwrite --


def _reduced_tridiagonal_problem(rows=40, cols=60):
    J, g = _problem(rows, cols, seed=3)
    return J, g, jacobian_power(J, g, kappa=-0.5, tau=1e-5)  # the reference: SVD of J


@pytest.mark.parametrize("failing", [("dstevd",), ("dstevd", "stemr"), ("dstevd", "stemr", "dstev")])
def test_tridiagonal_solver_failure_retries_on_the_intact_tridiagonal(monkeypatch, failing):
    """K is overwritten by the reduction (overwrite=True); a failing tridiagonal solver is
    retried with the next driver on the intact (d, e), and the direction equals the SVD's."""
    import scipy.linalg
    import scipy.linalg.lapack

    J, g, want = _reduced_tridiagonal_problem()
    calls = []

    def fails(name, real):
        def fake(*args, **kwargs):
            calls.append(name)
            if name == "stemr":
                raise np.linalg.LinAlgError("injected: stemr did not converge")
            vals, z, _ = real(*args, **kwargs)
            return vals, z, 1  # info > 0: LAPACK's "failed to converge"

        return fake

    if "dstevd" in failing:
        monkeypatch.setattr(scipy.linalg.lapack, "dstevd", fails("dstevd", scipy.linalg.lapack.dstevd))
    if "stemr" in failing:
        monkeypatch.setattr(scipy.linalg, "eigh_tridiagonal", fails("stemr", None))
    if "dstev" in failing:
        monkeypatch.setattr(scipy.linalg.lapack, "dstev", fails("dstev", scipy.linalg.lapack.dstev))
    K = (J @ J.T).contiguous()
    with pytest.warns(RuntimeWarning, match="tridiagonal eigen-solver failed"):
        c = gram_coefficients(K, g, kappa=-0.5, tau=1e-5, method="tridiagonal", overwrite=True)
    assert calls == list(failing)
    np.testing.assert_allclose(J.T @ c, want, rtol=1e-8, atol=1e-10)


def test_failed_reduction_that_destroyed_k_retries_with_the_svd_of_j(monkeypatch):
    """The reduction fails after scribbling over K (overwrite=True): HIG retries on the SVD
    route from J, and the direction equals the reference (SVD)."""
    import scipy.linalg.lapack

    from higbench.optim import HIG

    monkeypatch.setattr(inversion, "TRIDIAGONAL_MIN_ROWS", 8)  # the route `auto` takes for big K, on a small one
    J, g, want = _reduced_tridiagonal_problem()
    real, calls = scipy.linalg.lapack.dsytrd, []

    def scribbling_dsytrd(a, *args, overwrite_a=0, **kwargs):
        calls.append(overwrite_a)
        if overwrite_a:
            a[...] = np.nan  # what a reduction that died half-way could leave in K
        out = real(a, *args, overwrite_a=0, **kwargs)
        return (*out[:4], -1)

    monkeypatch.setattr(scipy.linalg.lapack, "dsytrd", scribbling_dsytrd)
    opt = HIG([torch.zeros(J.shape[1], dtype=torch.float64, requires_grad=True)], tau=1e-5, solver="gram")
    with pytest.warns(RuntimeWarning, match="retrying with the SVD of J"):
        got = opt.direction(J, g)
    assert calls == [1]  # K was handed over for overwriting, and was destroyed
    np.testing.assert_allclose(got, want, rtol=1e-8, atol=1e-10)


def test_runner_hig_update_survives_a_tridiagonal_failure(monkeypatch):
    """The oscillator HIG update (Gram route, 256 rows: tridiagonal) completes, with the same
    parameters as without the failure, when the tridiagonal solver fails once."""
    import scipy.linalg.lapack
    from optim_helpers import setup

    from higbench.runner.updates import build_update

    cfg, p, model, batch = setup("oscillator", 64, optimizer="hig")
    twin, start = copy.deepcopy(model), torch.cat([q.detach().reshape(-1) for q in model.parameters()])
    build_update(p, twin, cfg.optimizer)(batch)  # the reference update, nothing failing
    real, calls = scipy.linalg.lapack.dstevd, []

    def failing_once(*args, **kwargs):
        calls.append(1)
        vals, z, info = real(*args, **kwargs)
        return vals, z, (1 if len(calls) == 1 else info)

    monkeypatch.setattr(scipy.linalg.lapack, "dstevd", failing_once)
    update = build_update(p, model, cfg.optimizer)
    with pytest.warns(RuntimeWarning, match="used stemr"):
        result = update(batch)
    assert result.finite, result.reason
    assert calls == [1]
    got, want = (torch.cat([q.detach().reshape(-1) for q in m.parameters()]) for m in (model, twin))
    # Two eigen-solvers agree to ~eps/tau^2 (tau = 1e-6: ~1e-4) near the cutoff, not to round-off.
    assert torch.linalg.norm(got - want) <= 1e-3 * torch.linalg.norm(want - start)
