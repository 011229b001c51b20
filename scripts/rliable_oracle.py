"""Oracle values from rliable 1.2.0 for tests/results/test_league_stats.py (not run by the tests).

rliable pins an old ``arch`` (7.2, which needs pandas < 3), so it is not a dependency of
higbench; run this in a separate environment:

    python -m venv rliable-env && rliable-env/bin/pip install rliable==1.2.0 "pandas<3"
    rliable-env/bin/python scripts/rliable_oracle.py > tests/results/data/rliable_oracle.json

On seeded random score matrices (runs x tasks, higher is better for rliable; ties included) it
records rliable's IQM, its probability of improvement, and its stratified-bootstrap percentile
intervals of both. The test compares higbench.results.stats to the points exactly and to the
intervals within the bootstrap's Monte-Carlo error (the two draw different resamples).
"""

from __future__ import annotations

import json
import sys

import numpy as np
from rliable import library as rly
from rliable import metrics

REPS_IQM = 5000
REPS_PROBABILITY = 1000  # rliable runs a Mann-Whitney test per task and replicate: slow


def case(seed: int) -> dict:
    rng = np.random.default_rng(seed)
    runs_x, runs_y = (int(v) for v in rng.integers(3, 11, 2))
    tasks = int(rng.integers(1, 6))
    x = rng.random((runs_x, tasks))
    y = rng.random((runs_y, tasks))
    if seed % 3 == 0:  # ties: scores on a coarse grid
        x, y = np.round(x * 4) / 4, np.round(y * 4) / 4
    state = np.random.RandomState(seed)
    points, intervals = rly.get_interval_estimates(
        {"x": x, "y": y}, lambda s: np.array([metrics.aggregate_iqm(s)]), reps=REPS_IQM, random_state=state
    )
    pair_points, pair_intervals = rly.get_interval_estimates(
        {"x,y": [x, y]}, metrics.probability_of_improvement, reps=REPS_PROBABILITY, random_state=state
    )
    return {
        "seed": seed,
        "x": x.tolist(),
        "y": y.tolist(),
        "iqm_x": float(metrics.aggregate_iqm(x)),
        "iqm_x_interval": [float(v) for v in intervals["x"][:, 0]],
        "iqm_y": float(metrics.aggregate_iqm(y)),
        "probability_x_above_y": float(metrics.probability_of_improvement(x, y)),
        "probability_interval": [float(v) for v in np.ravel(pair_intervals["x,y"])],
        "reps_iqm": REPS_IQM,
        "reps_probability": REPS_PROBABILITY,
    }


if __name__ == "__main__":
    json.dump({"rliable": "1.2.0", "cases": [case(seed) for seed in range(12)]}, sys.stdout, indent=1)
    sys.stdout.write("\n")
