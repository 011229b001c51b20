"""Bad input found by the fourth adversarial pass, each one line naming key and value (exit 2)
before any work: a value of the wrong kind (a mapping for a list), sizes beyond memory, an
argument a ``**kwargs`` optimizer would swallow, the Krylov route's true size."""

from __future__ import annotations

import pytest
from rel_helpers import refused

from higbench import cli
from higbench.errors import ConfigError

TINY = ["budget.max_updates=3", "budget.seconds=null", "eval_unit=updates", "eval_every=1", "progress=false", "threads=1"]


def count_app_runs(monkeypatch, limit: int = 5) -> dict:
    """Count runs of Hydra's app; past ``limit`` for one command line it is looping: fail."""
    runs = {"n": 0}
    real = cli._hydra_main

    def counted():
        runs["n"] += 1
        if runs["n"] > limit:
            raise AssertionError(f"Hydra's app ran {runs['n']} times for one command line: the retry loops")
        return real()

    monkeypatch.setattr(cli, "_hydra_main", counted)
    return runs


# -- the retry path (``cli._run_app``) ------------------------------------------------------


@pytest.mark.parametrize(
    "override",
    ["problem.held_out={a:1}", "problem.targets={a:1}", "optimizer.betas={a:1}"],
)
def test_a_mapping_for_a_list_is_one_line_not_an_endless_retry(override, tmp_path, monkeypatch, capsys):
    """Before: held_out and targets were taken for keys the problem's YAML does not list, and
    the app ran again with ++key, forever; betas got the hint "not set in adam.yaml"."""
    monkeypatch.chdir(tmp_path)
    runs = count_app_runs(monkeypatch)
    key, _, value = override.partition("=")
    line = refused(["optimizer=adam", override, *TINY], capsys)
    assert f"{key}='{value}'" in line and "must be a list" in line and "not set in" not in line, line
    assert runs["n"] == 1
    assert list(tmp_path.iterdir()) == []


def test_the_retry_path_ends_even_when_the_same_key_is_refused_again(tmp_path, monkeypatch, capsys):
    """Whatever the error says, a key already given with ++ is never retried: at most one
    run again per override (before, an error that kept calling itself addable looped)."""
    from higbench import preflight

    monkeypatch.chdir(tmp_path)
    runs = count_app_runs(monkeypatch)

    def always_addable(exc, overrides):
        error = ConfigError("problem.held_out", "{a:1}", "not set in the problem's YAML")
        error.addable = True
        return error

    monkeypatch.setattr(cli, "composition_error", always_addable)
    assert preflight.composition_error is not always_addable
    line = refused(["problem.held_out={a:1}", *TINY], capsys)
    assert "problem.held_out=" in line and runs["n"] == 2


# -- the Krylov route's memory: Lanczos stops at J's rows -------------------------------------


def test_the_krylov_estimate_uses_the_steps_lanczos_takes():
    from higbench.optim.memory_guard import estimate_bytes

    def basis(steps):
        return estimate_bytes(64, 2, 30, solver="krylov", krylov_steps=steps).parts["krylov_basis"]

    rows = 64 * 2
    assert basis(10**12) == basis(100_000) == basis(rows) > basis(rows - 1)


def test_a_krylov_run_with_more_steps_than_rows_is_not_refused(tmp_path, monkeypatch):
    """Before: krylov_steps=100000 was refused ('not even batch_size=1 fits', 76,685 MB on the
    toy) though the route uses at most rows x rows."""
    from higbench.runfile.reader import read_head

    monkeypatch.chdir(tmp_path)
    route = ["optimizer=hig", "optimizer.solver=krylov", "+optimizer.krylov_steps=100000", "batch_size=64"]
    cli.main([*route, *TINY, "memory_limit_mb=1000", "hydra.run.dir=run"])
    assert read_head(tmp_path / "run" / "run.h5").status == "completed"


# -- optimizers taking **kwargs: their keys against the documented signature -----------------


