"""Each problem: exact parameter counts, data as specified, physics shapes, loss values."""

import math

import pytest
import torch
from cases import FIXED_DATA_PROBLEMS, PROBLEM_CONFIGS
from hydra import compose, initialize_config_dir

from higbench.config import config_dir
from higbench.problems import build_problem
from higbench.problems.networks import count_parameters

PARAMETER_COUNTS = {"toy": 30, "oscillator": 2956, "poisson": 41408, "dipole": 9484, "dipole_cnn": 21984}


def compose_cfg(*overrides):
    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides))


def make(problem, *overrides, dtype=torch.float64):
    cfg = compose_cfg(f"problem={problem}", *overrides)
    return build_problem(cfg.problem, dtype=dtype, device=torch.device("cpu"), seed=0), cfg


def test_every_problem_config_has_its_facts_here():
    """A new problem (tests/cases.py finds it in conf/problem/) states its sizes below, and its
    short-horizon case for the optimizer tests (tests/optim/optim_helpers.py)."""
    from optim.optim_helpers import CASES

    assert sorted(PARAMETER_COUNTS) == PROBLEM_CONFIGS and sorted(OUTPUT_SIZES) == PROBLEM_CONFIGS
    assert sorted(CASES) == PROBLEM_CONFIGS


@pytest.mark.parametrize("problem,count", PARAMETER_COUNTS.items())
def test_parameter_counts(problem, count):
    p, _ = make(problem)
    assert count_parameters(p.build_model()) == count


def test_dipole_model_switch_by_key():
    p, _ = make("dipole", "problem.model=cnn")
    assert count_parameters(p.build_model()) == 21984


OUTPUT_SIZES = {"toy": 2, "oscillator": 4, "poisson": 64, "dipole": 28, "dipole_cnn": 28}


@pytest.mark.parametrize("problem,y_size", OUTPUT_SIZES.items())
def test_outputs_and_loss_shapes(problem, y_size):
    p, cfg = make(problem)
    model = p.build_model()
    batch = next(p.epoch(4, torch.Generator().manual_seed(0)))
    y = p.outputs(model, batch)
    assert y.shape == (4, y_size)
    loss = p.loss(y, batch.targets)
    assert loss.shape == (4,) and torch.isfinite(loss).all() and (loss >= 0).all()


def test_toy_data_and_loss():
    p, _ = make("toy", "problem.gamma=0.01")
    x = p.train.net_inputs
    assert x.shape == (1024, 1) and x.min() >= -1 and x.max() <= 1
    assert torch.allclose(p.train.targets, torch.cat([torch.sin(6 * x), torch.cos(9 * x)], 1))
    # y = (u1, gamma*u2); loss = 1/2 (y1 - yhat1)^2 + 1/2 (gamma u2 - yhat2)^2
    u = torch.tensor([[1.0, 100.0]], dtype=torch.float64)
    y = p.physics(None, u)
    assert torch.allclose(y, torch.tensor([[1.0, 1.0]], dtype=torch.float64))
    assert math.isclose(p.loss(y, torch.tensor([[0.0, 0.0]], dtype=torch.float64)).item(), 1.0)


def test_toy_eval_logs_have_fixed_shapes():
    p, _ = make("toy")
    logs = p.eval_logs(p.build_model())
    assert logs["neuron_mean"].shape == (7,) and logs["neuron_std"].shape == (7,)
    assert (logs["neuron_std"] > 0).all() and (abs(logs["neuron_mean"]) <= 1).all()
    assert logs["probe_output"].shape == (2,)


def test_oscillator_data_and_zero_loss_at_target():
    p, _ = make("oscillator")
    assert p.train.inputs.shape == (4096, 4) and p.test.inputs.shape == (4096, 4)
    assert p.train.inputs.min() >= 0 and p.train.inputs.max() < 1
    assert torch.equal(p.train.targets, p.train.inputs)
    assert not torch.equal(p.train.inputs[:10], p.test.inputs[:10])
    assert p.loss(p.train.targets[:5], p.train.targets[:5]).abs().max() == 0


def test_poisson_targets_are_laplace_of_a_zero_mean_field():
    p, _ = make("poisson")
    batch = next(p.epoch(8, torch.Generator().manual_seed(1)))
    assert batch.targets.shape == (8, 64)
    # An exact solution phi_gt exists: solving L phi = rho and applying the physics gives rho back.
    from higbench.physics.poisson import laplace_matrix

    L = laplace_matrix(8, 8, dtype=torch.float64)
    phi = torch.linalg.solve(L, batch.targets.T).T
    assert torch.allclose(p.physics(None, phi), batch.targets, atol=1e-10)
    assert p.loss(p.physics(None, phi), batch.targets).max() < 1e-18
    # Fresh samples every batch (infinite data), a fixed evaluation set.
    again = next(p.epoch(8, torch.Generator().manual_seed(2)))
    assert not torch.allclose(batch.targets, again.targets)


def test_dipole_targets_are_normalised_superpositions_of_phi2_phi3():
    from higbench.physics.dipole import eigenstate, overlap

    p, _ = make("dipole")
    t = p.train.targets.reshape(-1, 14, 2)
    a = overlap(eigenstate(2).expand_as(t), t).real
    b = overlap(eigenstate(3).expand_as(t), t).real
    assert torch.allclose(a**2 + b**2, torch.ones_like(a), atol=1e-12)
    assert p.train.targets.shape == (1024, 28) and p.test.targets.shape == (1024, 28)
    # Perfect control has zero loss and zero low/high-energy losses.
    perfect = p.loss(p.train.targets[:3], p.train.targets[:3])
    assert perfect.abs().max() < 1e-12
    m = p.metrics(p.train.targets[:3], p.train[:3])
    assert set(m) == {"low_energy_loss", "high_energy_loss"} and max(v.abs().max() for v in m.values()) < 1e-12


@pytest.mark.parametrize("problem", FIXED_DATA_PROBLEMS)
def test_data_is_seeded(problem):
    a, _ = make(problem)
    b, _ = make(problem)
    c, _ = make(problem, "problem.data_seed=1")
    assert torch.equal(a.train.targets, b.train.targets)
    assert not torch.equal(a.train.targets, c.train.targets)


def test_glorot_initialisation_is_default_and_biases_are_zero():
    p, _ = make("oscillator")
    model = p.build_model()
    lin = model[0]
    bound = math.sqrt(6 / (lin.in_features + lin.out_features))
    assert lin.bias.abs().max() == 0 and lin.weight.abs().max() <= bound
    q, _ = make("oscillator", "problem.init=torch")
    assert q.build_model()[0].bias.abs().max() > 0


@pytest.mark.parametrize("problem", FIXED_DATA_PROBLEMS)
def test_train_then_test_from_one_data_seed_generator(problem):
    """sample_datasets draws train first, then test, from one generator: the order the
    published runs were made with (swapping it, or a second generator, changes the data)."""
    p, cfg = make(problem)
    gen = torch.Generator().manual_seed(int(cfg.problem.data_seed))
    train = p._sample(int(cfg.problem.train_size), gen)
    test = p._sample(int(cfg.problem.test_size), gen)
    assert torch.equal(p.train.targets, train.targets) and torch.equal(p.test.targets, test.targets)
    assert not torch.equal(p.test.targets[: len(train)], train.targets[: len(p.test)])
