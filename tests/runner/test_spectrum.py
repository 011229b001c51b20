"""The spectrum of every GN/HIG/LM step in the run file: per update sv_max, sv_min_kept and
sv_dropped in /updates; at every evaluation the quantiles of the last step's singular values
in /logs/sv_quantiles. First-order runs record none of it."""

import numpy as np
import pytest
from synthetic import short_run

from higbench.runfile.reader import load_logs, load_run, load_updates


def run(tmp_path, optimizer, *overrides):
    return short_run(tmp_path, optimizer, *overrides)


@pytest.mark.parametrize(
    "optimizer,overrides", [("hig", ["optimizer.tau=0.05"]), ("gn", ["optimizer.solver=gram", "batch_size=4"]), ("lm", [])]
)
def test_updates_hold_the_spectrum_of_every_step(optimizer, overrides, tmp_path):
    path = run(tmp_path, optimizer, *overrides)
    updates = load_updates(path)
    assert len(updates) == 9
    assert (updates["sv_max"] > 0).all() and (updates["sv_min_kept"] <= updates["sv_max"]).all()
    assert (updates["sv_dropped"] >= 0).all() and (updates["sv_dropped"] == updates["sv_dropped"].round()).all()
    if optimizer == "hig":  # tau = 0.05: the kept ones are above tau * max
        assert (updates["sv_min_kept"] >= 0.05 * updates["sv_max"] * (1 - 1e-12)).all()
    _, curves = load_run(path)
    q = load_logs(path)["sv_quantiles"]
    assert q.shape == (len(curves), 11)
    assert np.isnan(q[0]).all()  # step 0: no step taken yet
    last = updates.iloc[-1]
    assert q[-1, -1] == pytest.approx(last["sv_max"]) and np.all(np.diff(q[-1]) >= 0)


def test_first_order_runs_record_no_spectrum(tmp_path):
    path = run(tmp_path, "adam")
    assert "sv_max" not in load_updates(path) and "sv_quantiles" not in load_logs(path)
