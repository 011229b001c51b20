"""The run file records the final evaluation's test loss sample by sample (/final/test_losses):
their mean is the curve's last test loss, so a median or a percentile of the same evaluation
can be read without training again. A problem's large fresh draw (``problem.fresh_test_size``)
is evaluated once at the end (/final/fresh_test_losses)."""

import numpy as np
import torch
from hydra import compose, initialize_config_dir

from higbench.config import config_dir
from higbench.results.index import read_run_summary
from higbench.runfile.reader import load_final, load_run
from higbench.runner import train as train_mod
from higbench.runner.plan import Plan


def config(*overrides):
    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        return compose(
            "config",
            overrides=["problem=toy", "optimizer=adam", "budget.max_updates=5", "budget.seconds=null", "eval_unit=updates",
                       "eval_every=2", "threads=1", "progress=false", "checkpoint_every=null", *overrides],
        )  # fmt: skip


def test_final_per_sample_losses_average_to_the_last_test_loss(tmp_path):
    threads = torch.get_num_threads()
    try:
        train_mod.train(Plan.for_run(config("problem.test_size=300"), tmp_path / "run.h5"))
    finally:
        torch.set_num_threads(threads)
    final = load_final(tmp_path / "run.h5")
    _meta, curves = load_run(tmp_path / "run.h5")
    losses = final["test_losses"]
    assert losses.shape == (300,) and losses.dtype == np.float64 and (losses >= 0).all()
    assert np.isclose(losses.mean(), curves["test_loss"].iloc[-1], rtol=1e-12, atol=0)
    assert losses.std() > 0  # one value per sample, not the mean repeated
    row, _ = read_run_summary(tmp_path / "run.h5")  # the index's robust view of the same evaluation
    assert row["final_test_median"] == np.median(losses) and row["final_test_p95"] == np.percentile(losses, 95)


def test_the_fresh_draw_is_evaluated_once_at_the_end(tmp_path):
    threads = torch.get_num_threads()
    try:
        train_mod.train(Plan.for_run(config("problem.test_size=300", "+problem.fresh_test_size=2000"), tmp_path / "run.h5"))
    finally:
        torch.set_num_threads(threads)
    final = load_final(tmp_path / "run.h5")
    fresh, test = final["fresh_test_losses"], final["test_losses"]
    assert fresh.shape == (2000,) and (fresh >= 0).all() and fresh.std() > 0
    assert not np.isin(fresh[:300], test).all()  # another draw, not the test set again
    row, _ = read_run_summary(tmp_path / "run.h5")
    assert row["final_fresh_mean"] == fresh.mean()
    assert not np.isclose(row["final_fresh_mean"], row["final_test_loss"], rtol=1e-6)


def test_the_fresh_draw_leaves_every_other_set_as_it_was():
    """Drawn after train, test and validation from the same generator, so runs made before the key
    existed keep their data; the same data_seed gives the same fresh draw."""
    from omegaconf import OmegaConf

    from higbench.problems.base import registry

    def problem(**extra):
        cfg = OmegaConf.merge(config("problem=oscillator").problem, extra)
        return registry()["oscillator"](cfg, torch.float32, torch.device("cpu"), seed=0)

    plain, with_fresh = problem(fresh_test_size=0), problem(fresh_test_size=64)
    for name in ("train", "test", "val"):
        assert torch.equal(getattr(plain, name).inputs, getattr(with_fresh, name).inputs)
    assert plain.fresh_test_set() is None
    a, b = with_fresh.fresh_test_set(), problem(fresh_test_size=64).fresh_test_set()
    assert len(a) == 64 and torch.equal(a.inputs, b.inputs)
    assert not torch.equal(a.inputs, with_fresh.test.inputs[:64])
    other = problem(fresh_test_size=64, data_seed=1).fresh_test_set()
    assert not torch.equal(a.inputs, other.inputs)


def test_a_run_without_a_final_evaluation_has_no_final_record(tmp_path, monkeypatch):
    import signal

    from higbench.runner.train import StopSignals

    original = StopSignals.check

    def stop_now(self):  # as a SIGTERM before the first update: interrupted, no final evaluation
        self.signum = signal.SIGTERM
        original(self)

    monkeypatch.setattr(StopSignals, "check", stop_now)
    threads = torch.get_num_threads()
    try:
        summary = train_mod.train(Plan.for_run(config(), tmp_path / "run.h5"))
    finally:
        torch.set_num_threads(threads)
    assert summary.status == "interrupted"
    assert load_final(tmp_path / "run.h5") == {}


def test_a_run_resumed_with_nothing_left_records_its_last_evaluation_per_sample(tmp_path, monkeypatch):
    """Stopped right after an evaluation, resumed with a budget it already met: no evaluation in
    the resuming process, so the per-sample record is computed from the restored network."""
    import signal

    from higbench.runner.train import StopSignals

    original, turns = StopSignals.check, {"n": 0}

    def stop_at_third(self):
        turns["n"] += 1
        if turns["n"] == 3:  # after 2 updates, each evaluated (eval_every=1 update)
            self.signum = signal.SIGTERM
        original(self)

    threads = torch.get_num_threads()
    try:
        with monkeypatch.context() as m:
            m.setattr(StopSignals, "check", stop_at_third)
            stopped = train_mod.train(Plan.for_run(config("eval_every=1", "checkpoint_every=1000"), tmp_path / "run.h5"))
        assert stopped.status == "interrupted" and stopped.steps == 2
        resumed = train_mod.train(Plan.for_run(config("eval_every=1", "budget.max_updates=2"), tmp_path / "run.h5", resume=True))
    finally:
        torch.set_num_threads(threads)
    assert resumed.status == "completed" and resumed.steps == 2
    _meta, curves = load_run(tmp_path / "run.h5")
    losses = load_final(tmp_path / "run.h5")["test_losses"]
    assert list(curves["step"]) == [0, 1, 2]  # nothing evaluated again on resume
    assert np.isclose(losses.mean(), curves["test_loss"].iloc[-1], rtol=1e-12, atol=0)
