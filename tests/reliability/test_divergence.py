"""Divergence: NaN/inf anywhere ends the run as `diverged` (step, reason), keeps what was
logged and returns normally. (A real divergence through the CLI, its exit code 0 and the
index never ranking it best: test_concurrent.py.)"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir
from rel_helpers import FAST

from higbench import cli
from higbench.optim import hig as hig_mod  # the GN/HIG step the runner calls
from higbench.runfile.reader import load_run, load_updates, load_weights
from higbench.runner import train as train_mod
from higbench.runner.plan import Plan
from higbench.runner.updates import UpdateResult

BASE = ["budget.seconds=20", "budget.max_updates=40", "eval_unit=updates", "eval_every=3", "checkpoint_every=null", *FAST]


def config(*overrides):
    with initialize_config_dir(config_dir=cli.config_dir(), version_base="1.3"):
        return compose("config", overrides=[*BASE, *overrides])


@pytest.fixture(autouse=True)
def one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def fail_after(n_ok: int, make_failure):
    """A build_update wrapper whose update works n_ok times, then fails as make_failure says."""
    real = train_mod.build_update

    def build(problem, model, opt_cfg):
        update = real(problem, model, opt_cfg)
        calls = {"n": 0}

        class Wrapped:
            optimizer = update.optimizer

            def __call__(self, batch):
                calls["n"] += 1
                if calls["n"] > n_ok:
                    return make_failure(update, batch)
                return update(batch)

        return Wrapped()

    return build


def assert_diverged(path, step, reason_part):
    meta, curves = load_run(path)
    assert meta["status"] == "diverged", meta["status"]
    assert meta["status_step"] == step, (meta["status_step"], step)
    assert reason_part in meta["status_reason"], meta["status_reason"]
    assert meta["steps"] == step
    # everything logged before the divergence is there, one curve row per step
    assert len(curves) >= 2 and curves["step"].is_monotonic_increasing and curves["step"].is_unique
    assert curves["step"].iloc[-1] == step
    updates = load_updates(path)
    assert list(updates["step"]) == list(range(1, step)), "per-update rows up to the failed update"
    assert np.isfinite(updates["loss"]).all()
    assert all(np.isfinite(w).all() for w in load_weights(path).values()), "the failed update must not be applied"
    return meta, curves


@pytest.mark.parametrize(
    "optimizer,failure,reason",
    [
        (
            "hig",
            lambda u, b: UpdateResult(0.5, finite=False, reason="inversion failed: SVD did not converge"),
            "inversion failed",
        ),
        ("hig", lambda u, b: UpdateResult(float("nan"), finite=False, reason="non-finite loss"), "non-finite loss"),
        ("adam", lambda u, b: UpdateResult(float("inf"), {}), "non-finite loss"),
        (
            "gn",
            lambda u, b: (_ for _ in ()).throw(torch.linalg.LinAlgError("linalg.svd: The algorithm failed to converge")),
            "linear algebra failed",
        ),
    ],
    ids=["inversion-failed", "nan-loss-hig", "inf-loss-adam", "svd-raises"],
)
def test_forced_failure_marks_run_diverged(optimizer, failure, reason, tmp_path, monkeypatch):
    monkeypatch.setattr(train_mod, "build_update", fail_after(7, failure))
    summary = train_mod.train(Plan.for_run(config(f"optimizer={optimizer}"), tmp_path / "run.h5"))
    assert summary.status == "diverged" and summary.steps == 8
    assert_diverged(tmp_path / "run.h5", 8, reason)


@pytest.mark.parametrize("mode", ["naive", "structured"])
def test_nan_jacobian_is_caught(mode, tmp_path, monkeypatch):
    cfg = config("optimizer=gn")
    if "jacobian" not in cfg.optimizer:
        if mode == "structured":
            pytest.skip("no structured Jacobian in this optimizer")
    else:
        cfg.optimizer.jacobian = mode
    calls = {"n": 0}
    if mode == "naive":
        real = hig_mod.per_sample_jacobian

        def jacobian(*args, **kwargs):
            calls["n"] += 1
            J = real(*args, **kwargs)
            return J if calls["n"] <= 5 else J * float("nan")

        monkeypatch.setattr(hig_mod, "per_sample_jacobian", jacobian)
    else:
        real = hig_mod.solver_jacobian

        def jacobian(*args, **kwargs):
            calls["n"] += 1
            y, A = real(*args, **kwargs)
            return (y, A) if calls["n"] <= 5 else (y, A * float("nan"))

        monkeypatch.setattr(hig_mod, "solver_jacobian", jacobian)
    train_mod.train(Plan.for_run(cfg, tmp_path / "run.h5"))
    assert_diverged(tmp_path / "run.h5", 6, "non-finite Jacobian")


def test_nan_gradient_is_caught(tmp_path, monkeypatch):
    real = train_mod.build_update

    def build(problem, model, opt_cfg):
        calls = {"n": 0}

        def poison(grad):  # the 4th update's backward pass yields a NaN gradient (finite loss);
            calls["n"] += 1  # the first pass is the warm-up's, through the run's own network
            return grad * float("nan") if calls["n"] == 5 else grad

        next(model.parameters()).register_hook(poison)
        return real(problem, model, opt_cfg)

    monkeypatch.setattr(train_mod, "build_update", build)
    train_mod.train(Plan.for_run(config("optimizer=adam"), tmp_path / "run.h5"))
    assert_diverged(tmp_path / "run.h5", 4, "non-finite gradient")
