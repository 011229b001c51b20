"""The Krylov route (optimizer.solver=krylov): Lanczos on products with K = J J^T, checked
against the exact routes (SVD of J, eigen-decomposition of K)."""

import json
import math

import numpy as np
import pytest
import torch
from optim_helpers import flat, setup
from synthetic import short_run
from torch import nn

from higbench.optim import HIG, GaussNewton, gram_coefficients, jacobian_power
from higbench.optim.krylov import CHECK_EVERY, krylov_coefficients, krylov_direction, lanczos
from higbench.optim.lm import LevenbergMarquardt
from higbench.optim.memory_guard import estimate_bytes
from higbench.optim.solver_choice import choose_solver
from higbench.optim.structured import MLPJacobian, mlp_factor_values, network_jacobian, solver_jacobian
from higbench.runfile.reader import load_updates


def wide_jacobian(rows=40, cols=60, smin=1e-3, seed=0):
    """J = U diag(s) V^T with singular values from 1 down to smin (log-spaced), and a g."""
    gen = torch.Generator().manual_seed(seed)
    U, _ = torch.linalg.qr(torch.randn(rows, rows, dtype=torch.float64, generator=gen))
    V, _ = torch.linalg.qr(torch.randn(cols, rows, dtype=torch.float64, generator=gen))
    s = torch.logspace(0, math.log10(smin), rows, dtype=torch.float64)
    return (U * s) @ V.T, torch.randn(rows, dtype=torch.float64, generator=gen)


def cosine(a, b):
    return float(a @ b / (a.norm() * b.norm()))


# tau = 0.0123 sits between singular values (no keep/drop flip from round-off).
@pytest.mark.parametrize("kappa", [-0.5, -1.0, 1.0])
@pytest.mark.parametrize("tau", [1e-6, 0.0123])
@pytest.mark.parametrize("beta", [0.0, 0.5])
def test_full_krylov_space_gives_the_exact_direction(kappa, tau, beta):
    J, g = wide_jacobian()
    exact = jacobian_power(J, g, kappa, beta=beta, tau=tau)
    d, result = krylov_direction(J, g, kappa=kappa, beta=beta, tau=tau, steps=J.shape[0])
    assert result.steps == J.shape[0] and result.step_error == 0.0
    torch.testing.assert_close(d, exact, rtol=0, atol=1e-9 * exact.norm())
    c = gram_coefficients(J @ J.T, g, kappa, beta=beta, tau=tau)
    torch.testing.assert_close(result.coefficients, c, rtol=0, atol=1e-9 * c.norm())


def test_tall_jacobian_stops_at_the_invariant_subspace_exactly():
    # rows > params: K has rank 12, so the Krylov space of g closes after 13 steps (one more
    # where round-off leaves the last residual just above the breakdown test).
    J, g = wide_jacobian(rows=12, cols=12, smin=1e-2)
    J = torch.cat([J, J[:8] * 0.5 + J[4:]], dim=0)  # 20 x 12
    g = torch.randn(20, dtype=torch.float64, generator=torch.Generator().manual_seed(3))
    d, result = krylov_direction(J, g, kappa=-0.5, tau=1e-6, steps=200)
    assert result.steps <= 14 and result.step_error == 0.0
    exact = jacobian_power(J, g, -0.5, tau=1e-6)
    torch.testing.assert_close(d, exact, rtol=0, atol=1e-9 * exact.norm())


def test_fewer_steps_approximate_and_the_estimate_follows_the_error():
    J, g = wide_jacobian(rows=120, cols=150, smin=1e-2)
    exact = jacobian_power(J, g, -0.5, tau=1e-6)
    errors, estimates, cosines = [], [], []
    for m in (20, 40, 80):
        d, result = krylov_direction(J, g, kappa=-0.5, tau=1e-6, steps=m)
        assert result.steps == m and result.ritz_s.numel() == m
        errors.append(float((d - exact).norm() / exact.norm()))
        estimates.append(result.step_error)
        cosines.append(cosine(d, exact))
    assert errors[0] > errors[1] > errors[2] and cosines[0] < cosines[1] < cosines[2] < 1
    assert estimates[0] > estimates[1] > estimates[2] > 0
    for err, est in zip(errors, estimates):  # the estimate is of the right size (within 10x)
        assert err / 10 < est < err * 10, (err, est)


def test_tolerance_stops_early_below_it():
    J, g = wide_jacobian(rows=120, cols=150, smin=1e-1)
    _, result = krylov_direction(J, g, kappa=-0.5, tau=1e-6, steps=120, tol=1e-4)
    assert result.steps < 120 and result.steps % CHECK_EVERY == 0
    assert 0 < result.step_error < 1e-4


