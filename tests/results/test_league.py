"""The league's scores on hand-made frames with known answers, its search spaces and tuning
rule, and ``higbench-results --league`` on synthetic run files."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from higbench.results import league
from higbench.results.profile import performance_profile
from higbench.runfile.writer import RunFileWriter

# -- interval estimates ----------------------------------------------------------------------


def test_iqm_is_the_mean_of_the_middle_half():
    assert league.iqm([1, 2, 3, 4, 5, 6, 7, 8]) == pytest.approx(4.5)  # mean of 3, 4, 5, 6
    assert league.iqm([100, 1, 2, 3]) == pytest.approx(2.5)  # an outlier is cut
    assert league.iqm([1, 2, 3, math.inf]) == pytest.approx(2.5)  # inf (never reached) is cut too
    assert league.iqm([1, math.inf, math.inf, math.inf]) == math.inf  # most never reached
    assert math.isnan(league.iqm([]))


def test_bootstrap_of_a_constant_has_a_point_interval():
    assert league.bootstrap_ci([[2.0, 2.0, 2.0]], league.iqm, reps=200) == (2.0, 2.0, 2.0)


def test_bootstrap_is_stratified():
    # Two tasks of equal size, each constant: every stratified resample has the same pooled mean
    # (an unstratified one would not: it could draw all 1s).
    point, lo, hi = league.bootstrap_ci([[1.0] * 4, [3.0] * 4], np.mean, reps=500)
    assert (point, lo, hi) == (2.0, 2.0, 2.0)


def test_bootstrap_interval_covers_the_spread():
    point, lo, hi = league.bootstrap_ci([[1.0, 2.0, 3.0, 4.0, 5.0]], np.mean, reps=2000, seed=1)
    assert point == 3.0 and 1.0 <= lo < 3.0 < hi <= 5.0
    assert league.bootstrap_ci([[1.0, 2.0, 3.0, 4.0, 5.0]], np.mean, reps=2000, seed=1) == (point, lo, hi)  # seeded


def test_probability_of_improvement_counts_pairs_and_half_ties():
    assert league.probability_of_improvement([1, 2], [3, 4]) == 1.0
    assert league.probability_of_improvement([3, 4], [1, 2]) == 0.0
    assert league.probability_of_improvement([1], [1]) == 0.5
    assert league.probability_of_improvement([1, 3], [2]) == 0.5
    assert league.probability_of_improvement([1, 2, 3], [2]) == pytest.approx((1 + 0.5 + 0) / 3)


def test_probability_of_improvement_averages_over_tasks():
    point, lo, hi = league.probability_of_improvement_ci([([1, 1], [2, 2]), ([5, 5], [2, 2])], reps=200)
    assert (point, lo, hi) == (0.5, 0.5, 0.5)


# -- the integrated score --------------------------------------------------------------------


def test_integrated_score_known_answer_and_numeric_area():
    ratios = [1.0, 2.0, math.inf]
    assert league.integrated_score(ratios, 4.0) == pytest.approx((3 + 2 + 0) / 3 / 3)
    assert league.integrated_score([1.0, 1.0], 4.0) == 1.0
    assert league.integrated_score([5.0, math.nan], 4.0) == 0.0
    # The same area from the profile on a fine grid of tau (the step function's Riemann sum).
    times = pd.DataFrame({"problem": ["a", "b", "c"], "target": [1, 1, 1], "setting": ["s"] * 3, "ratio": ratios})
    taus = np.linspace(1, 4, 30001)
    rho = performance_profile(times, taus)["s"].to_numpy()
    assert np.trapezoid(rho, taus) / 3 == pytest.approx(league.integrated_score(ratios, 4.0), abs=1e-3)


# -- search spaces and the tuning rule -------------------------------------------------------


def test_leaders_name_the_lowest_setting_per_task_and_hig_s_rank():
    inf = math.inf
    table = pd.DataFrame({
        "task": ["a", "a", "a", "b", "b"],
        "setting": ["adam", "hig", "hig (paper)", "adam", "hig"],
        "final_test_loss": [(1.0, 0.5, 1.5), (3.0, 2.0, 4.0), (inf, inf, inf), (2.0, 1.0, 3.0), (1.0, 0.5, 2.5)],
    })  # fmt: skip
    best = league.leaders(table).set_index("task")
    assert best.loc["a", "best"] == "adam" and best.loc["a", "runner-up"] == "hig"
    assert bool(best.loc["a", "separated"])  # hig's interval [2, 4] lies above adam's [0.5, 1.5]
    assert (best.loc["a", "hig rank"], best.loc["a", "hig (paper) rank"]) == (2, 3)  # diverged last
    assert best.loc["b", "best"] == "hig" and not bool(best.loc["b", "separated"])  # [1, 3] overlaps [0.5, 2.5]


def test_every_shipped_optimizer_has_a_search_space():
    from higbench.config import config_dir

    optimizers = {p.stem for p in (Path(config_dir()) / "optimizer").glob("*.yaml")}
    assert optimizers <= set(league.all_spaces()), "conf/search/ lacks a space for some optimizer"


def test_sobol_trials_fill_the_log_range():
    space = {"optimizer.lr": {"low": 1e-4, "high": 1e-1, "log": True, "integer": False},
             "batch_size": {"low": 32, "high": 512, "log": True, "integer": True}}  # fmt: skip
    trials = league.sobol_trials(space, 8, seed=3)
    assert len(trials) == 8 and trials == league.sobol_trials(space, 8, seed=3)
    lrs = [t["optimizer.lr"] for t in trials]
    assert all(1e-4 <= lr <= 1e-1 for lr in lrs)
    assert min(lrs) < 1e-3 and max(lrs) > 1e-2  # log-uniform: both ends of the decades are visited
    assert {t["batch_size"] for t in trials} <= {32, 64, 128, 256, 512}


def test_a_bad_search_space_names_the_key(tmp_path):
    (tmp_path / "x.yaml").write_text(yaml.safe_dump({"space": {"optimizer.lr": {"low": 0, "high": 1}}}))
    with pytest.raises(ValueError, match=r"space.optimizer.lr: low=0"):
        league.load_space("x", tmp_path)
    with pytest.raises(ValueError, match="optimizer=nope: no search space"):
        league.load_space("nope", tmp_path)


def test_tuning_never_reads_the_test_loss():
    trials = pd.DataFrame(
        {"trial": [0, 1, 2], "status": ["completed", "completed", "diverged"], "final_val_loss": [0.3, 0.1, 0.01]}
    )
    # No test-loss column at all: the choice is made without it (the lowest validation loss;
    # the diverged trial does not count).
    assert league.best_trial(trials)["trial"] == 1
    with pytest.raises(ValueError, match="validation loss only"):
        league.best_trial(trials.assign(final_test_loss=[0.0, 1.0, 1.0]), metric="final_test_loss")


@pytest.fixture(scope="module")
def script():
    """The league's driver (higbench.league.driver, the ``higbench-league`` command)."""
    from higbench.league import driver

    return driver


