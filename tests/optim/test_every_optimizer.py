"""Every optimizer config (conf/optimizer/*.yaml) trains every problem; the split optimizer and the extras.

Parametrized from the config folder, so a new YAML is tested without editing this file:
each takes a few updates on each problem (a tiny batch, in the process), and a few through
the CLI on the toy. ``SplitOptimizer`` (Muon for the matrices, AdamW for the rest) is
checked against the two torch optimizers run apart on the same gradients.
"""

from __future__ import annotations

import copy
import functools
import math
import sys
from pathlib import Path

import pytest
import torch
from cases import OPTIMIZERS
from omegaconf import OmegaConf
from optim_helpers import CASES, compose_cfg, flat, setup

from higbench.optim.contract import needs_inverse_simulator, uses_jacobian
from higbench.optim.split import SplitOptimizer
from higbench.runner.updates import build_update
from higbench.schema import locate

CONF = Path(__file__).resolve().parents[2] / "conf" / "optimizer"
CLASSES = {n: locate(OmegaConf.load(CONF / f"{n}.yaml")._target_) for n in OPTIMIZERS}
NEEDS_INVERSE = {n for n, cls in CLASSES.items() if needs_inverse_simulator(cls)}
WITH_INVERSE = {"toy", "poisson"}
# GN, HIG, LM: their own tests take them through every problem, against references (test_update_paths.py, test_lm.py).
JACOBIAN_POWER = {n for n, cls in CLASSES.items() if uses_jacobian(cls)}


def test_the_new_optimizers_are_configs():
    assert {"adamw", "muon", "soap", "shampoo", "sip"} <= set(OPTIMIZERS) and NEEDS_INVERSE == {"sip"}
    assert JACOBIAN_POWER == {"gn", "hig", "lm"}


# The torch.optim configs that came before these tests: also through every problem in
# test_cli.py (adam) and their own files (lbfgs); here only with `make test-slow`.
EARLIER = {"adadelta", "adagrad", "adam", "lbfgs", "rmsprop", "sgd"}
SMALL = {"poisson": ("problem.hidden=[16]",)}  # Shampoo's and SOAP's preconditioners on 256x64 take seconds


@functools.cache
def problem_and_batch(case: str):
    """Built once per problem (the data sets take most of the time); each test builds its own network."""
    _, problem, _, batch = setup(case, 8, *SMALL.get(case, ()), optimizer="adam")
    return problem, batch


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize(
    "optimizer",
    [pytest.param(n, marks=pytest.mark.slow) if n in EARLIER else n for n in OPTIMIZERS if n not in JACOBIAN_POWER],
)
def test_every_optimizer_takes_finite_updates_on_every_problem(optimizer, case):
    if optimizer in NEEDS_INVERSE and CASES[case][0] not in WITH_INVERSE:
        pytest.skip("no inverse simulator: refused before any work (test_sip.py)")
    problem, batch = problem_and_batch(case)
    model = problem.build_model()
    name, extra = CASES[case]
    update = build_update(problem, model, compose_cfg(name, *extra, *SMALL.get(case, ()), optimizer=optimizer).optimizer)
    before = flat(model)
    results = [update(batch) for _ in range(2)]
    assert all(r.finite and math.isfinite(r.loss) for r in results), results
    assert torch.isfinite(flat(model)).all() and not torch.equal(flat(model), before)


@pytest.mark.parametrize("optimizer", OPTIMIZERS)
def test_every_optimizer_trains_the_toy_from_the_cli(higbench, tmp_path, optimizer):
    code, out, err = higbench("problem=toy", f"optimizer={optimizer}", "batch_size=16")
    assert code == 0, err
    assert f"completed: toy/{optimizer} 3 updates" in out + err


def test_help_lists_the_new_optimizers(higbench):
    code, out, _ = higbench("--help", tiny=False)
    assert code == 0
    for name in ("adamw", "muon", "soap", "shampoo", "sip"):
        assert f" {name} " in out.replace("\n", " \n"), name


# -- SplitOptimizer -----------------------------------------------------------------------------

MUON = {"_target_": "torch.optim.Muon", "lr": 0.02, "adjust_lr_fn": "match_rms_adamw"}
ADAMW = {"_target_": "torch.optim.AdamW", "lr": 0.01}


