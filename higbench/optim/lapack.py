"""Dense factorisations with fallbacks: SVD and symmetric eigen-decomposition that retry
other LAPACK drivers when the default one fails to converge (see ``higbench.optim.inversion``).

Below both the inversion and the tridiagonal route, which use them.
"""

from __future__ import annotations

import warnings

import torch


def _scipy_svd(A: torch.Tensor):
    import scipy.linalg

    u, s, vh = scipy.linalg.svd(A.detach().cpu().numpy(), full_matrices=False, lapack_driver="gesvd", check_finite=False)
    return tuple(torch.from_numpy(x).to(A.device, A.dtype) for x in (u, s, vh))


def _svd_via_eigh(A: torch.Tensor):
    """Thin SVD from eigh of the smaller Gram matrix (singular values below ~sqrt(eps) lost)."""
    wide = A.shape[0] <= A.shape[1]
    lam, W = eigh(A @ A.T if wide else A.T @ A)
    lam, W = lam.flip(0).clamp_min(0), W.flip(1)
    s = lam.sqrt()
    inv = torch.where(s > 0, 1 / torch.where(s > 0, s, torch.ones_like(s)), torch.zeros_like(s))
    if wide:
        return W, s, (A.T @ W * inv).T
    return A @ W * inv, s, W.T


def svd(A: torch.Tensor):
    """``torch.linalg.svd(A, full_matrices=False)`` with fallbacks when it does not converge."""
    routes = [("gesdd", lambda: torch.linalg.svd(A, full_matrices=False)), ("gesvd", lambda: _scipy_svd(A)),
              ("eigh of the Gram matrix", lambda: _svd_via_eigh(A))]  # fmt: skip
    return first_success("SVD", routes)


def _scipy_eigh(K: torch.Tensor, driver: str):
    import scipy.linalg

    lam, U = scipy.linalg.eigh(K.detach().cpu().numpy(), lower=True, driver=driver, check_finite=False)
    return torch.from_numpy(lam).to(K.device, K.dtype), torch.from_numpy(U).to(K.device, K.dtype)


def _eigh_via_svd(K: torch.Tensor):
    """K symmetric positive semi-definite: its SVD is its eigen-decomposition (ascending here)."""
    sym = torch.tril(K) + torch.tril(K, -1).T
    U, s, _ = torch.linalg.svd(sym)
    return s.flip(0), U.flip(1)


def eigh(K: torch.Tensor):
    """``torch.linalg.eigh(K)`` (lower triangle) with fallbacks when it does not converge."""
    routes = [("syevd", lambda: torch.linalg.eigh(K)), ("syevr", lambda: _scipy_eigh(K, "evr")),
              ("syev", lambda: _scipy_eigh(K, "ev")), ("SVD of K", lambda: _eigh_via_svd(K))]  # fmt: skip
    return first_success("eigh", routes)


def first_success(what: str, routes):
    """The result of the first route (name, thunk) that neither raises nor returns non-finite
    tensors; a warning names the routes that failed. LinAlgError when every route fails."""
    errors = []
    for name, route in routes:
        try:
            out = route()
        except (torch.linalg.LinAlgError, ImportError, ValueError) as exc:  # numpy's LinAlgError is a ValueError
            errors.append(f"{name}: {exc}")
            continue
        if not all(torch.isfinite(x).all() for x in out):
            errors.append(f"{name}: non-finite result")
            continue
        if errors:
            warnings.warn(f"{what} failed ({'; '.join(errors)}); used {name} instead", RuntimeWarning, stacklevel=3)
        return out
    raise torch.linalg.LinAlgError(f"{what} failed with every driver: {'; '.join(errors)}")
