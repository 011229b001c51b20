"""A failing LAPACK driver is retried with another one before a run counts as diverged.

Failures are injected by replacing torch.linalg.svd / eigh with functions that raise
LinAlgError (as gesdd / syevd do when they fail to converge); the direction must then
come out as without the failure, and only when every route fails is LinAlgError raised.
"""

import numpy as np
import pytest
import torch

from higbench.optim import inversion
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
    monkeypatch.setattr(inversion, "_scipy_svd", _failing(None, fail_first=10)[0])
    with pytest.warns(RuntimeWarning, match="eigh of the Gram matrix"):
        got = jacobian_power(J, g, kappa=-1.0, tau=1e-4)
    np.testing.assert_allclose(got, want, rtol=1e-7)


def test_every_route_failing_raises_linalgerror(monkeypatch):
    J, g = _problem()
    monkeypatch.setattr(torch.linalg, "svd", _failing(None, fail_first=99)[0])
    monkeypatch.setattr(torch.linalg, "eigh", _failing(None, fail_first=99)[0])
    monkeypatch.setattr(inversion, "_scipy_svd", _failing(None, fail_first=99)[0])
    monkeypatch.setattr(inversion, "_scipy_eigh", _failing(None, fail_first=99)[0])
    with pytest.raises(torch.linalg.LinAlgError, match="every driver"):
        jacobian_power(J, g, kappa=-0.5)


@pytest.mark.parametrize("fail_first", [1, 3])  # syevd fails; syevd, syevr and syev fail (SVD of K)
def test_eigh_failure_retries(monkeypatch, fail_first):
    J, g = _problem()
    K = J @ J.T
    want = gram_coefficients(K.clone(), g, kappa=-0.5, tau=1e-5, method="eigh")
    real_scipy = inversion._scipy_eigh
    count = {"n": 0}

    def scipy_maybe_failing(K, driver):
        count["n"] += 1
        if count["n"] + 1 <= fail_first:
            raise np.linalg.LinAlgError("injected")
        return real_scipy(K, driver)

    monkeypatch.setattr(torch.linalg, "eigh", _failing(torch.linalg.eigh, fail_first=1)[0])
    monkeypatch.setattr(inversion, "_scipy_eigh", scipy_maybe_failing)
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
