"""L-BFGS's history and LM's lambda are optimizer state: a run interrupted and resumed ends with
exactly the weights of the run that never stopped."""

import os
import signal

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir

from higbench import cli
from higbench.runfile.reader import load_run, load_weights
from higbench.runner import train as train_mod
from higbench.runner.plan import Plan


def config(optimizer):
    with initialize_config_dir(config_dir=cli.config_dir(), version_base="1.3"):
        return compose(
            "config",
            overrides=["problem=toy", f"optimizer={optimizer}", "batch_size=64", "budget.max_updates=8",
                       "budget.seconds=null", "eval_unit=updates", "eval_every=2", "threads=1", "progress=false",
                       "checkpoint_every=null"],
        )  # fmt: skip


@pytest.mark.parametrize("optimizer", ["lbfgs", "lm"])
def test_interrupted_and_resumed_equals_uninterrupted(optimizer, tmp_path, monkeypatch):
    threads = torch.get_num_threads()
    try:
        train_mod.train(Plan.for_run(config(optimizer), tmp_path / "a.h5"))
        real = train_mod.build_update

        def build(problem, model, opt_cfg):
            update, calls = real(problem, model, opt_cfg), {"n": 0}

            class Interrupting:
                optimizer = update.optimizer

                def __call__(self, batch):
                    calls["n"] += 1
                    if calls["n"] == 3:
                        os.kill(os.getpid(), signal.SIGINT)  # the first signal: stop after this update
                    return update(batch)

            return Interrupting()

        monkeypatch.setattr(train_mod, "build_update", build)
        stopped = train_mod.train(Plan.for_run(config(optimizer), tmp_path / "b.h5"))
        monkeypatch.setattr(train_mod, "build_update", real)
        assert stopped.status == "interrupted" and stopped.steps == 3
        resumed = train_mod.train(Plan.for_run(config(optimizer), tmp_path / "b.h5", resume=True))
    finally:
        torch.set_num_threads(threads)
    assert resumed.status == "completed" and resumed.steps == 8
    a, b = load_weights(tmp_path / "a.h5"), load_weights(tmp_path / "b.h5")
    assert all(np.array_equal(a[k], b[k]) for k in a)
    np.testing.assert_array_equal(load_run(tmp_path / "a.h5")[1]["test_loss"], load_run(tmp_path / "b.h5")[1]["test_loss"])
    # the CPU share of the resumed run counts both of its segments (the checkpoint carries the first's)
    assert load_run(tmp_path / "a.h5")[0]["env"]["cpu_segments"] == 1
    assert load_run(tmp_path / "b.h5")[0]["env"]["cpu_segments"] == 2
