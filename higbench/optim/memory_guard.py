"""Memory guard for GN/HIG: refuse a batch size whose Jacobian/inversion step cannot fit.

The Jacobian-power step materialises J (rows = batch_size * |y|, columns = |theta|) and
inverts it, either through the Gram matrix K = J J^T (rows x rows) or the thin SVD of J.
``estimate_bytes`` gives the peak of that step (the dominant arrays; model, data and
first-order optimizers are small next to it). ``check`` compares it with the memory
available now (psutil's available memory, or less where the process's address space is
capped, ``ulimit -v``; free CUDA memory on a GPU) or a configured cap (``memory_limit_mb``)
and raises ``ConfigError`` with the estimate and the largest batch size that fits, so a run
fails in a second instead of being killed by the OS an hour in. ``check_samples`` does the
same for the data sets a problem draws after its own (the validation and fresh test sets),
whatever the optimizer.

The model is deliberately simple and errs on the large side; a faster Jacobian path
(structured, never materialising J) can refine ``estimate_bytes`` without changing callers.
"""

from __future__ import annotations

from dataclasses import dataclass

from higbench.errors import MemoryRefusal
from higbench.optim.solver_choice import choose_solver, lanczos_steps

ITEMSIZE = {"float16": 2, "bfloat16": 2, "float32": 4, "float64": 8}


@dataclass
class Estimate:
    total: int
    parts: dict[str, int]
    solver: str
    work_rows: int = 0  # size of the inversion: the Gram rows, or min(rows, params) for the SVD

    def describe(self) -> str:
        return ", ".join(f"{k} {mb(v)}" for k, v in self.parts.items() if v)


def mb(n_bytes: float) -> str:
    return f"{n_bytes / 2**20:,.0f} MB" if n_bytes >= 2**20 else f"{n_bytes / 2**20:.2f} MB"


def _itemsize(dtype) -> int:
    name = str(dtype).replace("torch.", "")
    if name not in ITEMSIZE:
        raise ValueError(f"dtype={dtype!r}: expected one of {tuple(ITEMSIZE)}")
    return ITEMSIZE[name]


def estimate_bytes(
    batch_size: int,
    output_size: int,
    n_params: int,
    dtype="float32",
    solver: str = "auto",
    precision="float64",
    jacobian: str = "naive",
    tau: float = 1e-6,
    truncation: str = "relative",
    krylov_steps: int = 200,
    factor_values: int | None = None,
) -> Estimate:
    """Peak bytes of one Jacobian-power update.

    batch_size, output_size (|y| per sample), n_params (|theta|); dtype: network dtype (J as
    computed); precision: dtype of the inversion (J is converted to it); solver: gram, svd
    or auto, resolved with tau and truncation by the optimizer's own rule
    (``higbench.optim.solver_choice.choose_solver``); jacobian: naive (torch.func J in ``dtype``,
    then cast) or structured (computed in
    ``precision``; counted as one materialised J, an upper bound: the MLP Gram route of
    ``higbench.optim.structured`` forms only per-layer factors).
    krylov_steps: the Lanczos basis of the krylov route (rows x steps, steps capped at rows:
        ``solver_choice.lanczos_steps``; no K, no J formed).
    factor_values: values per row of J's per-layer factors where the structured route holds
        those instead of J (MLPs, ``structured.mlp_factor_values``); counted on the krylov
        route, which never forms J (the others do, or K, which dominates).
    """
    rows, p = batch_size * output_size, n_params
    e, e2 = _itemsize(dtype), _itemsize(precision)
    solver = choose_solver(solver, rows, p, tau, precision, truncation)
    if jacobian == "structured" and solver == "krylov" and factor_values is not None:
        parts = {"jacobian_factors": rows * factor_values * e2, "jacobian_cast": 0}
    elif jacobian == "structured":
        parts = {"jacobian": rows * p * e2, "jacobian_cast": 0}
    else:
        parts = {
            # torch.func returns one block per parameter tensor, then concatenates: 2 copies at the peak
            "jacobian": 2 * rows * p * e,
            "jacobian_cast": rows * p * e2 if e2 != e else 0,
        }
    if solver == "krylov":
        # the Lanczos basis, its T_m eigenvectors (steps^2) and a few vectors of rows; Lanczos
        # stops at J's rows, so a larger krylov_steps costs no more
        steps = lanczos_steps(krylov_steps, rows)
        parts["krylov_basis"] = (rows * (steps + 4) + steps * steps) * e2
    elif solver == "gram":
        # K = J J^T, eigenvectors of K, LAPACK syevd workspace (~1 + 6n + 2n^2 doubles)
        parts["gram"] = rows * rows * e2
        parts["eigh"] = (3 * rows * rows + 6 * rows) * e2
    else:
        k = min(rows, p)
        # gesdd destroys its input (a copy of J), returns U (rows x k) and Vh (k x p),
        # workspace ~ 4k^2 + max(rows, p) * k
        parts["svd_input"] = rows * p * e2
        parts["svd_factors"] = (rows * k + k * p) * e2
        parts["svd_work"] = (4 * k * k + max(rows, p) * k) * e2
    return Estimate(sum(parts.values()), parts, solver, rows if solver in ("gram", "krylov") else min(rows, p))


