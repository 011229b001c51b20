"""On a GPU: the compiled solvers serve a CUDA run from the host, and equal the reference
solvers run on the GPU; a HIG update on the GPU equals the CPU's; device=auto measures both.

Skipped, with the reason, on a machine without CUDA (CI has none); docs/benchmarks.md ("On a
GPU") says when they last ran and on which card.
"""

import math

import pytest
import torch

from higbench.optim.structured import solver_jacobian
from higbench.physics import dipole, dipole_fast, oscillator, oscillator_fast
from higbench.runner.plan import Plan

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU (none on this machine)")

F64, CUDA = torch.float64, torch.device("cuda")
TOL = 1e-10


def config(*overrides):
    from hydra import compose, initialize_config_dir

    from higbench.config import config_dir

    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        return compose("config", overrides=["threads=1", "progress=false", *overrides])


def rel(a, b):
    return ((a - b).norm() / b.norm()).item()


def cases():
    g = torch.Generator().manual_seed(0)
    psi = torch.randn(5, 14, 2, generator=g, dtype=F64)
    psi = psi / psi.square().sum((-2, -1), keepdim=True).sqrt()
    return {
        "oscillator": (oscillator.simulate, oscillator_fast.simulate, torch.rand(6, 4, generator=g, dtype=F64),
                       torch.randn(6, 96, generator=g, dtype=F64)),
        "dipole": (dipole.simulate, dipole_fast.simulate, psi, 3.0 * torch.randn(5, 384, generator=g, dtype=F64)),
    }  # fmt: skip


@pytest.mark.parametrize("name", ["oscillator", "dipole"])
def test_fast_solver_on_cuda_tensors_equals_the_reference_on_the_gpu(name):
    ref, fast, x0, u = cases()[name]
    results = []
    for solve in (ref, fast):
        x, v = x0.to(CUDA).requires_grad_(), u.to(CUDA).requires_grad_()
        y = solve(x, v)
        assert y.device.type == "cuda"
        w = torch.linspace(-1, 1, y.numel(), dtype=F64, device=CUDA).reshape(y.shape)
        (y * w).sum().backward()
        assert x.grad.device.type == "cuda" and v.grad.device.type == "cuda"
        results.append((y.detach(), x.grad, v.grad))
    for a, b in zip(results[1], results[0]):
        assert rel(a, b) < TOL
    y, A = solver_jacobian(lambda x, v: ref(x, v).reshape(v.shape[0], -1), x0.to(CUDA), u.to(CUDA))
    y_fast, A_fast = fast_jacobian(name)(x0.to(CUDA), u.to(CUDA))
    assert A_fast.device.type == "cuda"
    assert rel(y_fast.reshape(y.shape), y) < TOL and rel(A_fast.reshape(A.shape), A) < TOL


def fast_jacobian(name):
    return {"oscillator": oscillator_fast.solver_jacobian, "dipole": dipole_fast.solver_jacobian}[name]


@pytest.mark.parametrize(
    "problem, solver",
    [("oscillator", "auto"), ("dipole", "auto"), ("poisson", "auto"), ("oscillator", "krylov"), ("poisson", "krylov")],
)
def test_a_hig_update_on_the_gpu_equals_the_cpu_s(problem, solver):
    """The GPU's update equals the CPU's: the exact routes, and the Krylov route with as many
    Lanczos steps as rows (exact up to round-off)."""
    from higbench.runner import train as train_mod
    from higbench.runner.updates import build_update

    krylov = ["+optimizer.krylov_steps=1024"] if solver == "krylov" else []
    cfg = config(f"problem={problem}", "optimizer=hig", "dtype=float64", "batch_size=4", f"optimizer.solver={solver}", *krylov)
    params = []
    for device in (torch.device("cpu"), CUDA):
        _device, p = train_mod._setup(Plan.for_run(cfg, "run.h5"), device=device)
        model = p.build_model()
        update = build_update(p, model, cfg.optimizer)
        batch = next(p.epoch(4, torch.Generator().manual_seed(0)))
        assert update(batch).finite
        params.append(torch.cat([q.detach().cpu().flatten() for q in model.parameters()]))
    assert rel(params[1], params[0]) < 1e-8


@pytest.mark.parametrize("problem", ["oscillator", "poisson"])
def test_update_cost_on_the_gpu_is_measured(problem):
    from higbench.runner import train as train_mod

    cost = train_mod._update_cost(Plan.for_run(config(f"problem={problem}", "optimizer=hig", "batch_size=4"), "run.h5"), CUDA)
    assert 0 < cost < math.inf


def test_the_naive_jacobian_route_runs_through_the_host_solver():
    """torch.func's vmap(jacrev) through the host copies: the naive route's J equals the structured one's."""
    from higbench.runner import train as train_mod
    from higbench.runner.updates import build_update

    params = {}
    for jacobian in ("structured", "naive"):
        cfg = config("problem=oscillator", "optimizer=hig", "dtype=float64", "batch_size=4", f"optimizer.jacobian={jacobian}",
                     "optimizer.solver=svd")  # fmt: skip
        _device, p = train_mod._setup(Plan.for_run(cfg, "run.h5"), device=CUDA)
        model = p.build_model()
        update = build_update(p, model, cfg.optimizer)
        assert update(next(p.epoch(4, torch.Generator().manual_seed(0)))).finite
        params[jacobian] = torch.cat([q.detach().flatten() for q in model.parameters()])
    assert rel(params["naive"], params["structured"]) < 1e-8
