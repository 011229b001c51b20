"""Structured derivatives (solver part x network part) against the torch.func references."""

import pytest
import torch
from optim_helpers import CASES, setup
from torch import nn

from higbench.optim.jacobians import full_jacobian, per_sample_jacobian
from higbench.optim.structured import (
    SOLVER_JACOBIAN_METHODS,
    GenericJacobian,
    GraphJacobian,
    MLPJacobian,
    mlp_layers,
    network_jacobian,
    solver_jacobian,
)


def reference(p, model, batch):
    return per_sample_jacobian(model, p.physics, batch.inputs, batch.net_inputs)


@pytest.mark.parametrize("case", list(CASES))
def test_structured_rows_gram_and_vjp_match_torch_func(case):
    _, p, model, batch = setup(case)
    J_ref = reference(p, model, batch)
    u = model(batch.net_inputs)
    y, A = solver_jacobian(p.physics, batch.inputs, u)
    torch.testing.assert_close(y, p.outputs(model, batch).detach(), rtol=1e-12, atol=1e-12)
    sj = network_jacobian(model, list(model.parameters()), batch.net_inputs, A)
    assert isinstance(sj, GenericJacobian if case == "dipole_cnn" else MLPJacobian)
    assert (sj.rows, sj.n_params) == tuple(J_ref.shape)
    scale = J_ref.abs().max()
    torch.testing.assert_close(sj.matrix(), J_ref, rtol=0, atol=1e-12 * scale)
    K_ref = J_ref @ J_ref.T
    torch.testing.assert_close(sj.gram(), K_ref, rtol=0, atol=1e-12 * K_ref.abs().max())
    c = torch.randn(sj.rows, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    torch.testing.assert_close(sj.transpose_apply(c), J_ref.T @ c, rtol=1e-10, atol=1e-12 * (J_ref.T @ c).abs().max())


@pytest.mark.parametrize("method", SOLVER_JACOBIAN_METHODS)
@pytest.mark.parametrize("case", ["oscillator", "dipole"])
def test_solver_jacobian_methods_agree_with_full_jacobian_of_the_solver(case, method):
    _, p, model, batch = setup(case)
    u = model(batch.net_inputs).detach()
    y, A = solver_jacobian(p.physics, batch.inputs, u, method=method)
    full = torch.func.jacrev(lambda v: p.physics(batch.inputs, v))(u)  # (b, m, b, |u|), cross-sample blocks zero
    b = u.shape[0]
    blocks = full[torch.arange(b), :, torch.arange(b)]  # (b, m, |u|)
    torch.testing.assert_close(A, blocks, rtol=1e-12, atol=1e-12)
    off = full.clone()
    off[torch.arange(b), :, torch.arange(b)] = 0
    assert off.abs().max() == 0  # the samples really are independent


def test_solver_jacobian_without_inputs_and_with_multidimensional_u():
    grid = torch.linspace(0, 1, 5, dtype=torch.float64)
    physics = lambda u: (u.sin() * grid).sum(-1)  # u (b, 3, 5) -> y (b, 3)  # noqa: E731
    u = torch.randn(4, 3, 5, dtype=torch.float64)
    y, A = solver_jacobian(physics, None, u)
    assert y.shape == (4, 3) and A.shape == (4, 3, 15)
    expected = torch.zeros(4, 3, 3, 5, dtype=torch.float64)
    for k in range(3):
        expected[:, k, k] = u[:, k].cos() * grid
    torch.testing.assert_close(A, expected.reshape(4, 3, 15))


def test_columns_follow_the_optimizer_parameter_order():
    _, p, model, batch = setup("oscillator")
    params = list(model.parameters())
    J_ref = reference(p, model, batch)
    _, A = solver_jacobian(p.physics, batch.inputs, model(batch.net_inputs))
    reordered = params[::-1]
    starts = torch.cumsum(torch.tensor([0] + [q.numel() for q in params]), 0)
    expected = torch.cat([J_ref[:, starts[i] : starts[i + 1]] for i in reversed(range(len(params)))], dim=1)
    for route in ("mlp", "generic"):
        sj = network_jacobian(model, reordered, batch.net_inputs, A, route=route)
        torch.testing.assert_close(sj.matrix(), expected, rtol=1e-10, atol=1e-13)


def test_parameters_must_be_the_models():
    _, p, model, batch = setup("toy")
    _, A = solver_jacobian(p.physics, batch.inputs, model(batch.net_inputs))
    with pytest.raises(ValueError, match="exactly the model's trainable parameters"):
        network_jacobian(model, list(model.parameters())[:-1], batch.net_inputs, A)


def test_mlp_detection():
    assert mlp_layers(nn.Sequential(nn.Linear(2, 3), nn.Tanh(), nn.Linear(3, 1))) is not None
    assert mlp_layers(nn.Sequential(nn.Linear(2, 3), nn.GELU(), nn.Linear(3, 1))) is None  # unsupported activation
    assert mlp_layers(nn.Linear(2, 3)) is None  # not a Sequential
    frozen = nn.Sequential(nn.Linear(2, 3), nn.ReLU(), nn.Linear(3, 1))
    frozen[0].bias.requires_grad_(False)
    assert mlp_layers(frozen) is None


@pytest.mark.parametrize("activation", [nn.Sigmoid, nn.Identity, nn.GELU])
def test_other_activations_and_bias_free_layers_match_torch_func(activation):
    torch.manual_seed(0)
    model = nn.Sequential(nn.Linear(3, 6), activation(), nn.Linear(6, 4, bias=False), nn.Tanh(), nn.Linear(4, 5)).double()
    physics = lambda x, u: torch.stack([(u * x).sum(1), u.pow(2).sum(1)], dim=1)  # noqa: E731
    z, x = torch.randn(4, 3, dtype=torch.float64), torch.randn(4, 5, dtype=torch.float64)
    J_ref = per_sample_jacobian(model, physics, x, z)
    _, A = solver_jacobian(physics, x, model(z))
    sj = network_jacobian(model, list(model.parameters()), z, A)
    assert isinstance(sj, GenericJacobian if activation is nn.GELU else MLPJacobian)
    torch.testing.assert_close(sj.matrix(), J_ref, rtol=1e-10, atol=1e-13)
    torch.testing.assert_close(sj.gram(), J_ref @ J_ref.T, rtol=1e-10, atol=1e-13)


@pytest.mark.parametrize("case", ["oscillator", "dipole_cnn"])
def test_graph_route_for_closures_matches_full_jacobian(case):
    _, p, model, batch = setup(case)
    params = list(model.parameters())
    u = model(batch.net_inputs)
    _, A = solver_jacobian(p.physics, batch.inputs, u)
    sj = GraphJacobian(u, params, A, torch.float64)
    J_full = full_jacobian(model, p.physics, batch.inputs, batch.net_inputs)
    torch.testing.assert_close(sj.matrix(), J_full, rtol=0, atol=1e-12 * J_full.abs().max())


def test_float32_model_gives_float64_factors_close_to_the_float32_reference():
    _, p, model, batch = setup("oscillator", 3, dtype=torch.float32)
    J_ref = reference(p, model, batch)
    _, A = solver_jacobian(p.physics, batch.inputs, model(batch.net_inputs))
    sj = network_jacobian(model, list(model.parameters()), batch.net_inputs, A, torch.float64)
    J = sj.matrix()
    assert J.dtype == torch.float64
    assert (J - J_ref.double()).abs().max() <= 1e-5 * J_ref.abs().max()


@pytest.mark.parametrize("method", SOLVER_JACOBIAN_METHODS)
def test_solver_jacobian_of_outputs_independent_of_some_or_all_of_u(method):
    u = torch.randn(3, 4, dtype=torch.float64)
    y, A = solver_jacobian(lambda v: torch.stack([2 * v[:, 0], v[:, 1] ** 2], 1), None, u, method=method)
    expected = torch.zeros(3, 2, 4, dtype=torch.float64)
    expected[:, 0, 0] = 2
    expected[:, 1, 1] = 2 * u[:, 1]
    torch.testing.assert_close(A, expected)
    y, A = solver_jacobian(lambda v: torch.ones(v.shape[0], 2, dtype=v.dtype), None, u, method=method)
    assert A.shape == (3, 2, 4) and not A.any()
