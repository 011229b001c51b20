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


def _diverge_at(monkeypatch, step: int, how: str) -> list[np.ndarray]:
    """HIG's inversion, real, with update ``step`` diverging: ``direction`` (its inversion ran,
    the direction is NaN) or ``jacobian`` (refused before any inversion). Returns the singular
    values each inversion saw."""
    from higbench.optim.hig import JacobianPower

    seen, calls = [], {"n": 0}
    real_inversion, real_tail = JacobianPower._inversion, JacobianPower._derivative_tail

    def inversion(self, *args):
        d = real_inversion(self, *args)
        seen.append(self.last_spectrum["singular_values"].copy())
        return d * float("nan") if how == "direction" and calls["n"] == step else d

    def tail(self, J):
        calls["n"] += 1
        route, J, K = real_tail(self, J)
        if how == "jacobian" and calls["n"] == step:
            K = K * float("nan") if K is not None else J * float("nan")
        return route, J, K

    monkeypatch.setattr(JacobianPower, "_inversion", inversion)
    monkeypatch.setattr(JacobianPower, "_derivative_tail", tail)
    return seen


@pytest.mark.parametrize("how", ["direction", "jacobian"])
def test_a_diverged_update_logs_its_own_spectrum_or_none(how, tmp_path, monkeypatch):
    """The evaluation at the step that diverged (5: evaluations at 0, 3, then 5) logs that
    update's quantiles where its inversion ran, NaN where it did not: never update 4's."""
    seen = _diverge_at(monkeypatch, 5, how)
    path = run(tmp_path, "hig", "optimizer.tau=0.05")
    meta, curves = load_run(path)
    assert meta["status"] == "diverged" and list(curves["step"]) == [0, 3, 5], (meta["status_reason"], curves)
    q = load_logs(path)["sv_quantiles"]
    assert q.shape == (3, 11)
    np.testing.assert_allclose(q[1], np.quantile(seen[2], np.linspace(0, 1, 11)))  # update 3's at step 3
    if how == "direction":
        assert len(seen) == 5 and "non-finite update direction" in meta["status_reason"]
        np.testing.assert_allclose(q[-1], np.quantile(seen[4], np.linspace(0, 1, 11)))
        assert not np.allclose(q[-1], np.quantile(seen[3], np.linspace(0, 1, 11)))
    else:
        assert len(seen) == 4 and "non-finite Jacobian" in meta["status_reason"]
        assert np.isnan(q[-1]).all(), q[-1]
