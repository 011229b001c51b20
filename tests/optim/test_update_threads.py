"""The optimizers' own thread default: a small HIG update runs on one thread in user code
(torch's default count collapses on a shared machine), torch's count is restored after it,
and the runner, which sets the threads itself, turns it off."""

from __future__ import annotations

import pytest
import torch

from higbench.optim import HIG
from higbench.optim.threads import PARALLEL_MIN_ROWS, update_threads


@pytest.fixture
def two_threads():
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(before)


def _threads_seen(threads, updates=3, b=8, n_y=4):
    """torch's thread count inside the physics, per update."""
    seen = []

    def physics(x, u):
        seen.append(torch.get_num_threads())
        return u * x

    torch.manual_seed(0)
    model = torch.nn.Sequential(torch.nn.Linear(2, 8), torch.nn.Tanh(), torch.nn.Linear(8, n_y))
    opt = HIG(model.parameters(), threads=threads)
    z, x = torch.randn(b, 2), torch.randn(b, n_y)
    for _ in range(updates):
        opt.step_structured(model, z, physics=physics, inputs=x, loss=lambda y: (y**2).sum(1))
        assert torch.get_num_threads() == 2  # restored after every update
    return seen


def test_auto_runs_a_small_update_on_one_thread(two_threads):
    # 32 Gram rows: the first update does not know them yet, the later ones run on 1 thread
    assert _threads_seen("auto")[-1] == 1
    assert set(_threads_seen(None)) == {2}  # None: torch's count as it is
    assert _threads_seen(1)[-1] == 1


def test_a_large_update_keeps_the_threads_it_has(two_threads):
    with update_threads("auto", PARALLEL_MIN_ROWS):
        assert torch.get_num_threads() == 2
    with update_threads("auto", PARALLEL_MIN_ROWS - 1):
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == 2


def test_bad_threads_are_refused():
    for bad in ("many", 0, True, 1.5):
        with pytest.raises(ValueError, match="threads="):
            HIG([torch.nn.Parameter(torch.zeros(2))], threads=bad)


def test_the_runner_sets_the_threads_itself():
    from omegaconf import OmegaConf

    from higbench.problems.toy import Toy
    from higbench.runner.updates import build_update

    model = torch.nn.Linear(2, 2)
    cfg = OmegaConf.create({"_target_": "higbench.optim.HIG", "name": "hig", "lr": 1.0})
    problem = Toy.__new__(Toy)  # build_update only reads the class
    assert build_update(problem, model, cfg).optimizer.threads is None
