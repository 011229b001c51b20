"""The long budget's table (higbench.results.long_budget) on hand-made runs: known medians."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from higbench.results.league import ROLES
from higbench.results.long_budget import LONG_ROLES, format_long_budget, long_budget_table


def _run(role, name, seed, val, test, status="completed", steps=100, seconds=600.0, task="oscillator"):
    return {"league_role": role, "optimizer.name": name, "seed": seed, "final_val_loss": val, "final_test_loss": test,
            "status": status, "steps": steps, "train_time_s": seconds, "task": task}  # fmt: skip


def test_the_table_shows_every_seed_and_the_medians_best_first():
    runs = pd.DataFrame([
        _run("long", "hig", 0, 3e-5, 4e-5, steps=9000), _run("long", "hig", 1, 1e-5, 2e-5, steps=9100),
        _run("long", "hig", 2, 2e-5, 3e-5, steps=8900),
        _run("long-paper", "hig", 0, 1e-3, 1e-3), _run("long-paper", "hig", 1, math.nan, math.nan, status="diverged"),
        _run("long-paper", "hig", 2, 2e-3, 2e-3),
        _run("long", "adam", 0, 5e-4, 6e-4), _run("long", "adam", 1, 4e-4, 5e-4), _run("long", "adam", 2, 6e-4, 7e-4),
        _run("confirm", "adam", 0, 1e-9, 1e-9),  # the league's own runs never enter the long table
        _run("long", "adam", 3, 1e-9, 1e-9, status="interrupted"),  # nor an unfinished one
        _run("confirm", "hig", 0, 1e-4, 2e-4), _run("confirm", "hig", 1, 3e-4, 4e-4),  # hig at the league's budget
        _run("paper", "hig", 0, 0.1, 0.1), _run("paper", "hig", 1, math.nan, math.nan, status="diverged"),
        _run("paper", "hig", 2, 0.3, 0.3), _run("confirm", "hig", 0, 9.0, 9.0, task="oscillator coupling=2.0"),
    ])  # fmt: skip
    table = long_budget_table(runs)
    assert list(table["setting"]) == ["hig", "adam", "hig (paper)"]
    assert list(table["median val"]) == [2e-5, 5e-4, 2e-3]  # the diverged seed counts as the worst: inf
    assert table.loc[0, "test per seed"] == "4e-05, 2e-05, 3e-05" and table.loc[0, "updates per seed"] == "9000, 9100, 8900"
    assert table.loc[2, "test per seed"] == "0.001, inf, 0.002" and list(table["seeds"]) == [3, 3, 3]
    # the same setting at the league's budget, on the same task only: tuned from confirm, shipped from paper
    assert table.loc[0, "league median test"] == pytest.approx(3e-4) and table.loc[2, "league median test"] == 0.3
    assert table.loc[1, "league median test"] == 1e-9  # adam's one confirmation run
    no_league = long_budget_table(runs[runs["league_role"].isin(LONG_ROLES)])
    assert no_league["league median test"].isna().all()  # no confirmation runs: NaN, not a crash
    assert "long budget (--long)" in format_long_budget(runs)


def test_a_long_run_that_ended_above_its_first_evaluation_counts_as_diverged():
    runs = pd.DataFrame([_run("long", "lm", 0, 2e-6, 3e-6), _run("long", "lm", 1, 25.0, 26.0),
                         _run("long", "lm", 2, 4e-6, 5e-6)])  # fmt: skip
    firsts = runs.assign(first_val_loss=0.85, first_test_loss=0.87)  # league.with_first_losses' columns
    assert long_budget_table(firsts).loc[0, "test per seed"] == "3e-06, inf, 5e-06"
    assert long_budget_table(runs).loc[0, "test per seed"] == "3e-06, 26, 5e-06"  # no curves: the value


def test_a_run_trained_twice_under_one_identity_counts_once_in_both_columns():
    """Two sittings into one root can train a job twice; the copy is not an extra seed (the
    first by ``run`` is kept, as in the league's scores)."""
    rows = [_run("long", "hig", s, 1e-5 * (s + 1), 1e-5 * (s + 1)) | {"config_id": f"L{s}", "run": f"a/{s}"} for s in range(3)]
    rows += [_run("long", "hig", 2, 9.0, 9.0) | {"config_id": "L2", "run": "b/2"}]  # seed 2 again, later
    rows += [_run("confirm", "hig", s, 1e-3, v) | {"config_id": f"C{s}", "run": f"a/c{s}"} for s, v in ((0, 1e-3), (1, 2e-3))]
    rows += [_run("confirm", "hig", 1, 1e-3, 7.0) | {"config_id": "C1", "run": "b/c1"}]  # a copy: not a third seed
    table = long_budget_table(pd.DataFrame(rows))
    assert table.loc[0, "seeds"] == 3 and table.loc[0, "test per seed"] == "1e-05, 2e-05, 3e-05"
    assert table.loc[0, "league median test"] == pytest.approx(1.5e-3)  # median of 2 seeds, not of 3 rows


def test_no_long_runs_no_table_and_the_roles_reach_the_tables():
    assert format_long_budget(pd.DataFrame([_run("confirm", "adam", 0, 1e-3, 1e-3)])) is None
    assert set(LONG_ROLES) <= set(ROLES)  # exported to the tables with their role


def test_the_report_counts_the_tuning_trials_a_piece_has_made_per_optimizer():
    from higbench.league.report import tuning_counts

    runs = pd.DataFrame({"league_role": ["tune"] * 5 + ["target-tune", "confirm"],
                         "problem.name": ["toy", "toy", "toy", "dipole", "toy", "toy", "toy"],
                         "optimizer.name": ["adam", "adam", "hig", "lm", "hig", "adam", "adam"]})  # fmt: skip
    assert tuning_counts(runs).splitlines()[1:] == ["  dipole: 1 trials: lm 1", "  toy: 4 trials: adam 2, hig 2"]
    assert tuning_counts(runs.iloc[5:]) == "tuning: no league tuning trials in the tables yet"
    unfinished = runs.assign(status=["completed", "diverged", "interrupted", "completed", "running", "completed", "completed"])
    assert tuning_counts(unfinished).splitlines()[1:] == [
        "  dipole: 1 trials: lm 1",
        "  toy: 2 trials: adam 2",
        "  toy: 2 unfinished (a stopped sitting's; resumed by the next): hig 2",
    ]


def test_the_report_says_how_many_tuning_trials_reached_the_validation_target_and_the_fastest():
    """Known answer: hig's trials reach 0.01 at 3 s and never; adam's at 5 s (more trials that
    reached first, then the faster); a failed trial and a problem without a target not counted."""
    from higbench.league.report import tuning_outcomes

    runs = pd.DataFrame({"league_role": ["tune"] * 5, "status": ["completed"] * 4 + ["failed"],
                         "problem.name": ["toy", "toy", "toy", "dipole", "toy"],
                         "optimizer.name": ["hig", "hig", "adam", "lm", "adam"], "run": ["a", "b", "c", "d", "e"]})  # fmt: skip
    curve = {"a": [1.0, 0.005, 0.001], "b": [1.0, 0.5, 0.2], "c": [0.5, 0.1, 0.009], "d": [1.0] * 3, "e": [0.0] * 3}
    curves = pd.DataFrame([{"run": r, "wall_time": 1.0 + 2 * i, "step": i, "val_loss": v}
                           for r, losses in curve.items() for i, v in enumerate(losses)])  # fmt: skip
    text = tuning_outcomes(runs, curves, {"toy": 0.01})
    assert text.splitlines()[1] == "  toy (validation target 0.01): hig 1 of 2, 3 s; adam 1 of 1, 5 s"
    assert tuning_outcomes(runs, curves, {}) == ""
    # two studies (tuning seeds 1000 and 1001): each study's fastest, the luck of one study alone
    studies = runs.assign(seed=[1000, 1001, 1000, 1000, 1001])
    line = tuning_outcomes(studies, curves, {"toy": 0.01}).splitlines()[1]
    assert line == "  toy (validation target 0.01): hig 1 of 2, 3 s (per study: 3, inf s); adam 1 of 1, 5 s"
