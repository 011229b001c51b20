"""Which inversion route a Jacobian-power update takes: the one rule, used by the optimizer
(``JacobianPower.resolved_solver``) and by the memory guard that sizes its step.

Plain numbers in, a name out (no tensors): the memory guard sizes a step before building it.
"""

from __future__ import annotations

# Machine epsilon of the inversion precisions (torch.finfo(dtype).eps).
EPS = {"bfloat16": 2.0**-7, "float16": 2.0**-10, "float32": 2.0**-23, "float64": 2.0**-52}


def _precision_name(precision) -> str:
    return str(precision).replace("torch.", "")


def gram_is_accurate(tau: float, precision="float64", truncation: str = "relative") -> bool:
    """Whether the Gram route resolves the relative cutoff tau.

    eigh(K) is backward stable: eigenvalues carry an absolute error of order
    eps * max(s)^2, so a singular value s = tau * max(s) comes out with a relative error of
    about eps / tau^2. Requiring tau^2 > 100 * eps keeps it below 1% at the cutoff and far
    smaller above it; below that, ``auto`` falls back to the SVD of J.
    """
    if truncation != "relative":
        return True  # absolute mode: the caller owns the scale; the SVD stays available
    return tau * tau > 100 * EPS[_precision_name(precision)]


def choose_solver(
    solver: str,
    rows: int | None,
    n_params: int | None,
    tau: float,
    precision="float64",
    truncation: str = "relative",
) -> str:
    """``gram``, ``svd`` or ``krylov`` for a J of ``rows`` x ``n_params``.

    An explicit ``gram``/``svd``/``krylov`` is kept (``krylov``: Lanczos on products with
    J J^T, ``higbench.optim.krylov``; never chosen by ``auto``, being approximate).
    ``auto``: the thin SVD of J when J is tall (rows >= params, e.g. the toy's 512 x 30:
    cheaper than eigh of the rows x rows Gram matrix) or when tau is too small for the Gram
    route in ``precision``; the Gram route otherwise.
    """
    if solver in ("gram", "svd", "krylov"):
        return solver
    if solver != "auto":
        raise ValueError(f"solver={solver!r}: expected auto, gram, svd or krylov")
    if rows is not None and n_params is not None and rows >= n_params:
        return "svd"
    return "gram" if gram_is_accurate(tau, precision, truncation) else "svd"


def lanczos_steps(steps: int, rows: int) -> int:
    """Lanczos steps the krylov route takes at most: ``krylov_steps``, but never more than J's rows
    (the basis of K's row space is then complete). Its memory (``memory_guard``) is sized by these."""
    return max(1, min(int(steps), int(rows)))
