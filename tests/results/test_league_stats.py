"""The league's statistics (higbench.results.stats) on hand-made seeds with known answers, and
the aggregate against rliable 1.2.0's values on seeded random matrices (the oracle file from
scripts/rliable_oracle.py, run in an environment of its own)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from higbench.results import stats

ORACLE = Path(__file__).parent / "data" / "rliable_oracle.json"


# -- the order-statistics interval for the median --------------------------------------------


def test_three_seeds_give_min_max_at_75_percent_and_say_no_better_exists():
    interval = stats.median_interval([3.0, 1.0, 2.0])
    assert (interval.low, interval.high, interval.k) == (1.0, 3.0, 1)
    assert interval.coverage == pytest.approx(0.75)  # 1 - 2 / 2**3
    assert not interval.meets
    assert "75.0%" in interval.label() and "no higher-coverage interval" in interval.label()


def test_five_seeds_fall_short_of_95_and_six_reach_it():
    five = stats.median_interval([5, 4, 3, 2, 1])
    assert (five.low, five.high) == (1, 5) and five.coverage == pytest.approx(1 - 2 / 32) and not five.meets
    six = stats.median_interval([6, 5, 4, 3, 2, 1])
    assert (six.low, six.high) == (1, 6) and six.coverage == pytest.approx(1 - 2 / 64) and six.meets


def test_ten_seeds_drop_one_at_each_end():
    # k = 2: 1 - 2 P(Bin(10, 1/2) <= 1) = 1 - 2 * 11 / 1024 = 0.9785; k = 3 gives 0.8906 < 0.95
    interval = stats.median_interval([10, 1, 9, 2, 8, 3, 7, 4, 6, 5])
    assert (interval.low, interval.high, interval.k) == (2, 9, 2)
    assert interval.coverage == pytest.approx(1 - 22 / 1024) and interval.meets
    assert "[x(2), x(9)] of 10 seeds" in interval.label()


def test_the_coverage_is_what_it_says_by_simulation():
    rng = np.random.default_rng(0)
    draws = rng.lognormal(size=(20000, 7))
    low, high = np.sort(draws, axis=1)[:, 0], np.sort(draws, axis=1)[:, 6]  # k = 1 at n = 7
    covered = ((low <= 1.0) & (1.0 <= high)).mean()  # the lognormal's median is 1
    assert covered == pytest.approx(stats.order_statistic_coverage(7, 1), abs=0.01)


# -- the tests of an ordering -----------------------------------------------------------------


def test_mann_whitney_exact_one_sided_known_values():
    assert stats.mann_whitney_less([1, 2, 3], [4, 5, 6]) == pytest.approx(1 / 20)  # U = 0: 1 / C(6, 3)
    assert stats.mann_whitney_less([1, 2, 4], [3, 5, 6]) == pytest.approx(2 / 20)  # U <= 1: 2 of 20 splits
    assert stats.smallest_attainable_p(3, 3) == pytest.approx(0.05)
    assert stats.smallest_attainable_p(5, 5) == pytest.approx(1 / 252)


def test_mann_whitney_with_tied_divergences_enumerates_every_split():
    x, y = [1.0, 2.0, math.inf], [4.0, math.inf, math.inf]
    # By hand: U(x) = #(x > y) + ties / 2; count the 20 splits of the pooled values whose U <= U(x).
    pooled = np.array(x + y)
    observed = stats.probability_of_improvement(y, x) * 9  # U(x) = P(Y < X) * n m
    from itertools import combinations

    count = 0
    for idx in combinations(range(6), 3):
        a = pooled[list(idx)]
        b = np.delete(pooled, list(idx))
        count += stats.probability_of_improvement(b, a) * 9 <= observed + 1e-12
    assert stats.mann_whitney_less(x, y) == pytest.approx(count / 20)


def test_holm_adjusts_step_down_and_keeps_nan_out():
    assert stats.holm([0.01, 0.04, 0.03]).tolist() == pytest.approx([0.03, 0.06, 0.06])
    assert stats.holm([0.05, 0.05]).tolist() == pytest.approx([0.1, 0.1])
    adjusted = stats.holm([0.02, math.nan, 0.2])
    assert adjusted[0] == pytest.approx(0.04) and math.isnan(adjusted[1]) and adjusted[2] == pytest.approx(0.2)


def test_compare_to_leader_picks_by_median_and_separates_only_after_holm():
    seeds = {
        "mean-leader": [0.01, 2.5, 2.6],  # the lowest mean (1.7), not the lowest median
        "median-leader": [1.0, 2.0, 3.0],
        "far": [10.0, 11.0, 12.0],
    }
    rows = stats.compare_to_leader(seeds)
    assert rows[0]["setting"] == "median-leader" and rows[0]["leader"]
    far = next(r for r in rows if r["setting"] == "far")
    assert far["p_leader_below"] == 1.0 and far["p_value"] == pytest.approx(0.05)
    assert far["p_holm"] == pytest.approx(0.1) and not far["separated"]  # 3 seeds cannot separate two rivals
    five = stats.compare_to_leader({"a": [1, 2, 3, 4, 5], "b": [6, 7, 8, 9, 10], "c": [11, 12, 13, 14, 15]})
    assert [r["separated"] for r in five] == [False, True, True]
    assert five[1]["p_holm"] == pytest.approx(2 / 252)


def test_a_finite_blow_up_and_a_nan_score_the_same():
    loss = stats.scored_loss([1e5, math.nan, 0.5, 0.2], ["diverged", "diverged", "completed", "diverged"])
    assert loss.tolist() == [math.inf, math.inf, 0.5, math.inf]
    assert stats.scored_loss([math.nan], ["completed"]).tolist() == [math.inf]


def test_a_completed_run_that_ended_above_its_first_evaluation_is_scored_as_diverged():
    """LM on the oscillator completed at 1.2e3 from a first evaluation of 0.88: a blow-up
    without a NaN. Within 1% of its start a run did not move (flag_row's constant predictor),
    and without a first evaluation (NaN) nothing is known."""
    final = [1181.0, 0.885, 0.89, 2e-6, 0.5]
    first = [0.878, 0.878, 0.878, 0.85, math.nan]
    assert stats.scored_loss(final, ["completed"] * 5, first).tolist() == [math.inf, 0.885, math.inf, 2e-6, 0.5]
    assert stats.scored_loss(final, ["completed"] * 5).tolist() == final  # without first: the value, as before
    runs = {"final_test_loss": final, "status": ["completed"] * 5, "first_test_loss": first}
    assert stats.scored_column(runs, "final_test_loss").tolist() == [math.inf, 0.885, math.inf, 2e-6, 0.5]
    assert stats.flag_row([30.0, 900.0], ["completed", "completed"], first=[0.9, 0.9]) == "diverged on every seed"


# -- rows flagged before publishing ----------------------------------------------------------


def test_a_constant_predictor_row_is_flagged():
    status = ["completed"] * 3
    assert "constant predictor" in stats.flag_row([0.480, 0.481, 0.479], status, constant_loss=0.4795)
    assert "first evaluation" in stats.flag_row([0.30, 0.30, 0.304], status, first=[0.30, 0.301, 0.305])
    assert stats.flag_row([0.30, 0.01, 0.31], status, constant_loss=0.4795, first=[0.5, 0.5, 0.5]) is None
    assert stats.flag_row([1.0, math.nan, 2.0], ["diverged"] * 3) == "diverged on every seed"


# -- the aggregate across tasks, against rliable --------------------------------------------


def test_normalised_scores_put_the_leader_at_one_and_divergence_at_zero():
    loss = np.array([[1e-4, 1.0], [1e-2, math.inf], [10.0, 1e-3]])
    s = stats.normalised_scores(loss, worst=[1.0, 1.0], best=[1e-4, 1e-3])
    np.testing.assert_allclose(s, [[1.0, 0.0], [0.5, 0.0], [0.0, 1.0]])


@pytest.mark.parametrize("case", json.loads(ORACLE.read_text())["cases"], ids=lambda c: f"seed{c['seed']}")
def test_aggregate_matches_rliable(case):
    x, y = np.array(case["x"]), np.array(case["y"])
    assert stats.iqm(x) == pytest.approx(case["iqm_x"], abs=1e-12)
    assert stats.iqm(y) == pytest.approx(case["iqm_y"], abs=1e-12)
    # rliable: higher is better; here lower is: the same question on negated scores
    assert stats.average_probability_of_improvement(-x, -y) == pytest.approx(case["probability_x_above_y"], abs=1e-12)
    # intervals: different resamples, so equal within the Monte-Carlo error of the percentiles
    _, lo, hi = stats.stratified_bootstrap_ci(x, reps=4000, seed=case["seed"])
    assert (lo, hi) == pytest.approx(case["iqm_x_interval"], abs=0.03)
    _, lo, hi = stats.probability_of_improvement_ci(-x, -y, reps=1000, seed=case["seed"])
    assert (lo, hi) == pytest.approx(case["probability_interval"], abs=0.05)


def test_the_tied_rank_sum_count_equals_scipy_s_exact_test_without_ties():
    from scipy import stats as scipy_stats

    rng = np.random.default_rng(0)
    for n, m in ((3, 3), (5, 7), (10, 10)):
        x, y = rng.random(n), rng.random(m)
        doubled = np.rint(2 * scipy_stats.rankdata(np.r_[x, y])).astype(int)
        counts = stats._rank_sum_counts(doubled, n)
        p = counts[: int(doubled[:n].sum()) + 1].sum() / math.comb(n + m, n)
        assert p == pytest.approx(scipy_stats.mannwhitneyu(x, y, alternative="less", method="exact").pvalue, abs=1e-12)