def test_the_league_script_tunes_on_the_validation_loss():
    from higbench.league import driver

    source = Path(driver.__file__).read_text()
    assert "best_trial(" in source and "test_loss" not in source.split("def choose")[1].split("\ndef ")[0]


def test_the_league_leaves_out_what_cannot_run_with_the_cli_s_line(script):
    assert script.refusal("oscillator", "sip") == "optimizer=sip: problem oscillator has no inverse simulator"
    assert script.refusal("toy", "sip") is None and script.refusal("oscillator", "hig") is None


def test_an_interrupted_tuning_stops_the_league(script, tmp_path, monkeypatch):
    """A Ctrl-C during tuning went on to confirm settings chosen from part of the tuning (and
    to the next problem); now the league stops and says the same command continues."""
    launched = []

    def interrupted(jobs, root, **kw):
        launched.append(len(jobs))
        return list(jobs)[1:]  # all but one still not done

    monkeypatch.setattr(script, "run_missing", interrupted)
    monkeypatch.setattr(script, "calibration", lambda: {})
    argv = ["--problems", "toy", "--optimizers", "adam,sgd", "--paper", "", "--trials", "2", "--seeds", "1", "--studies", "1"]
    with pytest.raises(SystemExit, match=r"toy tuning run\(s\) not done .*the same command continues"):
        script.main([*argv, "--seconds", "1", "--root", str(tmp_path / "runs"), "--out", str(tmp_path / "out")])
    assert launched == [4]  # the tuning only: nothing confirmed


