"""The league's protocol, fair to every optimizer: its own Sobol stream, a tuning seed per study,
search spaces that contain every shipped setting, tuning on what is scored, baselines set up as
their authors advise, and the scored runs one per identity on one hardware class per task."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import pandas as pd
import pytest
import torch
import yaml

from higbench.config import config_dir
from higbench.optim.split import SplitOptimizer
from higbench.results import league

CONF = Path(config_dir())


# -- trials ----------------------------------------------------------------------------------


def test_two_optimizers_with_same_shaped_spaces_get_different_points():
    # Before, every optimizer drew the same scrambled Sobol seed: Adam, AdamW, SOAP and Shampoo
    # tried the same 4 (lr, b) points, HIG, GN and LM the same 4 unit points.
    space = league.load_space("adam")
    assert league.load_space("adamw") == space
    adam, adamw = league.trial_points("adam", space, 4, study=0), league.trial_points("adamw", space, 4, study=0)
    assert all(a != b for a, b in zip(adam, adamw))
    assert league.trial_points("adam", space, 4, study=1) != adam  # a second study is a new stream
    assert league.trial_points("adam", space, 8, study=0)[:4] == adam  # more trials keep the first ones
    assert league.stream_seed("adam", 0) == league.stream_seed("adam", 0)  # stable across processes (CRC-32)


def test_tuning_seeds_are_one_per_study_and_never_a_confirmation_seed():
    seeds = [league.tuning_seed(s) for s in range(5)]
    assert seeds == [1000, 1001, 1002, 1003, 1004]
    assert all(league.is_tuning_seed(pd.Series(seeds))) and not league.is_tuning_seed(pd.Series([0, 9, 999])).any()
    with pytest.raises(ValueError, match="study=-1"):
        league.tuning_seed(-1)


# -- every shipped setting inside its search space -------------------------------------------


def _get(node: dict, dotted: str):
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return node


def shipped_value(problem: str, optimizer: str, key: str):
    """``key`` of the config the CLI composes for (problem, optimizer): the pair's file
    (conf/problem_optimizer/, the paper's settings; a global package), else the optimizer's or
    the problem's default."""
    pair = CONF / "problem_optimizer" / f"{problem}_{optimizer}.yaml"
    if pair.is_file() and (value := _get(yaml.safe_load(pair.read_text()) or {}, key)) is not None:
        return value
    if key.startswith("optimizer."):
        return _get(yaml.safe_load((CONF / "optimizer" / f"{optimizer}.yaml").read_text()), key.removeprefix("optimizer."))
    problem_file = yaml.safe_load((CONF / "problem" / f"{problem}.yaml").read_text())
    value = _get(problem_file, key)
    parents = [d for d in problem_file.get("defaults", []) if isinstance(d, str) and d != "_self_"]
    return value if value is not None or not parents else shipped_value(parents[0], optimizer, key)  # dipole_cnn: dipole's


def test_every_search_space_contains_every_shipped_setting():
    # Before: HIG's lr in [0.1, 2] left out the paper's Poisson lr 0.02 (and Adam's space the
    # toy's 0.3, the batch sizes the dipole's 16, L-BFGS's max_iter its default 20).
    outside = []
    for problem in sorted(p.stem for p in (CONF / "problem").glob("*.yaml")):
        for optimizer, space in league.all_spaces().items():
            for key in space:
                value = shipped_value(problem, optimizer, key)
                assert value is not None, f"{problem}/{optimizer}: {key} is set nowhere"
                if not league.in_space(space, key, value):
                    low, high = space[key]["low"], space[key]["high"]
                    outside.append(f"{problem}/{optimizer}: {key}={value} outside [{low:g}, {high:g}]")
    assert not outside, outside


def test_the_lookup_reads_the_paper_s_setting():
    assert shipped_value("poisson", "hig", "optimizer.lr") == 0.02 and shipped_value("toy", "hig", "optimizer.lr") == 1.0
    assert shipped_value("dipole", "adam", "batch_size") == 16


def test_soap_and_shampoo_tune_their_preconditioner_frequency():
    assert "optimizer.precondition_frequency" in league.load_space("soap")
    assert "optimizer.preconditioning_compute_steps" in league.load_space("shampoo")


# -- Muon as its authors advise ----------------------------------------------------------------


def test_muon_takes_hidden_weights_only_and_adamw_the_first_and_last_layers():
    torch.manual_seed(0)
    model = torch.nn.Sequential(torch.nn.Linear(3, 8), torch.nn.Tanh(), torch.nn.Linear(8, 8), torch.nn.Tanh(),
                                torch.nn.Linear(8, 8), torch.nn.Tanh(), torch.nn.Linear(8, 2))  # fmt: skip
    parts = yaml.safe_load((CONF / "optimizer" / "muon.yaml").read_text())["parts"]
    split = SplitOptimizer(model.parameters(), parts=parts)
    muon = [p for g in split.parts["hidden_matrices"].param_groups for p in g["params"]]
    adamw = [p for g in split.parts["rest"].param_groups for p in g["params"]]
    assert [id(p) for p in muon] == [id(model[2].weight), id(model[4].weight)]
    assert {id(model[0].weight), id(model[6].weight)} <= {id(p) for p in adamw}
    search = league.load_space("muon")
    assert {"optimizer.parts.hidden_matrices.lr", "optimizer.parts.rest.lr"} <= set(search)


# -- tuning selects on what is scored --------------------------------------------------------


def test_tuning_selects_on_the_time_to_the_validation_target_when_curves_exist():
    trials = pd.DataFrame({"trial": [0, 1], "path": ["t0", "t1"], "status": ["completed"] * 2,
                           "final_val_loss": [1e-4, 1e-3]})  # fmt: skip
    # trial 1 reaches 1e-2 at 1 s, trial 0 at 3 s but ends lower
    curves = pd.DataFrame({"path": ["t0"] * 4 + ["t1"] * 4, "wall_time": [0, 1, 2, 3] * 2, "step": [0, 10, 20, 30] * 2,
                           "val_loss": [1, 0.5, 0.1, 0.005, 1, 0.009, 0.002, 1e-3]})  # fmt: skip
    best, rule = league.choose_trial(trials, curves, target=1e-2)
    assert best["trial"] == 1 and "time to the validation target 0.01" in rule
    best, rule = league.choose_trial(trials)  # no curves: the final validation loss, and it says so
    assert best["trial"] == 0 and rule.startswith("final validation loss")
    best, rule = league.choose_trial(trials, curves, target=1e-9)  # nobody reached it: said too
    assert best["trial"] == 0 and "no trial reached" in rule


# -- the scored runs -------------------------------------------------------------------------


def _runs(**columns) -> pd.DataFrame:
    n = len(next(iter(columns.values())))
    base = {"status": ["completed"] * n, "problem.name": ["toy"] * n, "overrides": [""] * n, "final_test_loss": [0.1] * n,
            "config_id": [f"c{i}" for i in range(n)], "path": [f"r{i}" for i in range(n)]}  # fmt: skip
    return pd.DataFrame({**base, **columns})


def test_two_leagues_into_one_root_do_not_score_copies_as_seeds():
    runs = _runs(seed=[0, 0, 1], **{"optimizer.name": ["adam"] * 3}, config_id=["same", "same", "other"])
    scored = league.league_runs(runs, {})
    assert len(scored) == 2 and sorted(scored["seed"]) == [0, 1]


def test_league_role_names_paper_and_default_and_leaves_tuning_out():
    runs = _runs(seed=[0, 0, 0, 1000], **{"optimizer.name": ["hig", "hig", "adam", "adam"]},
                 league_role=["confirm", "paper", "default", "tune"])  # fmt: skip
    scored = league.league_runs(runs, league.all_spaces())
    assert sorted(scored["league_setting"]) == ["adam (default)", "hig", "hig (paper)"]


def test_a_problem_whose_confirmation_is_under_way_is_named_and_left_out_of_the_scores():
    """Known answer: adam and hig tuned on the toy; hig confirmed on 2 seeds, adam on 1, sgd (not
    tuned here) on 2; a stopped sitting. Whole once adam has its second seed."""
    opts = ["adam", "hig", "adam", "hig", "hig", "sgd", "sgd"]
    runs = _runs(seed=[1000, 1000, 0, 0, 1, 0, 1], **{"optimizer.name": opts},
                 league_role=["tune", "tune", "confirm", "confirm", "confirm", "default", "default"])  # fmt: skip
    assert league.confirmation_under_way(runs) == {"toy": "1 of 3 (task, setting) pairs at fewer than 2 seeds"}
    no_curves = pd.DataFrame(columns=["path", "test_loss", "val_loss"])
    assert league.league_frames(runs, no_curves, {})[0].empty
    assert "not scored until its confirmation is whole: toy (1 of 3" in league.format_league(runs, no_curves, {})
    no_adam = runs[runs["optimizer.name"] != "adam"].copy()
    no_adam.loc[len(runs)] = runs.iloc[0]  # adam tuned, never confirmed
    assert league.confirmation_under_way(no_adam) == {"toy": "not yet run on every task: adam"}
    whole = pd.concat([runs, _runs(seed=[1], **{"optimizer.name": ["adam"]}, league_role=["confirm"], config_id=["c9"])])
    assert league.confirmation_under_way(whole) == {}
    # the shipped settings run last: once hig ran at the paper's settings on another problem, a
    # problem that tuned hig is whole only with hig (paper) too (sgd's default rows: not tuned here)
    elsewhere = _runs(seed=[0, 1], **{"optimizer.name": ["hig"] * 2}, league_role=["paper"] * 2,
                      config_id=["o0", "o1"], path=["o0", "o1"], **{"problem.name": ["osc"] * 2})  # fmt: skip
    two = pd.concat([whole, elsewhere], ignore_index=True)
    assert league.confirmation_under_way(two) == {"toy": "not yet run at its shipped settings on every task: hig"}
    shipped = _runs(seed=[0, 1], **{"optimizer.name": ["hig"] * 2}, league_role=["paper"] * 2, config_id=["t0", "t1"],
                    path=["t0", "t1"])  # fmt: skip
    assert league.confirmation_under_way(pd.concat([two, shipped], ignore_index=True)) == {}


def test_an_optimizer_whose_every_tuning_trial_diverged_has_nothing_to_confirm_and_is_named():
    """Known answer: sgd's two trials on the toy diverged (the driver chose no setting, so it ran
    no confirmation); hig's tuned setting is confirmed on 2 seeds. The toy is whole and scored,
    and the report names sgd. A trial that finished, even badly, is a setting: not named."""
    runs = _runs(seed=[1000, 1000, 1000, 0, 1], **{"optimizer.name": ["sgd", "sgd", "hig", "hig", "hig"]},
                 league_role=["tune", "tune", "tune", "confirm", "confirm"], final_val_loss=[math.nan, math.inf, 0.1, 0.1, 0.1],
                 status=["diverged", "diverged", "completed", "completed", "completed"],
                 league_job=["tune/toy/sgd/0/0", "tune/toy/sgd/0/1", "tune/toy/hig/0/0", "", ""])  # fmt: skip
    assert league.without_a_setting(runs) == {"toy": ["sgd"]}
    assert league.confirmation_under_way(runs) == {}
    no_curves = pd.DataFrame(columns=["path", "test_loss", "val_loss"])
    text = league.format_league(runs, no_curves, {})
    assert "no setting to confirm (every tuning trial diverged or failed): toy: sgd" in text
    assert "not scored until" not in text
    finished = runs.assign(status=["completed", "diverged", *runs["status"][2:]], final_val_loss=[50.0, math.inf, 0.1, 0.1, 0.1])
    assert league.without_a_setting(finished) == {}
    assert league.confirmation_under_way(finished) == {"toy": "not yet run on every task: sgd"}


def test_each_problem_gets_its_own_aggregate_beside_the_one_across_all():
    """Known answer: a leads every seed on p, b on q; across both they tie (IQM 0.5 each), on each
    problem alone the leader scores 1 and the other 0. One problem alone: no second table."""
    scored = pd.DataFrame({
        "problem.name": ["p"] * 8 + ["q"] * 8, "task": ["p"] * 8 + ["q"] * 8,
        "league_setting": (["a"] * 4 + ["b"] * 4) * 2, "seed": [0, 1, 2, 3] * 4, "status": ["completed"] * 16,
        "final_test_loss": [1e-3] * 4 + [1e-1] * 4 + [1e-1] * 4 + [1e-3] * 4,
    })  # fmt: skip
    overall = league.aggregate_table(scored, reference="a").set_index("setting")["iqm"]
    assert overall["a"] == pytest.approx(0.5) and overall["b"] == pytest.approx(0.5)
    text = "\n".join(league.per_problem_aggregates(scored))
    p_part, q_part = text.split("across q's tasks alone")
    assert "across p's tasks alone (p)" in p_part
    iqm = {(part, line.split()[0]): float(line.split()[2]) for part, body in (("p", p_part), ("q", q_part))
           for line in body.splitlines() if line.split()[:1] in (["a"], ["b"])}  # fmt: skip
    assert iqm == {("p", "a"): 1.0, ("p", "b"): 0.0, ("q", "a"): 0.0, ("q", "b"): 1.0}
    assert league.per_problem_aggregates(scored[scored["problem.name"] == "p"]) == []


def test_a_task_that_mixes_hardware_is_split_into_one_table_per_class():
    runs = _runs(seed=[0, 0, 0], **{"optimizer.name": ["hig", "adam", "sgd"]}, hardware=["GPU", "CPU", "CPU"])
    scored = league.league_runs(runs, {})
    assert sorted(set(scored["task"])) == ["toy [CPU]", "toy [GPU]"]
    assert "one class per task" in league.hardware_line(scored)


def test_the_hardware_line_counts_the_machines_of_one_class_that_trained_a_task():
    scored = pd.DataFrame({
        "task": ["a", "a", "a", "b", "b"], "hardware": ["CPU, 2 cores"] * 5,
        "env.hostname": ["n1", "n1", "n2", "n1", None], "env.boot_time": ["t1", "t1", "t2", "t1", None],
    })  # fmt: skip
    line = league.hardware_line(scored)
    assert "a: CPU, 2 cores on 2 machines;" in line  # n1 and n2: equal seconds need not be equal work
    assert "b: CPU, 2 cores;" in line  # one named machine, one run that named none
    assert line.endswith("machine not recorded by 1 of 5 scored runs")
    old = scored.drop(columns=["env.hostname", "env.boot_time"])  # tables written before runs named their machine
    assert league.hardware_line(old).endswith("a: CPU, 2 cores; b: CPU, 2 cores; machine not recorded by 5 of 5 scored runs")
    # tables merged from older runs hold the machine columns as all-NaN floats: read as unnamed, no warning
    unnamed = scored.assign(**{"env.hostname": float("nan"), "env.boot_time": float("nan")})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert league.hardware_line(unnamed).endswith("machine not recorded by 5 of 5 scored runs")


# -- AlgoPerf's score: targets, budgets, gates -------------------------------------------------


def test_the_validation_target_is_the_best_reference_median_over_at_least_five_reruns():
    name, target = league.validation_target({"adam": [5, 4, 3, 2, 1], "lm": [0.1, 9, 9, 8, 0.2]})
    assert (name, target) == ("adam", 3.0)  # lm's best rerun is lower (0.1), its median (8) is not
    with pytest.raises(ValueError, match="lm has 3 reruns; need at least 5"):
        league.validation_target({"adam": [1] * 5, "lm": [1, 2, 3]})
    assert league.budget_from_target([10.0, 12.0, 11.0, 13.0, math.inf]) == pytest.approx(36.0)


def test_time_to_target_scores_each_problem_the_same_and_held_out_variants_gate():
    scored = pd.DataFrame({
        "task": ["p", "p", "q", "q", "p v", "p v"], "league_setting": ["a", "b"] * 3, "seed": [0] * 6,
        "status": ["completed"] * 6, "path": [f"r{i}" for i in range(6)],
    })  # fmt: skip
    reach_at = {"r0": 1.0, "r1": 2.0, "r2": 4.0, "r3": 2.0, "r4": 1.0, "r5": None}  # r5: b never reaches the variant's
    rows = []
    for run, t in reach_at.items():
        rows += [{"path": run, "wall_time": 0.0, "step": 0, "val_loss": 1.0},
                 {"path": run, "wall_time": t or 9.0, "step": 1, "val_loss": 0.01 if t else 1.0}]  # fmt: skip
    table = league.algoperf_table(scored, pd.DataFrame(rows), targets={"p": 0.1, "q": 0.1, "p v": 0.1},
                                  budgets={"p": 10, "q": 10, "p v": 10}, held_out={"p": ["p v"]})  # fmt: skip
    table = table.set_index("setting")
    # a: fastest on p (1), 2x on q; b: 2x on p, fastest on q: the same area, each problem weighing 1/2
    ignored = table["score, gates ignored"]
    assert ignored["a"] == pytest.approx(ignored["b"]) == pytest.approx((3 + 2) / 2 / 3)
    assert table.loc["b", "gates failed"] == "p v" and table.loc["a", "gates failed"] == ""
    # AlgoPerf's rule: b fails p's held-out variant, so its time on p counts as inf: only q scores
    assert table.loc["a", "score"] == pytest.approx(5 / 6) and table.loc["b", "score"] == pytest.approx(3 / 2 / 3)
    over_budget = league.algoperf_table(scored, pd.DataFrame(rows), targets={"p": 0.1, "q": 0.1},
                                        budgets={"p": 1.5, "q": 10}).set_index("setting")  # fmt: skip
    assert math.isinf(over_budget.loc["b", "s to target: p"])  # 2 s is past p's 1.5 s budget
    # the fastest on p fails p's gate: AlgoPerf takes the fastest after the gate, so b's 2 s is the best on p
    swapped = scored.assign(league_setting=["a", "b", "a", "b", "b", "a"])  # now a never reaches p's variant
    a_fails = league.algoperf_table(swapped, pd.DataFrame(rows), targets={"p": 0.1, "q": 0.1, "p v": 0.1},
                                    budgets={"p": 10, "q": 10, "p v": 10}, held_out={"p": ["p v"]})  # fmt: skip
    a_fails = a_fails.set_index("setting")
    assert a_fails.loc["a", "gates failed"] == "p v" and a_fails.loc["b", "gates failed"] == ""
    assert a_fails.loc["b", "score"] == pytest.approx(1.0)  # fastest on q, and on p once a is out
    assert a_fails.loc["a", "score"] == pytest.approx((0 + 2) / 2 / 3)  # p: out; q: 2x the fastest


def test_the_report_prints_the_algoperf_table_when_targets_and_budgets_are_given():
    runs = pd.DataFrame({
        "path": ["a0", "a1", "b0", "b1"], "status": ["completed"] * 4, "problem.name": ["toy"] * 4,
        "optimizer.name": ["adam", "adam", "sgd", "sgd"], "overrides": ["optimizer.lr=0.1"] * 4, "seed": [0, 1, 0, 1],
        "final_test_loss": [0.01, 0.02, 0.5, 0.6], "final_val_loss": [0.01, 0.02, 0.5, 0.6],
        "config_id": ["a0", "a1", "b0", "b1"], "problem.targets": [(0.1,)] * 4,
    })  # fmt: skip
    curves = pd.DataFrame({"path": [p for p in runs["path"] for _ in range(2)], "wall_time": [0.0, 2.0] * 4,
                           "step": [0, 5] * 4, "test_loss": [1, 0.01, 1, 0.02, 1, 0.5, 1, 0.6],
                           "val_loss": [1, 0.01, 1, 0.02, 1, 0.5, 1, 0.6]})  # fmt: skip
    text = league.format_league(runs, curves, league.all_spaces(), validation_targets={"toy": 0.05}, budgets={"toy": 6.0})
    algoperf = text.split("AlgoPerf:")[1].split("targets (problem.targets")[0]
    assert "toy: target 0.05, budget 6 s" in algoperf
    rows = {line.split()[0]: line.split() for line in algoperf.splitlines()[2:] if line.strip()}
    assert float(rows["adam"][1]) == 1.0 and float(rows["sgd"][1]) == 0.0  # sgd never reaches 0.05
    assert "AlgoPerf" not in league.format_league(runs, curves, league.all_spaces())  # no target-setting runs: no table


def test_a_problem_nobody_has_run_yet_is_left_out_of_the_score_not_failed_by_everyone():
    # a league run in pieces: targets for p and q, confirmation runs on p only; b has not run p's variant
    scored = pd.DataFrame({"task": ["p", "p", "p v"], "league_setting": ["a", "b", "a"], "seed": [0] * 3,
                           "status": ["completed"] * 3, "path": ["r0", "r1", "r2"]})  # fmt: skip
    rows = [{"path": r, "wall_time": w, "step": k, "val_loss": v}
            for r in ("r0", "r1", "r2") for k, (w, v) in enumerate([(0.0, 1.0), (1.0, 0.01)])]  # fmt: skip
    targets = {"p": 0.1, "q": 0.1, "p v": 0.1, "q v": 0.1}
    held_out = {"p": ["p v"], "q": ["q v"]}
    assert league.problems_in_play(scored, targets, held_out) == (["p"], ["q"])
    table = league.algoperf_table(scored, pd.DataFrame(rows), targets, budgets=dict.fromkeys(targets, 10),
                                  held_out=held_out).set_index("setting")  # fmt: skip
    assert "s to target: q" not in table  # q is waiting, not inf for everyone
    assert table.loc["a", "score"] == pytest.approx(1.0)  # fastest on the one problem run
    assert table.loc["a", "gates failed"] == "" and table.loc["b", "gates failed"] == ""  # q v: never a gate yet
    assert table.loc["b", "gates not run"] == "p v" and table.loc["a", "gates not run"] == ""
