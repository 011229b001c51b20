"""scripts/performance_profile.py: the Adam re-tuning and the setting labels (no training here)."""

import math
import sys
from pathlib import Path

import pandas as pd

from higbench.results.targets import league_seconds

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
import performance_profile as pp  # noqa: E402

sys.path.remove(str(ROOT / "scripts"))


def runs(rows):
    cols = ["problem.name", "optimizer.name", "optimizer.lr", "seed", "status", "final_test_loss"]
    return pd.DataFrame(rows, columns=cols)


def test_tuning_takes_the_lowest_completed_loss_and_never_a_diverged_run():
    df = runs([("toy", "adam", 0.3, 0, "completed", 1e-2), ("toy", "adam", 3.0, 0, "diverged", 1e-9),
               ("toy", "adam", 0.03, 0, "completed", 1e-3), ("toy", "adam", 0.03, 1, "completed", 1e-6),
               ("toy", "hig", 1.0, 0, "completed", 1e-8)])  # fmt: skip
    assert pp.tuned_lr(df, "toy", 0) == 0.03


def test_labels_keep_the_paper_rate_and_the_tuned_rate_and_drop_other_grid_points():
    df = runs([("toy", "adam", 0.3, 0, "completed", 1e-2), ("toy", "adam", 0.03, 0, "completed", 1e-3),
               ("toy", "adam", 3.0, 0, "completed", 1e-1), ("toy", "lm", 1.0, 0, "completed", 1e-6)])  # fmt: skip
    labels = pp.label_settings(df, {"toy": 0.03})
    assert labels.isna().tolist() == [False, False, True, False]
    assert labels.dropna().tolist() == ["Adam (paper η)", "Adam (re-tuned η)", "Levenberg-Marquardt"]


def test_a_paper_rate_that_wins_the_tuning_stands_for_both_adam_settings():
    df = runs([("toy", "adam", 0.3, s, "completed", 1e-2) for s in range(3)])
    df = df.assign(setting=pp.label_settings(df, {"toy": 0.3}))
    both = pp.expand_paper_adam(df, {"toy": 0.3})
    assert sorted(both["setting"].value_counts().items()) == [("Adam (paper η)", 3), ("Adam (re-tuned η)", 3)]


def test_the_first_stage_has_every_fixed_setting_and_the_grid_once():
    jobs = pp.first_stage(("toy",), (0, 1, 2))
    assert len(jobs) == len(pp.FIXED) * 3 + len(pp.adam_lrs("toy")) + 2
    assert len({tuple(j.override_list()) for j in jobs}) == len(jobs)
    assert all(j.overrides["budget.seconds"] == league_seconds("toy") for j in jobs)  # the problem's budget


def test_the_paper_rates_are_the_shipped_pair_configs():
    """Adam's paper rate is read from conf/problem_optimizer/<problem>_adam.yaml, not typed again."""
    import yaml

    for problem in pp.PROBLEMS:
        pair = yaml.safe_load((ROOT / "conf" / "problem_optimizer" / f"{problem}_adam.yaml").read_text())
        assert math.isclose(pp.paper_lr(problem), pair["optimizer"]["lr"]), problem
        assert math.isclose(pp.adam_lrs(problem)[0], pair["optimizer"]["lr"])
