"""Bad input found by the fourth adversarial pass, each one line naming key and value (exit 2)
before any work: a value of the wrong kind (a mapping for a list), sizes beyond memory, an
argument a ``**kwargs`` optimizer would swallow, the Krylov route's true size."""

from __future__ import annotations

import pytest

from higbench import cli
from higbench.errors import ConfigError

TINY = ["budget.max_updates=3", "budget.seconds=null", "eval_unit=updates", "eval_every=1", "progress=false", "threads=1"]


def refused(argv: list[str], capsys) -> str:
    """Run ``higbench argv``: it must exit 2 with one line; the line."""
    with pytest.raises(SystemExit) as info:
        cli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert info.value.code == 2 and len(err) == 1 and err[0].startswith("higbench: error: "), err
    return err[0]


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