def test_per_problem_trials_and_scoped_overrides_reach_the_jobs(script, tmp_path, monkeypatch, capsys):
    """``--trials 1,toy=2`` tunes the toy on 2 trials and the oscillator on 1; ``--set
    toy/hig:threads=1`` reaches the toy's HIG jobs alone, over ``toy:threads=2`` given after it;
    a league key is refused by --set."""
    launched = []

    def stop(jobs, root, **kw):
        launched.append(list(jobs))
        return list(jobs)  # nothing done: the league stops after this problem's tuning

    monkeypatch.setattr(script, "run_missing", stop)
    monkeypatch.setattr(script, "calibration", lambda: {})
    common = ["--optimizers", "adam,hig", "--paper", "", "--seeds", "1", "--seconds", "1,toy=2", "--root", str(tmp_path),
              "--studies", "1"]  # fmt: skip
    for problem, trials in (("toy", 2), ("oscillator", 1)):
        with pytest.raises(SystemExit, match="tuning"):
            sets = ["--set", "toy/hig:threads=1", "--set", "toy:threads=2"]
            script.main(["--problems", problem, "--trials", "1,toy=2", *sets, *common])
        jobs = launched.pop()
        assert len(jobs) == 2 * trials
        assert {j.overrides["budget.seconds"] for j in jobs} == {2.0 if problem == "toy" else 1.0}
        threads = {j.overrides["optimizer"]: j.overrides.get("threads") for j in jobs}
        assert threads == ({"adam": "2", "hig": "1"} if problem == "toy" else {"adam": None, "hig": None})  # narrower wins
    assert script.main(["--problems", "toy", "--set", "seed=3", *common]) == 2
    assert "--set seed=3: seed is the league's own" in capsys.readouterr().err


def test_machine_lines_are_per_problem_and_hardware_and_calibrations_come_back(script, tmp_path):
    """A league trained on two machines (the Poisson rows on a GPU machine) reports each
    (problem, hardware) apart, and re-reads the calibration each invocation left beside its runs."""
    runs = pd.DataFrame({
        "problem.name": ["toy", "poisson", "poisson"], "env.device": ["cpu", "cuda", "cpu"],
        "env.device_name": ["", "NVIDIA H100", ""], "env.cpu_count": [2, 16, 16], "env.cpu_share": [0.9, 0.3, 1.0],
    })  # fmt: skip
    assert list(script.hardware(runs)) == ["CPU, 2 cores", "NVIDIA H100", "CPU, 16 cores"]
    groups = script.machine(runs)
    assert [(g["problem"], g["hardware"], g["runs"]) for g in groups] == [
        ("poisson", "CPU, 16 cores", 1), ("poisson", "NVIDIA H100", 1), ("toy", "CPU, 2 cores", 1)
    ]  # fmt: skip
    (tmp_path / "gpu-out").mkdir()
    (tmp_path / "gpu-out" / "league.json").write_text(json.dumps({"calibration": [{"matmul_50x256_s": 0.01}]}))
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "league.json").write_text(json.dumps({"calibration": [{"matmul_50x256_s": 9.0}]}))
    found = script.recorded_calibrations([tmp_path], tmp_path / "out")
    assert found == [{"matmul_50x256_s": 0.01, "file": "gpu-out/league.json"}]  # the report's own out left out


