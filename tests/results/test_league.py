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

from higbench.results import league, league_figures
from higbench.results.profile import performance_profile
from higbench.runfile.writer import RunFileWriter

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


def test_the_final_loss_table_leads_by_median_and_flags_a_row_that_diverged_everywhere():
    inf = math.inf
    scored = pd.DataFrame({
        "task": ["a"] * 9,
        "league_setting": ["adam"] * 3 + ["hig"] * 3 + ["hig (paper)"] * 3,
        "seed": [0, 1, 2] * 3,
        "status": ["completed"] * 6 + ["diverged"] * 3,
        "final_test_loss": [1.0, 0.5, 1.5, 0.01, 3.0, 4.0, 1e5, inf, math.nan],
    })  # fmt: skip
    table = league.final_loss_table(scored).set_index("setting")
    assert table.loc["adam", "leader"] and table.loc["adam", "median"] == 1.0  # hig's mean (2.3) is higher, its min lower
    assert table.loc["hig", "p_leader_below"] == pytest.approx(6 / 9)  # adam below hig on 6 of 9 pairs
    assert table.loc["hig", "seeds"] == [0.01, 3.0, 4.0] and table.loc["hig", "coverage"] == pytest.approx(0.75)
    assert table.loc["hig (paper)", "seeds"] == [inf, inf, inf]  # a finite blow-up scores as a NaN does
    assert table.loc["hig (paper)", "flag"] == "diverged on every seed"
    assert not table["separated"].any()  # 3 seeds against 2 rivals: Holm's smallest p is 0.1
    text = league.format_final_loss_table(league.final_loss_table(scored))
    assert "coverage 75.0% at n=3" in text and "FLAGGED: diverged on every seed" in text
    assert "smallest attainable p at n=3: 0.05, after Holm 0.1: no ordering can be separated" in text


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
    argv = [
        "--problems",
        "toy",
        "--optimizers",
        "adam,sgd",
        "--paper",
        "",
        "--references",
        "",
        "--trials",
        "2",
        "--seeds",
        "1",
        "--studies",
        "1",
    ]
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
    common = ["--optimizers", "adam,hig", "--paper", "", "--references", "",
              "--seeds", "1", "--seconds", "1,toy=2", "--root", str(tmp_path),
              "--studies", "1"]  # fmt: skip
    for problem, trials in (("toy", 2), ("oscillator", 1)):
        with pytest.raises(SystemExit, match="tuning"):
            sets = ["--set", "toy/hig:threads=1", "--set", "toy:threads=2"]
            script.main(["--problems", problem, "--trials", "1,toy=2", *sets, *common])
        jobs = launched.pop()
        assert len(jobs) == 2 * trials
        assert {j.overrides["budget.seconds"] for j in jobs} == {2.0 if problem == "toy" else 1.0}
        threads = {j.overrides["optimizer"]: j.overrides.get("threads") for j in jobs}
        assert threads == ({"adam": 2, "hig": 1} if problem == "toy" else {"adam": None, "hig": None})  # narrower wins
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
    argv = [
        "--problems",
        "toy",
        "--optimizers",
        "adam",
        "--references",
        "",
        "--trials",
        "1",
        "--seeds",
        "1",
        "--seconds",
        "1",
        *flags,
    ]
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
    assert "6 scored runs" in out and "1 run(s) left out" in out
    assert "equal updates" not in out  # updates are not equal work (an L-BFGS or LM update is many evaluations)
    seconds = out.split("equal wall clock")[1]
    hig_row = next(line for line in seconds.splitlines() if line.startswith("hig"))
    adam_row = next(line for line in seconds.splitlines() if line.startswith("adam"))
    # hig: fastest on both targets (score 1); adam: 1e-1 at 2 s (2x), 1e-2 at 3 s (3x): (2 + 1) / 2 / 3
    assert hig_row.split()[-1] == "1.000" and adam_row.split()[-1] == f"{(2 + 1) / 2 / 3:.3f}"
    table = out.split("final test loss per task")[1].split("across tasks")[0]
    assert "leader (lowest median final_test_loss) hig" in table
    assert "0.001 0.001 0.001" in table and "0.0011" not in table  # the test loss, not the val loss (1.1x)
    assert "coverage 75.0% at n=3" in table and "not separated" in table  # Holm over 1 comparison: p = 0.05, not < 0.05


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


def test_a_task_is_its_job_s_variant_not_every_problem_override():
    """`--set toy:++problem.val_size=256` (the driver's own advice for a problem without a
    validation set) reaches every job of the toy: it is no variant, or no task is 'toy' and the
    target setting finds no target. Without a job name, the overrides are the variant."""
    sets = "problem=toy optimizer=adam ++problem.val_size=256"
    rows = [("confirm/toy/base/adam", sets, "toy"), ("tune/toy/adam/0/3", sets, "toy"),
            ("target/toy/problem.gamma=0.01/adam", f"{sets} problem.gamma=0.01", "toy gamma=0.01"),
            (None, "problem=toy problem.gamma=0.001", "toy gamma=0.001")]  # fmt: skip
    for job, overrides, task in rows:
        row = pd.Series({"league_job": job, "overrides": overrides, "problem.name": "toy"})
        assert league.task_label(row) == task, job