@pytest.mark.parametrize("optimizer,typo", [("soap", "precondition_frequncy"), ("shampoo", "matrix_epsilon")])
def test_a_misspelt_argument_of_a_kwargs_optimizer_is_one_line(optimizer, typo, tmp_path, monkeypatch, capsys):
    """Before: SOAP and Shampoo swallowed it (``**kwargs``) and trained with the default."""
    pytest.importorskip("pytorch_optimizer")
    monkeypatch.chdir(tmp_path)
    line = refused([f"optimizer={optimizer}", f"+optimizer.{typo}=5", *TINY], capsys)
    assert f"optimizer.{typo}=5: not an argument of pytorch_optimizer." in line, line
    assert list(tmp_path.iterdir()) == []


def test_the_arguments_of_a_kwargs_optimizer_are_its_own_signature():
    """SOAP's own named arguments, not its base class's ``defaults``, which **kwargs never reaches."""
    pytorch_optimizer = pytest.importorskip("pytorch_optimizer")
    from higbench.config import constructor_args

    assert "defaults" not in constructor_args(pytorch_optimizer.SOAP)
    assert {"lr", "betas", "precondition_frequency", "eps"} <= set(constructor_args(pytorch_optimizer.SOAP))


# -- the validation and fresh test sets: bounded, and checked against memory before any work --


@pytest.mark.parametrize("key", ["val_size", "fresh_test_size"])
def test_a_set_beyond_memory_is_one_line_before_any_work(key, tmp_path, monkeypatch, capsys):
    """Before: the validation set was drawn as the problem was built (a traceback when it did
    not fit), the fresh test set at the end of the run (a traceback and a failed run file after
    all the training). Both are now checked first, against memory_limit_mb here."""
    monkeypatch.chdir(tmp_path)
    line = refused(["optimizer=adam", f"problem.{key}=100000", "memory_limit_mb=1", *TINY], capsys)
    assert f"problem.{key}=100000: 100,000 samples of" in line and "(memory_limit_mb); at most" in line, line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("key", ["val_size", "fresh_test_size"])
def test_a_set_size_is_bounded_by_the_schema(key):
    """10**10 samples is refused by its bound (before: 160 GB asked of the allocator)."""
    from hydra import compose, initialize_config_dir

    from higbench.config import config_dir, to_plain, validate

    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        cfg = to_plain(compose("config", overrides=["optimizer=adam", f"++problem.{key}={10**10}"]))
    with pytest.raises(ConfigError, match=rf"problem.{key}=10000000000: must be an integer in \[0, 1000000000\]"):
        validate(cfg)


def test_the_later_sets_are_the_same_samples_drawn_when_first_asked_for():
    """Drawn when first asked for (after the memory check), they are the draws of before:
    the validation set right after the test set, the fresh test set right after it."""
    import torch
    from hydra import compose, initialize_config_dir

    from higbench.config import config_dir
    from higbench.problems.base import build_problem

    sizes = ["problem.train_size=64", "problem.test_size=32", "problem.data_seed=3", "problem.val_size=16"]
    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        cfg = compose("config", overrides=[*sizes, "++problem.fresh_test_size=8"])
    problem = build_problem(cfg.problem, torch.float32, torch.device("cpu"), 0)
    gen = torch.Generator().manual_seed(3)
    train, test = problem._sample(64, gen), problem._sample(32, gen)
    val, fresh = problem._sample(16, gen), problem._sample(8, gen)
    assert torch.equal(problem.train.net_inputs, train.net_inputs) and torch.equal(problem.test.targets, test.targets)
    assert torch.equal(problem.fresh_test_set().net_inputs, fresh.net_inputs)  # asks for the validation set first
    assert torch.equal(problem.val_set().net_inputs, val.net_inputs)


def test_a_key_below_an_unknown_one_names_it_and_where_it_is_not(capsys, tmp_path, monkeypatch):
    """`higbench nosuch.key=3` read "nosuch='<missing>': unknown key; valid keys:" (an empty list): Hydra
    names the unknown parent, and the valid keys were composed with the bad override still in."""
    monkeypatch.chdir(tmp_path)
    line = refused(["nosuch.key=3"], capsys)
    assert line.startswith("higbench: error: nosuch.key=3: unknown key; valid keys: ")
    assert "budget" in line and "problem" in line
