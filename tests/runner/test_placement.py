"""device=auto: the measured choice of a device, recorded in the run file, with the run itself
exactly what it would be on the chosen device (the measurement draws on throwaway state)."""

import math

import h5py
import pytest
import torch
from hydra import compose, initialize_config_dir

from higbench import cli
from higbench.runfile.reader import load_weights
from higbench.runner import placement
from higbench.runner import train as train_mod
from higbench.runner.plan import Plan

CPU, CUDA = torch.device("cpu"), torch.device("cuda")


def config(*overrides):
    with initialize_config_dir(config_dir=cli.config_dir(), version_base="1.3"):
        return compose(
            "config",
            overrides=["budget.max_updates=3", "eval_unit=updates", "eval_every=3", "threads=1", "progress=false",
                       "checkpoint_every=null", "problem=oscillator", "problem.steps=8", "batch_size=8", *overrides],
        )  # fmt: skip


def test_choose_takes_the_cheaper_device_and_says_every_cost():
    device, reason = placement.choose({CPU: 0.02, CUDA: 0.005})
    assert device == CUDA
    assert reason.startswith("cuda:") and "cpu 0.02 s" in reason and "cuda 0.005 s" in reason
    device, reason = placement.choose({CPU: 0.02, CUDA: math.inf})
    assert device == CPU and "cuda cannot run" in reason


def test_choose_refuses_when_no_device_can_run():
    with pytest.raises(ValueError, match="no device could run"):
        placement.choose({CPU: math.inf, CUDA: math.inf})


def test_a_single_device_is_not_measured():
    calls = []
    placed = placement.place(lambda d: calls.append(d) or 1.0, cuda_available=False)
    assert calls == [] and placed.device == CPU and placed.reason == "cpu: the only device available"


def test_a_resumed_run_stays_where_it_started():
    assert placement.resumed({"cuda_rng": None}, cuda_available=True).device == CPU
    assert placement.resumed({"cuda_rng": torch.zeros(3)}, cuda_available=True).device == CUDA
    with pytest.raises(ValueError, match="started on a GPU"):
        placement.resumed({"cuda_rng": torch.zeros(3)}, cuda_available=False)


@pytest.mark.parametrize("optimizer", ["hig", "adam"])
def test_update_cost_is_measured_without_touching_the_run_s_random_streams(optimizer):
    cfg = config(f"optimizer={optimizer}")
    state, threads = torch.get_rng_state(), torch.get_num_threads()
    cost = train_mod._update_cost(Plan.for_run(cfg, "run.h5"), CPU)
    assert 0 < cost < 10
    assert torch.equal(torch.get_rng_state(), state) and torch.get_num_threads() == threads


def test_auto_records_its_choice_and_the_run_equals_the_one_on_that_device(tmp_path, monkeypatch):
    """Two candidates (the GPU faked as unable to run): auto measures the CPU for real, chooses it,
    records why, and trains exactly the run device=cpu trains."""
    measured, real_cost = [], train_mod._update_cost

    def cost(cfg, device):
        measured.append(device.type)
        return real_cost(cfg, device) if device.type == "cpu" else math.inf

    monkeypatch.setattr(placement, "candidates", lambda cuda_available=None: [CPU, CUDA])
    monkeypatch.setattr(train_mod, "_update_cost", cost)
    threads = torch.get_num_threads()
    try:
        train_mod.train(Plan.for_run(config("device=auto"), tmp_path / "auto.h5"))
        train_mod.train(Plan.for_run(config("device=cpu"), tmp_path / "cpu.h5"))
    finally:
        torch.set_num_threads(threads)
    assert measured == ["cpu", "cuda"]
    a, b = load_weights(tmp_path / "auto.h5"), load_weights(tmp_path / "cpu.h5")
    assert all((a[k] == b[k]).all() for k in a), "measuring must not move the RNG or the data order"
    with h5py.File(tmp_path / "auto.h5") as f:
        env = f["env"].attrs
        assert env["device"] == "cpu" and env["device_requested"] == "auto"
        assert env["device_reason"].startswith("cpu: least time per update") and "cuda cannot run" in env["device_reason"]
        assert env["placement_s"] > 0
    with h5py.File(tmp_path / "cpu.h5") as f:
        assert "device_reason" not in f["env"].attrs


def test_devices_benchmark_says_where_cuda_is_later():
    from higbench.bench.devices import verdicts
    from higbench.results.index import threshold_column

    t0, t1, t2 = threshold_column(1e0), threshold_column(1e-1), threshold_column(1e-2)
    rows = [
        {"problem": "p", "device": "cuda", t0: 3.002, t1: 4.0, t2: float("nan")},
        {"problem": "p", "device": "cpu", t0: 3.001, t1: 3.0, t2: 5.0},
    ]
    assert verdicts(rows) == [
        "p 1: cuda 3.0 s, cpu 3.0 s: no later",  # the same scheduled evaluation
        "p 0.1: cuda 4.0 s, cpu 3.0 s: LATER",
        "p 0.01: cuda not reached, cpu 5.0 s: LATER",
    ]