def test_two_settings_under_one_league_label_are_refused(tmp_path, capsys):
    """Two confirmed configurations of one optimizer on one task would be scored as one setting."""
    from higbench.results.__main__ import main

    for seed, lr in ((0, 0.01), (1, 0.01), (2, 0.02)):
        write_league_run(tmp_path, f"a{seed}", "adam", seed, [1.0, 0.05], overrides=[f"optimizer.lr={lr}"], lr=lr)
    assert main([str(tmp_path), "--league"]) == 2
    err = capsys.readouterr().err
    assert "task toy: adam has runs of 2 different settings" in err, err


def test_the_figures_draw_the_leaders_and_hig_in_colour_and_the_rest_grey():
    colours = league_figures.assign_colours(["a", "b", "c", "hig", "hig (paper)"], ["a", "b"])
    assert colours["c"] == "0.7" and len({colours[n] for n in ("a", "b", "hig", "hig (paper)")}) == 4


def test_a_row_whose_seeds_never_moved_from_the_first_evaluation_is_flagged():
    scored = pd.DataFrame({
        "task": ["toy"] * 4, "league_setting": ["muon", "muon", "adam", "adam"], "seed": [0, 1, 0, 1],
        "status": ["completed"] * 4, "final_test_loss": [0.300, 0.301, 0.01, 0.02], "path": ["m0", "m1", "a0", "a1"],
    })  # fmt: skip
    curves = pd.DataFrame({"path": ["m0", "m0", "m1", "m1", "a0", "a0", "a1", "a1"],
                           "test_loss": [0.302, 0.300, 0.300, 0.301, 0.5, 0.01, 0.5, 0.02]})  # fmt: skip
    table = league.final_loss_table(league.with_first_losses(scored, curves)).set_index("setting")
    assert "constant predictor" in table.loc["muon", "flag"] and table.loc["adam", "flag"] == ""
    assert league.final_loss_table(scored).set_index("setting").loc["muon", "flag"] == ""  # without curves: not known


def test_a_seed_that_blew_up_without_a_nan_ranks_with_the_diverged_ones():
    """Two LM seeds ended at 26 and 1.2e3 from first evaluations near 0.9: scored as diverged, so
    against GN, which diverged on every seed, LM's blown-up seeds tie rather than win."""
    finals = {"lm": [2e-6, 3e-6, 4e-6, 26.0, 1181.0], "gn": [math.nan] * 5}
    rows = [{"task": "oscillator", "league_setting": name, "seed": seed, "path": f"{name}{seed}",
             "status": "completed" if math.isfinite(v) else "diverged", "final_test_loss": v}
            for name, values in finals.items() for seed, v in enumerate(values)]  # fmt: skip
    scored = pd.DataFrame(rows)
    curves = pd.DataFrame({"path": scored["path"], "test_loss": 0.9})
    table = league.final_loss_table(league.with_first_losses(scored, curves)).set_index("setting")
    assert list(table.loc["lm", "seeds"]) == [2e-6, 3e-6, 4e-6, math.inf, math.inf]
    assert table.loc["gn", "p_leader_below"] == pytest.approx(0.8)  # 15 of 25 pairs won, 10 tied (counted half)
    untouched = league.final_loss_table(scored).set_index("setting")  # without curves: the values, as before
    assert list(untouched.loc["lm", "seeds"]) == finals["lm"] and untouched.loc["gn", "p_leader_below"] == 1.0


@pytest.mark.slow  # draws the 11-panel figure
def test_the_published_runs_csv_re_reads_to_the_committed_table(tmp_path):
    """docs/results/league/reread.txt is what scripts/league_reread.py makes of runs.csv alone."""
    import importlib.util

    docs = Path(__file__).resolve().parents[2] / "docs" / "results" / "league"
    path = Path(__file__).resolve().parents[2] / "scripts" / "league_reread.py"
    spec = importlib.util.spec_from_file_location("league_reread", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert script.main([str(docs / "runs.csv"), "--out", str(tmp_path)]) == 0
    assert (tmp_path / "reread.txt").read_text() == (docs / "reread.txt").read_text()
    table = league.final_loss_table(league.runs_csv_frame(docs / "runs.csv"))
    leaders = table[table["leader"]].set_index("task")["setting"]
    assert leaders["toy"] == "lm" and leaders["dipole dt=0.04"] == "lm"  # by median, as the audit found
    assert not table["separated"].any() and table["p_holm"].min() == pytest.approx(0.25)  # 3 seeds separate nothing
    assert table.groupby("task")["setting"].count().sum() == 147 and (table["n"] == 3).all()
