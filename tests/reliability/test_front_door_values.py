"""Bad input that passed the front door (issue 39, item 7): each is one line naming the key,
exit 2, before any directory or file is made."""

from __future__ import annotations

import pytest
from test_front_door_security import TINY, listing, refused

CASES = [
    (["tensorboard=2"], "tensorboard=2", "true or false"),
    (["progress=2"], "progress=2", "true or false"),
    (["progress=yes"], "progress=yes", "true or false"),
    (["threads=1000000000"], "threads=1000000000", "at most"),
    (["optimizer=lbfgs", "optimizer.history_size=0"], "optimizer.history_size=0", "LBFGS"),
    (["optimizer=lbfgs", "optimizer.line_search_fn=backtracking"], "optimizer.line_search_fn=backtracking", "strong_wolfe"),
    (["optimizer=adam", "+optimizer.capturable=true"], "optimizer.capturable=true", "Adam"),
    (["optimizer=adam", "+optimizer.differentiable=true"], "optimizer.differentiable=true", "Adam"),
]


@pytest.mark.parametrize(("args", "names", "why"), CASES, ids=[c[1] for c in CASES])
def test_bad_values_are_refused_before_anything_is_written(args, names, why, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    before = listing(tmp_path)
    line = refused(["problem=toy", *TINY, *args, f"hydra.run.dir={tmp_path / 'run'}"], capsys)
    assert names in line and why in line, line
    assert listing(tmp_path) == before and not (tmp_path / "run").exists()


def test_a_sweep_job_with_a_bad_switch_is_refused_up_front(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    line = refused(["-m", "problem=toy", *TINY, "optimizer.lr=0.1,0.2", "progress=2", "hydra.sweep.dir=sweep"], capsys)
    assert "progress=2" in line, line
    assert not (tmp_path / "sweep").exists()


@pytest.mark.parametrize("value", ["true", "false", "True"])
def test_switches_take_true_and_false(value):
    from higbench.config import check_bool_overrides

    check_bool_overrides([f"progress={value}", f"tensorboard={value}", "seed=2"])


def test_a_network_too_large_for_memory_is_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    args = ["problem=oscillator", "optimizer=adam", "problem.hidden=[10000000,10000000]", *TINY, "hydra.run.dir=run"]
    line = refused(args, capsys)
    assert "problem.hidden=" in line and "does not fit in memory" in line, line
    assert not (tmp_path / "run").exists()


def test_a_network_the_allocator_would_overcommit_is_refused_before_it_is_built(tmp_path, monkeypatch, capsys):
    """torch's allocator over-commits: a toy network of 10**9 hidden units was built and then
    killed by the kernel (SIGKILL, no line). Its size is estimated on the meta device first."""
    from higbench.optim import memory_guard

    monkeypatch.setattr(memory_guard, "available_bytes", lambda device="cpu": (10**6, "available memory"))
    monkeypatch.chdir(tmp_path)
    args = ["problem=toy", "optimizer=adam", "problem.hidden=10000000", *TINY, "hydra.run.dir=run"]  # 640 MB
    line = refused(args, capsys)
    assert "problem.hidden=10000000" in line and "does not fit in memory" in line and "parameters" in line, line
    assert not (tmp_path / "run").exists()