def test_ritz_values_are_the_spectrum_the_filter_sees():
    J, g = wide_jacobian(rows=30, cols=40, smin=1e-2)
    seen = {}
    krylov_coefficients(lambda v: J @ (J.T @ v), g, -0.5, tau=0.05, steps=30, on_spectrum=lambda s, k: seen.update(s=s, k=k))
    s_exact = torch.linalg.svdvals(J).flip(0)
    torch.testing.assert_close(seen["s"], s_exact, rtol=1e-8, atol=0)
    assert torch.equal(seen["k"], s_exact >= 0.05 * s_exact.max())


def test_lanczos_basis_is_orthonormal_and_tridiagonalises_K():
    J, g = wide_jacobian(rows=50, cols=60, smin=1e-4)
    K = J @ J.T
    basis = lanczos(lambda v: K @ v, g, 30)
    Q, T = basis.Q, basis.tridiagonal()
    torch.testing.assert_close(Q.T @ Q, torch.eye(30, dtype=torch.float64), rtol=0, atol=1e-13)
    torch.testing.assert_close(Q.T @ K @ Q, T, rtol=0, atol=1e-13)


def test_zero_and_non_finite_gradients():
    J, _ = wide_jacobian(rows=10, cols=12)
    d, result = krylov_direction(J, torch.zeros(10, dtype=torch.float64), kappa=-0.5, steps=5)
    assert torch.equal(d, torch.zeros(12, dtype=torch.float64)) and result.step_error == 0.0
    g = torch.ones(10, dtype=torch.float64)
    g[3] = math.nan
    d, _ = krylov_direction(J, g, kappa=-0.5, steps=5)
    assert not torch.isfinite(d).any()


def mlp_case():
    torch.manual_seed(0)
    model = nn.Sequential(nn.Linear(3, 6), nn.Tanh(), nn.Linear(6, 4, bias=False), nn.Tanh(), nn.Linear(4, 5)).double()
    physics = lambda x, u: torch.stack([(u * x).sum(1), u.pow(2).sum(1), u[:, 0]], dim=1)  # noqa: E731
    z, x = torch.randn(4, 3, dtype=torch.float64), torch.randn(4, 5, dtype=torch.float64)
    _, A = solver_jacobian(physics, x, model(z))
    return model, network_jacobian(model, list(model.parameters()), z, A)


def test_mlp_products_match_the_materialised_jacobian():
    model, sj = mlp_case()
    assert isinstance(sj, MLPJacobian)
    J = sj.matrix()
    gen = torch.Generator().manual_seed(1)
    v, c = torch.randn(sj.n_params, dtype=torch.float64, generator=gen), torch.randn(sj.rows, dtype=torch.float64, generator=gen)
    torch.testing.assert_close(sj.apply(v), J @ v, rtol=1e-12, atol=1e-13)
    torch.testing.assert_close(sj.gram_apply(c), J @ (J.T @ c), rtol=1e-12, atol=1e-13)
    assert mlp_factor_values(model) == 2 * (6 + 4 + 5) + (3 + 6 + 4)


@pytest.mark.parametrize("case", ["poisson", "dipole_cnn"])
def test_generic_and_mlp_products_match_on_the_problems(case):
    _, p, model, batch = setup(case, 2)
    _, A = solver_jacobian(p.physics, batch.inputs, model(batch.net_inputs))
    sj = network_jacobian(model, list(model.parameters()), batch.net_inputs, A)
    J = sj.matrix()
    c = torch.randn(sj.rows, dtype=torch.float64, generator=torch.Generator().manual_seed(2))
    ref = J @ (J.T @ c)
    torch.testing.assert_close(sj.gram_apply(c), ref, rtol=0, atol=1e-12 * ref.abs().max())


@pytest.mark.parametrize("case", ["poisson", "oscillator", "dipole_cnn"])
@pytest.mark.parametrize("cls", [HIG, GaussNewton])
def test_optimizer_step_with_all_steps_equals_the_gram_step(case, cls):
    _, p, model, batch = setup(case, 2)
    start = {k: v.clone() for k, v in model.state_dict().items()}
    after = {}
    for solver in ("gram", "krylov"):
        model.load_state_dict(start)
        opt = cls(model.parameters(), lr=0.1, tau=1e-6, solver=solver, krylov_steps=10_000)
        opt.step_structured(model, batch.net_inputs, p.physics, lambda y: p.loss(y, batch.targets), batch.inputs)
        assert opt.last_finite, opt.last_reason
        after[solver] = flat(model)
        spectrum = opt.last_spectrum
    moved = after["gram"] - flat_state(start)
    # Both exact to round-off amplified by the conditioning (GN's 1/s^2 on the CNN: ~1e-9).
    torch.testing.assert_close(after["krylov"] - flat_state(start), moved, rtol=0, atol=1e-7 * moved.abs().max())
    assert spectrum["step_error"] == 0.0 and spectrum["krylov_steps"] <= batch.net_inputs.shape[0] * 64
    assert spectrum["sv_max"] > 0