def net():
    torch.manual_seed(0)
    return torch.nn.Sequential(torch.nn.Linear(3, 5), torch.nn.Tanh(), torch.nn.Linear(5, 2))


def test_split_is_muon_on_the_matrices_and_adamw_on_the_rest():
    x = torch.randn(16, 3)
    split_model, ref_model = net(), net()
    split = SplitOptimizer(split_model.parameters(), parts={"matrices": MUON, "rest": ADAMW})
    matrices = [p for p in ref_model.parameters() if p.ndim == 2]
    rest = [p for p in ref_model.parameters() if p.ndim != 2]
    assert [p.shape for p in split.parts["matrices"].param_groups[0]["params"]] == [p.shape for p in matrices]
    muon = torch.optim.Muon(matrices, lr=0.02, adjust_lr_fn="match_rms_adamw")
    adamw = torch.optim.AdamW(rest, lr=0.01)
    calls = []

    def closure(model):
        def run():
            calls.append(1)
            for p in model.parameters():
                p.grad = None
            loss = (model(x) ** 2).mean()
            loss.backward()
            return loss

        return run

    for _ in range(3):
        split.step(closure(split_model))
        closure(ref_model)()
        muon.step()
        adamw.step()
    assert len(calls) == 6  # one closure call per split step
    for a, b in zip(split_model.parameters(), ref_model.parameters()):
        torch.testing.assert_close(a, b)
    assert len(split.param_groups) == 2 and split.param_groups[0]["lr"] == 0.02  # the parts' groups


def test_split_state_round_trips():
    model = net()
    split = SplitOptimizer(model.parameters(), parts={"matrices": MUON, "rest": ADAMW})
    model(torch.randn(4, 3)).sum().backward()
    split.step()
    twin = SplitOptimizer(net().parameters(), parts={"matrices": MUON, "rest": ADAMW})
    twin.load_state_dict(copy.deepcopy(split.state_dict()))
    assert set(twin.state_dict()) == {"matrices", "rest"}
    with pytest.raises(ValueError, match="state of parts"):
        twin.load_state_dict({"rest": split.state_dict()["rest"]})


@pytest.mark.parametrize(
    "parts,message",
    [
        ({"matrices": MUON}, r"no rule takes the parameters of shapes \[\(2,\), \(5,\)\]; add a `rest` part"),
        ({"weights": MUON}, "parts.weights: unknown rule; valid rules: matrices, hidden_matrices, vectors, rest"),
        ({"matrices": {**MUON, "lr": -1.0}, "rest": ADAMW}, "parts.matrices: torch.optim.Muon refuses its arguments"),
        ({"matrices": {"lr": 1.0}, "rest": ADAMW}, "parts.matrices=.*must be a mapping with a _target_"),
    ],
)
def test_split_refuses_bad_parts(parts, message):
    with pytest.raises(ValueError, match=message):
        SplitOptimizer(net().parameters(), parts=parts)


def test_a_part_without_parameters_still_checks_its_arguments():
    """The config check builds the optimizer on one 1-D dummy parameter: Muon's part is empty there."""
    with pytest.raises(ValueError, match="parts.matrices: torch.optim.Muon refuses"):
        SplitOptimizer([torch.nn.Parameter(torch.zeros(1))], parts={"matrices": {**MUON, "lr": -1.0}, "rest": ADAMW})


def test_a_bad_part_value_is_one_line(higbench, tmp_path):
    code, _, err = higbench("problem=toy", "optimizer=muon", "optimizer.parts.hidden_matrices.lr=-1")
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "parts.hidden_matrices: torch.optim.Muon refuses its arguments" in err
    assert sorted(tmp_path.rglob("*")) == []


# -- an optimizer from an optional extra ------------------------------------------------------


@pytest.mark.parametrize("optimizer", ["soap", "shampoo"])
def test_a_missing_extra_names_the_pip_install(higbench, monkeypatch, tmp_path, optimizer):
    monkeypatch.setitem(sys.modules, "pytorch_optimizer", None)  # as if the extra were not installed
    code, _, err = higbench("problem=toy", f"optimizer={optimizer}")
    target = OmegaConf.load(CONF / f"{optimizer}.yaml")._target_
    expected = f'higbench: error: optimizer={optimizer}: {target} comes with the optimizers extra: pip install -e ".[optimizers]"'
    assert code == 2 and err.strip() == expected, err
    assert sorted(tmp_path.rglob("*")) == []