def available_bytes(device: str = "cpu") -> tuple[int, str]:
    """(bytes available now, where that number comes from)."""
    if str(device).startswith("cuda"):
        import torch

        free, _total = torch.cuda.mem_get_info(torch.device(device))
        return int(free), "free CUDA memory"
    import psutil

    available = int(psutil.virtual_memory().available)
    headroom = address_space_headroom()
    if headroom is not None and headroom < available:
        return headroom, "address space left under RLIMIT_AS (ulimit -v)"
    return available, "available memory"


def address_space_headroom() -> int | None:
    """Bytes this process may still map under its RLIMIT_AS soft limit (``ulimit -v``), or None
    where there is no such limit: the machine's available memory is no use to a capped process."""
    import resource

    import psutil

    soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    return max(0, soft - int(psutil.Process().memory_info().vms))


def usable_bytes(device: str = "cpu", limit_mb: float | None = None) -> tuple[int, str]:
    """(bytes a run may use now, where that number comes from): what is available, or the
    configured cap (``memory_limit_mb``) where it is lower."""
    avail, source = available_bytes(device)
    if limit_mb is not None and limit_mb * 2**20 < avail:
        avail, source = int(limit_mb * 2**20), "memory_limit_mb"
    return avail, source


# A data set being drawn holds its samples and, while a problem makes them (float64 before the
# cast, the physics' intermediate arrays), about as much again: counted twice, on the large side.
DRAW_COPIES = 2


def check_samples(sizes: dict[str, int], sample_bytes: int, device: str = "cpu", limit_mb: float | None = None) -> None:
    """Raise ConfigError, naming the size key, if data sets drawn after the run's own do not fit.

    ``sizes``: key -> samples (``problem.val_size``, ``problem.fresh_test_size``), in the order
    they are drawn; each is held to the end of the run, so each must fit beside those before
    it. ``sample_bytes``: bytes of one sample (``Problem.sample_bytes``)."""
    avail, source = usable_bytes(device, limit_mb)
    held, per_sample = 0, max(1, int(sample_bytes))
    for key, n in sizes.items():
        need = DRAW_COPIES * n * per_sample
        if held + need > avail:
            fits = max(0, (avail - held) // (DRAW_COPIES * per_sample))
            beside = f" beside {mb(held)} of the sets before it" if held else ""
            raise MemoryRefusal(
                key,
                n,
                f"{n:,} samples of {per_sample:,} bytes need about {mb(need)} while drawn{beside}, "
                f"but {mb(avail)} is available ({source}); at most {fits:,} fit",
            )
        held += n * per_sample


def largest_batch(
    limit: int,
    output_size: int,
    n_params: int,
    dtype="float32",
    solver: str = "auto",
    precision="float64",
    upper: int = 1 << 30,
    **route,
) -> int:
    """Largest batch size whose estimate fits in ``limit`` bytes (0 if not even 1 fits).

    ``route``: the keyword arguments of :func:`estimate_bytes` that pick the step's route
    (``jacobian``, ``tau``, ``truncation``, ``krylov_steps``, ``factor_values``), with its defaults.
    """

    def fits(batch_size: int) -> bool:
        return estimate_bytes(batch_size, output_size, n_params, dtype, solver, precision, **route).total <= limit

    if not fits(1):
        return 0
    lo, hi = 1, upper
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if fits(mid):
            lo = mid
        else:
            hi = mid - 1
    return lo


def check(
    batch_size: int,
    output_size: int,
    n_params: int,
    dtype="float32",
    solver: str = "auto",
    precision="float64",
    device: str = "cpu",
    limit_mb: float | None = None,
    **route,
) -> Estimate:
    """Raise ConfigError if the step for ``batch_size`` does not fit; return the estimate.

    ``route``: :func:`estimate_bytes`'s route keywords, as in :func:`largest_batch`.
    """
    est = estimate_bytes(batch_size, output_size, n_params, dtype, solver, precision, **route)
    avail, source = usable_bytes(device, limit_mb)
    if est.total > avail:
        best = largest_batch(avail, output_size, n_params, dtype, solver, precision, upper=batch_size, **route)
        advice = f"largest batch size that fits: {best}" if best else "not even batch_size=1 fits"
        raise MemoryRefusal(
            "batch_size",
            batch_size,
            f"the {est.solver.upper()} Jacobian-power step needs about {mb(est.total)} "
            f"({batch_size}x{output_size} rows x {n_params} params; {est.describe()}) "
            f"but {mb(avail)} is available ({source}); {advice}",
        )
    return est
