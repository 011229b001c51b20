"""Time to target and the performance profile on hand-made index rows whose answer is known."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from higbench.results.profile import (
    lower_median,
    parse_targets,
    performance_profile,
    setting_labels,
    time_to_target,
)

NAN = math.nan


def _runs(rows):
    """rows: (problem, setting, seed, time_to_1e0, time_to_1e-1, budget_s[, status])."""
    out = []
    for problem, setting, seed, t0, t1, budget, *status in rows:
        out.append(
            {
                "problem.name": problem,
                "setting": setting,
                "seed": seed,
                "time_to_1e0": t0,
                "time_to_1e-1": t1,
                "budget.seconds": budget,
                "status": status[0] if status else "completed",
            }
        )
    return pd.DataFrame(out)


@pytest.fixture
def runs():
    return _runs(
        [
            # X: 1e0 at 1, 2, 3 s (median 2); 1e-1 by 2 of 3 seeds (lower median of 4, 6, inf: 6)
            ("a", "X", 0, 1.0, 4.0, 10), ("a", "X", 1, 2.0, NAN, 10), ("a", "X", 2, 3.0, 6.0, 10),
            # Y: 1e0 median 2 (a tie with X); 1e-1 by 1 of 3 seeds: unsolved although the fastest seed
            ("a", "Y", 0, 2.0, 1.0, 10), ("a", "Y", 1, 2.0, NAN, 10), ("a", "Y", 2, 10.0, NAN, 10),
            # Z: 2 seeds, 1e0 by one of them (half: solved, at 8 s); 1e-1 never
            ("a", "Z", 0, 8.0, NAN, 10), ("a", "Z", 1, NAN, NAN, 10),
            # problem b, target 0.5 (column time_to_5e-1 absent): nobody reaches it
            ("b", "X", 0, NAN, NAN, 10), ("b", "Y", 0, NAN, NAN, 10), ("b", "Z", 0, NAN, NAN, 10),
        ]
    )  # fmt: skip


TARGETS = {"a": [1.0, 0.1], "b": [0.5]}


def _cell(times, problem, target, setting, column):
    row = times[(times["problem"] == problem) & (times["target"] == target) & (times["setting"] == setting)]
    assert len(row) == 1
    return row[column].iloc[0]


def test_median_over_seeds_ties_and_unsolved(runs):
    times = time_to_target(runs, TARGETS)
    assert len(times) == 9  # 3 pairs x 3 settings
    assert _cell(times, "a", 1.0, "X", "time_s") == 2.0 and _cell(times, "a", 1.0, "X", "ratio") == 1.0
    assert _cell(times, "a", 1.0, "Y", "time_s") == 2.0 and _cell(times, "a", 1.0, "Y", "ratio") == 1.0  # tie
    assert _cell(times, "a", 1.0, "Z", "time_s") == 8.0 and _cell(times, "a", 1.0, "Z", "ratio") == 4.0
    assert _cell(times, "a", 0.1, "X", "time_s") == 6.0 and _cell(times, "a", 0.1, "X", "ratio") == 1.0
    assert _cell(times, "a", 0.1, "Y", "reached") == 1 and math.isinf(_cell(times, "a", 0.1, "Y", "time_s"))
    assert math.isinf(_cell(times, "a", 0.1, "Y", "ratio"))
    assert all(math.isnan(_cell(times, "b", 0.5, s, "ratio")) for s in "XYZ")


def test_profile_counts_every_pair_including_unsolved_ones(runs):
    rho = performance_profile(time_to_target(runs, TARGETS), [1.0, 3.9, 4.0, 100.0])
    # 3 pairs; b's is solved by nobody and stays in the denominator
    assert rho["X"].tolist() == pytest.approx([2 / 3] * 4)
    assert rho["Y"].tolist() == pytest.approx([1 / 3] * 4)
    assert rho["Z"].tolist() == pytest.approx([0, 0, 1 / 3, 1 / 3])


def test_times_after_the_shortest_budget_do_not_count():
    runs = _runs([("a", "long", 0, 20.0, NAN, 60), ("a", "short", 0, 9.0, NAN, 10)])
    times = time_to_target(runs, {"a": [1.0]})
    assert math.isinf(_cell(times, "a", 1.0, "long", "time_s"))  # reached at 20 s, after the 10 s horizon
    assert _cell(times, "a", 1.0, "short", "ratio") == 1.0


def test_runs_that_did_not_finish_are_left_out():
    runs = _runs([("a", "X", 0, 1.0, NAN, 10), ("a", "X", 1, NAN, NAN, 10, "interrupted"), ("a", "X", 2, 3.0, NAN, 10)])
    assert _cell(time_to_target(runs, {"a": [1.0]}), "a", 1.0, "X", "seeds") == 2


def test_lower_median():
    assert lower_median([3.0, 1.0, 2.0]) == 2.0
    assert lower_median([4.0, 1.0]) == 1.0
    assert math.isinf(lower_median([1.0, math.inf, math.inf]))


def test_parse_targets_and_its_errors():
    assert parse_targets(["poisson=1,0.1", "toy=1e-3"]) == {"poisson": [1.0, 0.1], "toy": [1e-3]}
    for bad in ("poisson", "poisson=", "poisson=abc", "poisson=-1", "=1"):
        with pytest.raises(ValueError, match="--targets"):
            parse_targets([bad])


def test_setting_labels_drop_seed_problem_and_budget():
    runs = pd.DataFrame(
        {
            "overrides": ["problem=toy optimizer=adam optimizer.lr=0.01 seed=2 budget.seconds=5", "seed=0", ""],
            "optimizer.name": ["adam", "hig", "hig"],
        }
    )
    assert setting_labels(runs).tolist() == ["adam lr=0.01", "hig", "hig"]
    assert setting_labels(runs.assign(x=[1, 2, 2]), ["optimizer.name", "x"]).tolist() == ["adam 1", "hig 2", "hig 2"]


def test_a_diverged_run_does_not_cut_the_comparison_short():
    """The issue's case: GN diverges at 0.04 s of a 10 s budget, HIG (10 s) reaches the target
    at 8 s, Adam has 20 s. The horizon is HIG's 10 s, not GN's 0.04 s."""
    runs = _runs(
        [
            ("a", "gn", 0, NAN, NAN, 10, "diverged"),
            ("a", "hig", 0, 8.0, NAN, 10),
            ("a", "adam", 0, 15.0, NAN, 20),
        ]
    ).assign(train_time_s=[0.04, 10.01, 20.0])
    times = time_to_target(runs, {"a": [1.0]})
    assert _cell(times, "a", 1.0, "hig", "time_s") == 8.0
    assert _cell(times, "a", 1.0, "hig", "horizon_s") == 10.01
    assert math.isinf(_cell(times, "a", 1.0, "adam", "time_s"))  # 15 s: after the horizon
    assert math.isinf(_cell(times, "a", 1.0, "gn", "time_s"))
