"""The solvers compile before the training clock starts (numba: compile or cache load), the
time is recorded apart as /env warmup_s, and the run is exactly the one without it."""

import h5py
import pytest
import torch
from hydra import compose, initialize_config_dir

from higbench import cli
from higbench.runfile.reader import load_weights
from higbench.runner import train as train_mod
from higbench.runner import warmup
from higbench.runner.plan import Plan


def config(*overrides):
    with initialize_config_dir(config_dir=cli.config_dir(), version_base="1.3"):
        return compose(
            "config",
            overrides=["budget.max_updates=3", "eval_unit=updates", "eval_every=3", "threads=1", "progress=false",
                       "checkpoint_every=null", *overrides],
        )  # fmt: skip


@pytest.mark.parametrize("optimizer", ["hig", "adam"])
def test_warm_up_changes_nothing_but_is_recorded(optimizer, tmp_path, monkeypatch):
    cfg = config("problem=oscillator", "problem.steps=8", "batch_size=8", f"optimizer={optimizer}")
    threads = torch.get_num_threads()
    try:
        train_mod.train(Plan.for_run(cfg, tmp_path / "a.h5"))
        monkeypatch.setattr(train_mod, "warm_up", lambda problem, model, jacobian: 0.0)
        train_mod.train(Plan.for_run(cfg, tmp_path / "b.h5"))
    finally:
        torch.set_num_threads(threads)
    a, b = load_weights(tmp_path / "a.h5"), load_weights(tmp_path / "b.h5")
    assert all((a[k] == b[k]).all() for k in a), "the warm-up must not move the RNG or the data order"
    with h5py.File(tmp_path / "a.h5") as f:
        assert f["env"].attrs["warmup_s"] > 0


def test_warm_up_calls_the_solver_each_way(monkeypatch):
    from higbench.problems.base import build_problem

    cfg = config("problem=oscillator", "problem.steps=8")
    problem = build_problem(cfg.problem, dtype=torch.float32, device=torch.device("cpu"), seed=0)
    calls = []
    real = warmup.solver_jacobian
    monkeypatch.setattr(warmup, "solver_jacobian", lambda *a: calls.append("jacobian") or real(*a))
    state = torch.get_rng_state()
    assert warmup.warm_up(problem, problem.build_model(), jacobian=True) > 0
    assert calls == ["jacobian"] and torch.equal(torch.get_rng_state(), state)
