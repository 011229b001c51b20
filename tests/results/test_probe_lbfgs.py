"""scripts/probe_lbfgs_divergence.py: its committed csv is a replay of the published league's rows,
and its summary is the league page's sentence (no training here)."""

import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
import probe_lbfgs_divergence as probe  # noqa: E402

sys.path.remove(str(ROOT / "scripts"))

CSV = ROOT / "docs" / "results" / "probes" / "lbfgs_divergence.csv"


def test_the_probe_replayed_every_diverged_oscillator_lbfgs_trial_of_the_published_tables():
    trials = probe.diverged_trials(ROOT / probe.TABLE)
    replayed = pd.read_csv(CSV)
    assert len(trials) == 23 and set(trials["optimizer.name"]) == {"lbfgs"}
    key = ["study", "trial", "overrides"]
    both = trials.astype({"study": int, "trial": int}).merge(replayed, on=key, validate="one_to_one")
    assert len(both) == len(trials)  # each published trial once, with its recorded overrides
    assert (both["league_updates"] == both["steps"]).all()  # the csv's count is the table's


def test_the_summary_says_where_the_replays_diverged():
    text = probe.summary(pd.read_csv(CSV))
    assert text.startswith("23 diverged trials replayed; 23 reached a non-finite trial point")
    assert "the replay diverged where the league's run did in 23" in text
    assert "(a new mini-batch, step length lr): 23" in text and "median 0.000921" in text


def test_the_summary_counts_a_later_iteration_apart():
    rows = pd.DataFrame({
        "nonfinite_update": [5.0, 9.0, None], "nonfinite_iteration": [1, 3, None], "nonfinite_trial_point": [1, 2, None],
        "loss_before": [1e-3, 1e-2, None], "earlier_trial_points_all_finite": [True, False, None],
        "same_update": [True, True, False],
    })  # fmt: skip
    text = probe.summary(rows)
    assert text.startswith("3 diverged trials replayed; 2 reached a non-finite trial point")
    assert "(a new mini-batch, step length lr): 1" in text and "at a later iteration of its update: 1" in text
    assert "at a later trial point of its line search: 1" in text and "every earlier trial point finite in 1" in text
