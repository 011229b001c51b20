"""The declared contracts: the optimizer's step report, the one answer to "does it use the
Jacobian", and the problem's surface (``higbench.optim.contract``, ``higbench.problems.base``)."""

from __future__ import annotations

import math
import re
import time
from pathlib import Path

import pytest
import torch
from optim_helpers import CASES, compose_cfg, flat, setup

import higbench
from higbench.optim import HIG, GaussNewton, JacobianPower
from higbench.optim.contract import PHASES, StepReport, StepReporter, needs_inverse_simulator, report_of, uses_jacobian
from higbench.optim.lm import LevenbergMarquardt
from higbench.optim.sip import ScaleInvariantPhysics
from higbench.optim.split import SplitOptimizer
from higbench.problems.base import Problem, build_problem, registry
from higbench.results import targets
from higbench.runner.updates import Update, build_update

PACKAGE = Path(higbench.__file__).parent


@pytest.mark.parametrize("cls", [JacobianPower, HIG, GaussNewton, LevenbergMarquardt])
def test_the_jacobian_power_family_uses_the_jacobian(cls):
    opt = cls([torch.nn.Parameter(torch.zeros(2))])
    assert uses_jacobian(cls) and uses_jacobian(opt) and not needs_inverse_simulator(cls)


@pytest.mark.parametrize("cls", [torch.optim.Adam, torch.optim.LBFGS, SplitOptimizer, ScaleInvariantPhysics, object])
def test_the_others_do_not(cls):
    assert not uses_jacobian(cls)
    assert needs_inverse_simulator(cls) == (cls is ScaleInvariantPhysics)


def test_one_answer_to_does_it_use_the_jacobian():
    """The four old answers (a method's presence, an attribute's, a subclass test, a missing
    timing) and the runner's getattr defaults are gone from the package: ``uses_jacobian`` and
    ``report_of`` answer."""
    old = re.compile(
        r"hasattr\([^)]*\"(step_structured|last_spectrum|last_timings)\""
        r"|issubclass\([^)]*JacobianPower"
        r"|getattr\([^)]*\"last_(timings|finite|reason|spectrum|metrics)\""
        r"|__self__"
    )
    found = [f"{p.relative_to(PACKAGE)}: {m.group(0)}" for p in PACKAGE.rglob("*.py") for m in old.finditer(p.read_text())]
    assert found == []


def test_a_torch_optimizer_reports_nothing_and_is_timed_by_the_closure():
    cfg, p, model, batch = setup("toy", 8, optimizer="adam")
    update = build_update(p, model, cfg.optimizer)
    result = update(batch)
    assert report_of(update.optimizer) is None
    assert set(result.timings) == set(PHASES) and result.timings["inversion_s"] == 0 and result.timings["jacobian_s"] > 0
    assert result.finite and result.spectrum == {} and result.metrics == {}


def test_the_runner_records_what_the_report_says():
    cfg, p, model, batch = setup("oscillator", 4)
    update = build_update(p, model, cfg.optimizer)
    result = update(batch)
    report = update.optimizer.last_report
    assert result.timings == dict(report.timings) and set(result.timings) == set(PHASES)
    assert result.spectrum["sv_max"] == report.spectrum["sv_max"] > 0 and result.finite


class _Reporting(torch.optim.SGD, StepReporter):
    """SGD that reports what ``self.script`` says (None: forgets to report)."""

    script: StepReport | None = None

    def step(self, closure):
        loss = closure()
        if self.script is not None and self.script.finite:
            super().step()
        self.last_report = self.script if self.script is not None else self.last_report
        return loss


def _reporting_update(script_for_each_step):
    cfg, p, model, batch = setup("toy", 8, optimizer="sgd")
    opt = _Reporting(model.parameters(), lr=0.1)
    update = Update(p, model, opt)

    def step(script):
        opt.script = script
        return update(batch)

    return model, step, [step(s) for s in script_for_each_step]


def test_a_report_of_its_own_values_becomes_columns():
    timings = {"jacobian_s": 1.0, "inversion_s": 2.0, "apply_s": 3.0}
    _model, _step, (result,) = _reporting_update([StepReport(timings=timings, metrics={"mine": 7.0})])
    assert result.timings == timings and result.metrics == {"mine": 7.0} and result.finite


def test_a_refused_step_is_reported_and_the_weights_stay():
    model, step, _ = _reporting_update([])
    before = flat(model)
    result = step(StepReport.refused("too steep"))
    assert not result.finite and result.reason == "too steep" and result.timings == {}
    torch.testing.assert_close(flat(model), before, rtol=0, atol=0)


def test_a_reporter_that_sets_no_new_report_is_an_error():
    timings = dict.fromkeys(PHASES, 0.0)
    _model, step, _ = _reporting_update([StepReport(timings=timings)])
    with pytest.raises(TypeError, match="_Reporting.step set no new StepReport"):
        step(None)


def test_a_report_without_the_phases_is_an_error():
    with pytest.raises(TypeError, match=r"reported timings \['total_s'\]; expected"):
        _reporting_update([StepReport(timings={"total_s": 1.0})])


# -- the problem's surface --


def test_physics_jacobian_is_declared_and_used_where_a_problem_has_one(monkeypatch):
    assert Problem.physics_jacobian(None, None, None) is None  # the default: autograd
    cfg, p, model, batch = setup("oscillator", 4)
    calls = []
    declared = type(p).physics_jacobian

    def counted(self, inputs, u):
        calls.append(u.shape[0])
        return declared(self, inputs, u)

    monkeypatch.setattr(type(p), "physics_jacobian", counted)
    build_update(p, model, cfg.optimizer)(batch)
    assert calls == [4]


@pytest.mark.parametrize("name", sorted(registry()))
def test_every_problem_says_what_it_is_judged_by(name):
    small = next((extra for problem, extra in CASES.values() if problem == name), [])  # a new problem: its defaults
    cfg = compose_cfg(name, *small)
    p = build_problem(cfg.problem, dtype=torch.float64, device=torch.device("cpu"), seed=0)
    assert p.targets == tuple(cfg.problem.targets) and len(p.targets) >= 2 and list(p.targets) == sorted(p.targets, reverse=True)
    assert p.league_seconds == float(cfg.problem.league_seconds) and math.isfinite(p.league_seconds) and p.league_seconds > 0
    # the readers of recorded and shipped configs (no problem built) agree with the problem's own
    assert p.targets == targets.for_problem(name) and p.league_seconds == targets.league_seconds(name)
    assert p.has_inverse_simulator() == (type(p).inverse_simulator is not Problem.inverse_simulator)


def test_the_report_is_timed_phase_by_phase():
    """The Jacobian-power family's phases add up to about the step it timed."""
    cfg, p, model, batch = setup("toy", 64)
    update = build_update(p, model, cfg.optimizer)
    update(batch)
    t0 = time.perf_counter()
    result = update(batch)
    total = time.perf_counter() - t0
    assert 0 < sum(result.timings.values()) <= total
