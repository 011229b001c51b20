"""tensorboard=true: event files with the curves and per-update phase times beside the run file;
one clear line when the package is missing, before anything is written."""

import sys

import pytest
import torch
from hydra import compose, initialize_config_dir

from higbench import cli
from higbench.errors import ConfigError
from higbench.runner import train as train_mod
from higbench.runner.plan import Plan


def config(*overrides):
    with initialize_config_dir(config_dir=cli.config_dir(), version_base="1.3"):
        return compose(
            "config",
            overrides=["problem=toy", "budget.max_updates=12", "eval_unit=updates", "eval_every=4", "threads=1", "progress=false",
                       "checkpoint_every=null", *overrides],
        )  # fmt: skip


@pytest.mark.parametrize("optimizer", ["hig", "adam"])
def test_event_files_hold_curves_and_phase_times(optimizer, tmp_path):
    pytest.importorskip("tensorboard", reason="the tensorboard extra is not installed (it is in the dev extra)")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    threads = torch.get_num_threads()
    try:
        train_mod.train(Plan.for_run(config(f"optimizer={optimizer}", "tensorboard=true"), tmp_path / "run.h5"))
    finally:
        torch.set_num_threads(threads)
    acc = EventAccumulator(str(tmp_path / "tensorboard"))
    acc.Reload()
    tags = set(acc.Tags()["scalars"])
    assert {"eval/test_loss", "eval/train_loss", "update/loss", "update/jacobian_s", "update/inversion_s"} <= tags
    assert [e.step for e in acc.Scalars("eval/test_loss")] == [0, 4, 8, 12]
    assert len(acc.Scalars("update/update_s")) == 12
    assert ("update/sv_max" in tags) == (optimizer == "hig")


def test_missing_package_is_one_line_before_anything_is_written(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "torch.utils.tensorboard", None)  # import fails as if not installed
    with pytest.raises(ConfigError, match=r"needs the tensorboard package: pip install"):
        train_mod.check_build(Plan.for_run(config("optimizer=adam", "tensorboard=true"), tmp_path / "run.h5"))
    assert not list(tmp_path.iterdir())
