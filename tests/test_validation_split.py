"""The validation split: every problem draws one, disjoint from train and test, after them
(the train and test draws of every earlier run stay as they were), and the run file records
its loss as the curve ``val_loss``; the keys that judge a problem do not change a run's identity."""

from __future__ import annotations

import copy

import pytest
import torch
from cases import PROBLEM_CONFIGS
from omegaconf import OmegaConf

from higbench.problems.base import build_problem

PROBLEMS = PROBLEM_CONFIGS


def problem_node(name: str, **changes) -> dict:
    from higbench.jobs import compose, hydra_conf

    with hydra_conf():
        node = copy.deepcopy(compose((f"problem={name}",))["problem"])
    node.update(changes)
    if name == "poisson":
        node["test_size"] = 64  # small sets: the split's rule does not depend on their size
    return node


def build(node: dict):
    return build_problem(OmegaConf.create(node), dtype=torch.float64, device=torch.device("cpu"), seed=0)


@pytest.mark.parametrize("name", PROBLEMS)
def test_validation_set_is_disjoint_and_leaves_train_and_test_unchanged(name):
    node = problem_node(name)
    assert node["val_size"] > 0, f"conf/problem/{name}.yaml sets no validation split"
    with_val, without = build({**node, "val_size": 16}), build({**node, "val_size": 0})
    assert without.val_set() is None and len(with_val.val_set()) == 16
    torch.testing.assert_close(with_val.test_set().net_inputs, without.test_set().net_inputs, rtol=0, atol=0)
    if hasattr(without, "train"):
        torch.testing.assert_close(with_val.train.net_inputs, without.train.net_inputs, rtol=0, atol=0)
        seen = torch.cat([with_val.train.net_inputs, with_val.test_set().net_inputs])
    else:  # Poisson: training samples come from the run seed's stream, the test set from data_seed's
        seen = with_val.test_set().net_inputs
    val = with_val.val_set().net_inputs
    distance = torch.cdist(val, seen).min(dim=1).values
    assert (distance > 0).all(), "a validation sample is also a training or test sample"


@pytest.mark.parametrize("name", PROBLEMS)
def test_each_problem_declares_its_targets_budget_and_held_out_variants(name):
    node = problem_node(name)
    assert node["targets"] and all(t > 0 for t in node["targets"])
    assert node["league_seconds"] > 0
    assert node["held_out"] and all("=" in v for v in node["held_out"])


def test_judging_keys_do_not_change_a_runs_identity():
    from higbench.results.index import config_id

    node = problem_node("toy")
    bare = {k: v for k, v in node.items() if k not in ("val_size", "targets", "league_seconds", "held_out")}
    assert config_id({"problem": node, "seed": 0}) == config_id({"problem": bare, "seed": 0})
    assert config_id({"problem": {**node, "gamma": 0.5}, "seed": 0}) != config_id({"problem": node, "seed": 0})


def test_run_file_records_the_validation_loss(tmp_path):
    from synthetic import short_run

    from higbench.runfile.reader import load_run

    path = short_run(tmp_path, "adam", updates=4, eval_every=2)
    curves = load_run(path)[1]
    assert "val_loss" in curves and len(curves["val_loss"]) == len(curves["test_loss"]) == 3
    assert (curves["val_loss"] != curves["test_loss"]).all()  # another data set, not a copy