def flat_state(state):
    return torch.cat([v.reshape(-1) for v in state.values()]).double()


def test_optimizer_with_few_steps_records_its_estimate():
    _, p, model, batch = setup("poisson", 2)
    opt = HIG(model.parameters(), lr=0.1, solver="krylov", krylov_steps=30)
    opt.step_structured(model, batch.net_inputs, p.physics, lambda y: p.loss(y, batch.targets), batch.inputs)
    assert opt.last_finite and opt.last_spectrum["krylov_steps"] == 30
    assert 0 < opt.last_spectrum["step_error"] < 1 and len(opt.last_spectrum["singular_values"]) == 30


def test_closure_step_takes_the_krylov_route():
    _, p, model, batch = setup("toy", 8)
    start = {k: v.clone() for k, v in model.state_dict().items()}
    moved = {}
    for solver in ("svd", "krylov"):
        model.load_state_dict(start)
        opt = HIG(model.parameters(), lr=0.1, solver=solver)

        def closure():
            y = p.outputs(model, batch)
            return y, p.loss(y, batch.targets)

        opt.step(closure)
        moved[solver] = flat(model) - flat_state(start)
    torch.testing.assert_close(moved["krylov"], moved["svd"], rtol=0, atol=1e-6 * moved["svd"].abs().max())


def test_bad_settings_are_refused():
    params = [nn.Parameter(torch.zeros(2))]
    with pytest.raises(ValueError, match="krylov_steps=0"):
        HIG(params, solver="krylov", krylov_steps=0)
    with pytest.raises(ValueError, match="krylov_tol=1.5"):
        HIG(params, solver="krylov", krylov_tol=1.5)
    with pytest.raises(ValueError, match="solver='krylov'"):
        LevenbergMarquardt(params, solver="krylov")
    assert choose_solver("krylov", 10, 5, 1e-6) == "krylov"
    assert choose_solver("auto", 10, 50, 1e-6) == "gram"  # auto never picks the approximate route


def test_memory_estimate_of_the_krylov_route_has_no_gram_matrix():
    # Poisson at b=1024: 65,536 rows, 41,408 parameters, factors of 2*(64+256+64+64)+(64+64+256+64) values per row.
    factors = 2 * (64 + 256 + 64 + 64) + (64 + 64 + 256 + 64)
    kw = dict(precision="float64", jacobian="structured", factor_values=factors)
    est = estimate_bytes(1024, 64, 41408, solver="krylov", krylov_steps=200, **kw)
    assert est.solver == "krylov" and "gram" not in est.parts
    assert est.total < 2 * 2**30
    assert estimate_bytes(1024, 64, 41408, solver="gram", **kw).total > 30 * 2**30


def test_run_file_records_the_step_error_per_update(tmp_path):
    path = short_run(tmp_path, "hig", "optimizer.solver=krylov", "+optimizer.krylov_steps=4", updates=3)
    updates = load_updates(path)
    assert len(updates) == 3 and (updates["step_error"] > 0).all() and (updates["sv_max"] > 0).all()
    exact = load_updates(short_run(tmp_path / "exact", "hig", "optimizer.solver=gram", updates=2))
    assert np.isnan(exact["step_error"]).all()


def test_probe_prints_cosine_and_estimate_per_step_count(capsys):
    from higbench.bench import krylov as bench_krylov

    threads = torch.get_num_threads()
    try:
        bench_krylov.main(["--problem", "poisson", "--batch-size", "1", "--steps", "8", "64", "--repeats", "1", "--threads", "1"])
    finally:
        torch.set_num_threads(threads)
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.startswith("{")]
    assert [r["steps"] for r in rows] == [8, 64] and all(r["rows"] == 64 for r in rows)
    few, full = rows
    assert full["cosine"] == pytest.approx(1.0, abs=1e-9) and full["step_error"] == 0.0
    assert few["cosine"] < full["cosine"] and few["step_error"] > 0 and few["krylov_s"] > 0 and few["exact_s"] > 0