@pytest.mark.parametrize(
    "flags, line",
    [
        (["--set", "devic=cuda"], "--set (toy, adam: devic=cuda): devic=cuda: unknown key"),
        (["--set", "threads=0"], "--set (toy, adam: threads=0): threads=0: must be auto, null or an integer >= 1"),
        (["--set", "poison/adam:threads=1"], "poison/adam is not a problem, an optimizer or problem/optimizer"),
        (["--trials", "2,tyo=3"], "--trials tyo=3: no problem tyo (conf/problem/: "),
        (["--seconds", "0"], "--seconds 0: must be positive"),
        (["--seconds", "inf"], "--seconds inf: must be positive and finite"),
        (["--seconds", "nan"], "--seconds nan: must be positive and finite"),
        (["--optimizers", "adma"], "--optimizers adma: no optimizer adma"),
        (["--problems", "tyo"], "--problems tyo: no problem tyo"),
        (["--out", "TMP/a-file"], "a-file: an existing file; --out names a folder"),
        (["--report-only"], "no league runs or tables there"),
    ],
)
def test_a_bad_protocol_flag_is_one_line_before_any_run(script, tmp_path, monkeypatch, capsys, flags, line):
    """A typo in a --set scope trained on the wrong device without a word; a bad --set value made
    every optimizer 'left out' and ended in a KeyError; --seconds 0 fell back to the default;
    an unknown optimizer or problem, --seconds inf or nan, an --out naming a file, --report-only of
    an empty root gave tracebacks; a refused --set first created the root and ran the calibration."""
    launched, calibrated = [], []
    monkeypatch.setattr(script, "run_missing", lambda jobs, root, **kw: launched.append(jobs) or [])
    monkeypatch.setattr(script, "calibration", lambda: calibrated.append(1) or {})
    (tmp_path / "a-file").write_text("mine\n")
    flags = [f.replace("TMP", str(tmp_path)) for f in flags]
    argv = ["--problems", "toy", "--optimizers", "adam", "--trials", "1", "--seeds", "1", "--seconds", "1", *flags]
    out = [] if "--out" in flags else ["--out", str(tmp_path / "out")]
    assert script.main([*argv, "--root", str(tmp_path / "runs"), *out]) == 2
    err = capsys.readouterr().err.strip()
    assert line in err and len(err.splitlines()) == 1, err
    assert not launched and not calibrated and not (tmp_path / "runs").exists()
    assert (tmp_path / "a-file").read_text() == "mine\n"


# -- --league on synthetic run files ---------------------------------------------------------


def write_league_run(root: Path, name: str, optimizer: str, seed: int, losses, *, overrides=(), updates_per_eval=10, lr=None):
    """A completed run of the toy problem whose test and validation curves are ``losses``."""
    config = {"problem": {"name": "toy", "targets": [1e-1, 1e-2]}, "optimizer": {"name": optimizer}, "seed": seed,
              "budget": {"seconds": 5.0, "max_updates": None}}  # fmt: skip
    if lr is not None:
        config["optimizer"]["lr"] = lr
    w = RunFileWriter(
        root / name / "run.h5", yaml.safe_dump(config), ["problem=toy", f"optimizer={optimizer}", f"seed={seed}", *overrides],
        env={"hostname": "test"}, meta={"problem": "toy", "optimizer": optimizer},
    )  # fmt: skip
    for i, loss in enumerate(losses):
        w.append_row("curves", {"step": i * updates_per_eval, "epoch": 0, "wall_time": float(i), "train_loss": loss,
                                "test_loss": loss, "val_loss": loss * 1.1, "rss_mb": 1.0})  # fmt: skip
    w.flush()
    w.f.attrs["steps"] = (len(losses) - 1) * updates_per_eval
    w.f.attrs["wall_time"] = float(len(losses) - 1)
    w.close("completed", "", (len(losses) - 1) * updates_per_eval)


