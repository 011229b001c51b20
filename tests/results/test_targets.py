"""One owner per fact: a problem's targets come from its config, and one time-to-target rule
is used by the index, the league and scripts/time_to_loss.py."""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from synthetic import write_run

from higbench.results import targets

ROOT = Path(__file__).resolve().parents[2]
PROBLEMS = sorted(p.stem for p in (ROOT / "conf" / "problem").glob("*.yaml"))


def _yaml_problem(name: str) -> dict:
    conf = yaml.safe_load((ROOT / "conf" / "problem" / f"{name}.yaml").read_text())
    node: dict = {}
    for base in conf.get("defaults", []):
        if base != "_self_":
            node |= _yaml_problem(base)
    return node | conf.get("problem", {})


@pytest.mark.parametrize("name", PROBLEMS)
def test_every_shipped_problem_owns_its_targets_and_league_budget(name):
    levels = targets.for_problem(name)
    assert levels == tuple(_yaml_problem(name)["targets"])
    assert levels and all(t > 0 for t in levels) and list(levels) == sorted(levels, reverse=True), levels
    assert targets.league_seconds(name) == _yaml_problem(name)["league_seconds"] > 0


def test_a_runs_stored_targets_win_over_the_shipped_ones():
    stored = {"problem": {"name": "toy", "targets": [0.5, 0.05]}}
    assert targets.for_problem(stored) == (0.5, 0.05)
    assert targets.for_problem(stored["problem"]) == (0.5, 0.05)  # the problem node alone
    assert targets.for_problem({"problem": {"name": "toy"}}) == targets.for_problem("toy")  # predates the key
    assert targets.for_problem({"problem": {"name": "my_own_problem"}}) == ()  # out of tree, none declared
    assert targets.for_problem("../problem/toy") == ()  # never a path outside conf/problem
    for bad in ("1e-3", ["a"], [1e-3] * (targets.MAX_TARGETS + 1)):  # a crafted file's: the shipped ones instead
        assert targets.for_problem({"problem": {"name": "toy", "targets": bad}}) == targets.for_problem("toy")
    from omegaconf import OmegaConf  # the composed config the CLI holds (its end-of-run summary)

    assert targets.for_problem(OmegaConf.create({"problem": {"name": "toy", "targets": [0.1]}})) == (0.1,)


def test_the_rule_is_the_first_evaluation_at_or_below_the_target():
    loss = [1.0, 0.3, float("nan"), 0.1, 0.05, 0.1]
    assert targets.reach_index(loss, 0.1) == 3  # at or below, the first one; NaN never counts
    assert targets.reach_index(loss, 0.01) is None
    assert targets.time_to(loss, [0, 1, 2, 3, 4, 5], 0.3) == 1.0
    assert targets.time_to(loss, [0, 1, 2, 3, 4, 5], 0.01) == math.inf


def test_index_league_and_time_to_loss_script_read_the_same_times(tmp_path):
    """A toy run passes its targets (1e-2 .. 1e-5) at known evaluations (wall_time 0.5 s apart):
    the index's time_to columns, the league's reach and the script's table agree with the rule."""
    from higbench.results.index import load_runs, threshold_column
    from higbench.results.league import reach

    loss = [1.0, 0.02, 0.009, 4e-4, 9e-5, 2e-5]
    path = write_run(tmp_path / "r" / "run.h5", test_loss=loss)
    expected = {t: targets.time_to(loss, 0.5 * np.arange(len(loss)), t) for t in targets.for_problem("toy")}
    assert expected == {1e-2: 1.0, 1e-3: 1.5, 1e-4: 2.0, 1e-5: math.inf}

    runs, curves = load_runs(tmp_path, curves=True)
    for t, seconds in expected.items():
        got = runs.loc[0, threshold_column(t)]
        assert (got == seconds) if math.isfinite(seconds) else math.isnan(got), t
        assert reach(curves, t)[0] == seconds
    assert not [c for c in runs.columns if c.startswith("time_to_") and float(c[8:]) not in expected]

    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import time_to_loss
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    row = time_to_loss.summarise(path)
    assert {k: v for k, v in row.items() if k.startswith("t_")} == {
        time_to_loss.column(t): (s if math.isfinite(s) else None) for t, s in expected.items()
    }


# Lists of loss levels, and the rule, written anywhere but higbench/results/targets.py
DUPLICATES = re.compile(
    r"^\s*[A-Z_]*(THRESHOLDS|TARGETS|ADAM_PAPER_LR|BUDGET_S)\b\s*[:=]"  # a module-level list of levels
    r"|1e-3, 1e-4, 1e-5|1\.0e-3, 1\.0e-4"  # the paper's levels typed again
    r"|flatnonzero\(.*<=|\[\"test_loss\"\] <= ",  # the time-to-target rule written again
    re.M,
)


def test_no_other_module_holds_targets_or_the_time_to_target_rule():
    found = []
    for path in sorted([*(ROOT / "higbench").rglob("*.py"), *(ROOT / "scripts").glob("*.py")]):
        if path.name == "targets.py" and path.parent.name == "results":
            continue
        for m in DUPLICATES.finditer(path.read_text()):
            found.append(f"{path.relative_to(ROOT)}: {m.group(0).strip()}")
    assert not found, found


def test_profile_without_targets_times_the_problem_configs_targets(tmp_path, capsys):
    """higbench-results --plot: toy runs whose files predate problem.targets are timed at the
    shipped toy config's targets; a problem whose runs recorded their own are timed at those."""
    from higbench.results.__main__ import main as results_main

    for seed in range(2):
        write_run(tmp_path / f"toy{seed}/run.h5", config_extra={"seed": seed}, test_loss=[1.0, 0.05, 0.004])
        write_run(tmp_path / f"osc{seed}/run.h5", problem="oscillator", problem_extra={"targets": [0.5, 0.04]},
                  config_extra={"seed": seed}, test_loss=[1.0, 0.3, 0.03])  # fmt: skip
    assert results_main([str(tmp_path), "--plot", str(tmp_path / "c.png")]) == 0
    rows = [line.split(" <= ")[:2] for line in capsys.readouterr().out.splitlines() if " <= " in line]
    timed = {(p.strip(), float(rest.split()[0])) for p, rest in rows}
    assert timed == {("toy", t) for t in targets.for_problem("toy")} | {("oscillator", 0.5), ("oscillator", 0.04)}