def test_results_league_prints_scores_and_leaves_tuning_runs_out(tmp_path, capsys):
    from higbench.results.__main__ import main

    for seed in (0, 1, 2):  # hig reaches 1e-2 at 1 s in 1 update, adam at 3 s in 30 updates
        write_league_run(tmp_path, f"h{seed}", "hig", seed, [1.0, 0.005, 0.001], overrides=["optimizer.lr=0.5"],
                         updates_per_eval=1)  # fmt: skip
        write_league_run(tmp_path, f"a{seed}", "adam", seed, [1.0, 0.5, 0.05, 0.009], overrides=["optimizer.lr=0.01"])
    write_league_run(tmp_path, "tune", "adam", 1000, [1.0, 1e-6], overrides=["optimizer.lr=0.1"])  # a tuning seed
    assert main([str(tmp_path), "--league"]) == 0
    out = capsys.readouterr().out
    assert "6 scored runs" in out and "1 tuning run(s) left out" in out
    seconds = out.split("equal wall clock")[1].split("equal updates")[0]
    hig_row = next(line for line in seconds.splitlines() if line.startswith("hig"))
    adam_row = next(line for line in seconds.splitlines() if line.startswith("adam"))
    # hig: fastest on both targets (score 1); adam: 1e-1 at 2 s (2x), 1e-2 at 3 s (3x): (2 + 1) / 2 / 3
    assert hig_row.split()[-1] == "1.000" and adam_row.split()[-1] == f"{(2 + 1) / 2 / 3:.3f}"
    assert "P(hig ends below X)" in out and "adam" in out.split("P(hig ends below X)")[1]
    assert "0.00123 [0.00123, 0.00123]" not in out  # the test loss, not the val loss (1.1x), is the table's
    assert "0.001 [0.001, 0.001]" in out


def test_the_bootstraps_row_wise_iqm_matches_iqm():
    rng = np.random.default_rng(0)
    matrix = rng.lognormal(size=(50, 7))
    matrix[3, 2] = math.inf  # one cut, and a row where inf stays
    matrix[4, :5] = math.inf
    np.testing.assert_allclose(league._iqm_rows(matrix), [league.iqm(row) for row in matrix], rtol=1e-12)


def test_profile_targets_come_from_the_problem_configs():
    from higbench.results.targets import for_problem, of_runs

    runs = pd.DataFrame(
        {"problem.name": ["toy", "toy", "poisson"], "problem.targets": [(1e-2, 1e-3), None, None],
         "started": ["2026-01-01T00:00:00+0000"] * 3}
    )  # fmt: skip
    # toy: its run's stored targets; poisson's runs predate the key: the shipped config's
    assert of_runs(runs) == {"toy": [1e-2, 1e-3], "poisson": list(for_problem("poisson"))}


def test_more_trials_keep_the_first_ones():
    # A league run again with more trials reuses its earlier runs: the first points stay the same.
    space = league.load_space("hig")
    assert league.sobol_trials(space, 8)[:4] == league.sobol_trials(space, 4)


def test_two_settings_under_one_league_label_are_refused(tmp_path, capsys):
    """Two confirmed configurations of one optimizer on one task would be scored as one setting."""
    from higbench.results.__main__ import main

    for seed, lr in ((0, 0.01), (1, 0.01), (2, 0.02)):
        write_league_run(tmp_path, f"a{seed}", "adam", seed, [1.0, 0.05], overrides=[f"optimizer.lr={lr}"], lr=lr)
    assert main([str(tmp_path), "--league"]) == 2
    err = capsys.readouterr().err
    assert "task toy: adam has runs of 2 different settings" in err, err


def test_the_profile_draws_the_leaders_and_hig_in_colour():
    flat = np.zeros(3)
    bands = {name: (np.full(3, level), flat, flat) for name, level in
             [("a", 0.9), ("b", 0.8), ("c", 0.1), ("hig", 0.0), ("hig (paper)", 0.05)]}  # fmt: skip
    assert league.highlighted(bands, top=2) == {"a", "b", "hig", "hig (paper)"}
