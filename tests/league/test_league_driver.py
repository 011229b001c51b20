"""The league's command (higbench.league.driver) without training: its machine record, the files
it reads and writes under a root (links, FIFOs, foreign files), a user's own problem and
optimizer, its outputs, launchers and plan. Runs are faked (``run_missing``) or hand-made."""

from __future__ import annotations

import json
import os
import signal
import sys
from pathlib import Path

import pandas as pd
import pytest
import yaml

from higbench.league import driver, tables
from higbench.league.files import RootFileError, safe_dir, write_text

HEAT = Path(__file__).resolve().parents[2] / "examples" / "heat"


@pytest.fixture
def no_runs(monkeypatch):
    """run_missing faked (every job returned as done with no file) and no calibration: what the
    driver launched, with which keywords."""
    calls = []

    def fake(jobs, root, **kw):
        calls.append((list(jobs), kw))
        return []

    monkeypatch.setattr(driver, "run_missing", fake)
    monkeypatch.setattr(driver, "calibration", lambda: {})
    monkeypatch.setenv(driver.SEARCHPATH_ENV, "")  # restored after the test: --searchpath sets it
    monkeypatch.setenv("PYTHONPATH", os.environ.get("PYTHONPATH", ""))
    return calls


# -- the machine record (issue 47: the load; issue 51 break 11: foreign values) ----------------


def test_the_load_is_the_first_load_average_not_its_first_character():
    runs = pd.DataFrame({"problem.name": ["toy"] * 3, "env.device": ["cpu"] * 3, "env.cpu_count": [16] * 3,
                         "env.load_at_finish": ["11.87 11.99 10.86", "12.50 11.00 10.00", "9.25 9.00 9.00"]})  # fmt: skip
    (group,) = driver.machine(runs)
    assert group["load_1min_median"] == 11.87  # the old parse read '1', '1', '9': a median of 1.0


def test_foreign_values_in_run_rows_are_left_out_not_a_crash():
    """A float where the load's string belongs, ``started`` as an int beside a string, a share that
    is text: the machine line is written from what can be read."""
    runs = pd.DataFrame({
        "problem.name": ["toy", "toy"], "env.device": ["cpu", "cpu"], "env.cpu_count": [2, 2],
        "env.load_at_finish": [3.5, "2.50 1 1"], "env.cpu_share": ["lots", 0.5],
        "started": [12, "2026-01-01T00:00:00"], "finished": ["2026-01-01T00:01:00", None],
    })  # fmt: skip
    (group,) = driver.machine(runs)
    assert group["load_1min_median"] == 3.0 and group["cpu_share_median"] == 0.5 and group["trained"] is not None


def test_foreign_manifests_are_skipped_with_a_line_naming_each(tmp_path, capsys):
    (tmp_path / "manifests").mkdir()
    (tmp_path / "manifests" / "a.json").write_text(json.dumps({"calibration": 5}))
    (tmp_path / "manifests" / "b.json").write_text("[" * 100_000 + "]" * 100_000)  # RecursionError in json
    (tmp_path / "manifests" / "c.json").write_text(json.dumps({"calibration": [{"matmul_50x256_s": 0.5}]}))
    found = driver.recorded_calibrations([tmp_path], tmp_path / "report")
    assert found == [{"matmul_50x256_s": 0.5, "file": "manifests/c.json"}]
    err = capsys.readouterr().err
    assert "a.json: its calibration is not a list" in err and "b.json: nested too deeply" in err


def test_a_sitting_on_a_machine_of_another_speed_is_named_against_the_last_calibration():
    def at(when, seconds):
        return {"when": when, "matmul_50x256_s": seconds}

    # the CPU league's first machine (19-27 ms between its sittings), then the second (16.4 ms)
    first = [0.0199, 0.0250, 0.0192, 0.0239, 0.0262, 0.0210]
    earlier = [at(f"2026-11-30T0{i}:00:00+0000", s) for i, s in enumerate(first)] + [{"matmul_50x256_s": "x"}]
    line = driver.speed_change(at("2026-11-30T06:00:00+0000", 0.0164), earlier)  # against 25.0, 19.2, 23.9, 26.2, 21.0
    assert line and "(16.4 ms) is 0.69x the median of the latest 5 recorded under the roots (23.9 ms, the last at" in line
    assert driver.speed_change(at("now", 0.0192), earlier) is None  # 0.80x: within one machine's spread
    assert driver.speed_change(at("now", 0.0164), []) is None and driver.speed_change({}, earlier) is None


def test_a_seed_that_is_not_a_number_leaves_its_run_out_of_the_table_with_a_line(tmp_path, capsys):
    from test_league_tables import league_root

    jobs = league_root(tmp_path, [0, 1])
    table = tables.runs_table(tmp_path, _with_bad_seed(tmp_path), tables._roles(tmp_path, jobs))
    assert len(table) == 3 and "seed 'zero'" in capsys.readouterr().err


def _with_bad_seed(root: Path) -> pd.DataFrame:
    from higbench.results.index import load_runs

    runs = load_runs(root, figure_runs=True)
    runs["seed"] = runs["seed"].astype(object)
    runs.loc[0, "seed"] = "zero"
    return runs


# -- links and FIFOs under a root (issue 51 breaks 1-3) ---------------------------------------


def test_a_linked_manifest_brings_no_file_from_outside_the_root(tmp_path, capsys):
    secret = tmp_path / "elsewhere.json"
    secret.write_text(json.dumps({"calibration": [{"secret": 1}]}))
    root = tmp_path / "root"
    (root / "manifests").mkdir(parents=True)
    (root / "manifests" / "x.json").symlink_to(secret)
    (root / "sub").mkdir()
    (root / "sub" / "league.json").symlink_to(secret)
    assert driver.recorded_calibrations([root], root / "report") == []
    assert capsys.readouterr().err.count("a symbolic link") == 2


def test_a_linked_manifests_folder_is_neither_read_nor_written_through(tmp_path):
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "m.json").write_text(json.dumps({"calibration": [{"secret": 1}]}))
    root = tmp_path / "root"
    root.mkdir()
    (root / "manifests").symlink_to(outside)
    assert driver.recorded_calibrations([root], root / "report") == []
    with pytest.raises(RootFileError, match="manifests: a symbolic link"):
        write_text(safe_dir(root / "manifests", create=True) / "new.json", "{}")
    assert sorted(p.name for p in outside.iterdir()) == ["m.json"]


def test_a_fifo_named_league_json_never_hangs_the_report(tmp_path, capsys):
    root = tmp_path / "root"
    (root / "old").mkdir(parents=True)
    os.mkfifo(root / "old" / "league.json")
    fired = []

    def alarm(*_):  # the old reader blocked in open() until this, then swallowed it (except OSError)
        fired.append(1)
        raise TimeoutError("the report hung on a FIFO")

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(5)
    try:
        assert driver.recorded_calibrations([root], root / "report") == []
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    assert not fired and "not a regular file" in capsys.readouterr().err
    # and written over: replaced by a file, never opened for writing (no reader: that would block or fail)
    write_text(root / "old" / "league.json", "{}\n")
    assert (root / "old" / "league.json").read_text() == "{}\n"


def test_a_link_planted_in_the_report_folder_is_replaced_not_written_through(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("mine\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / "league.txt").symlink_to(victim)
    driver.write_report(out, "the league\n", {"protocol": {}}, pd.DataFrame(), pd.DataFrame())
    assert victim.read_text() == "mine\n" and (out / "league.txt").read_text() == "the league\n"


# -- outputs: under the root, never another league's ------------------------------------------


def test_outputs_default_to_outputs_league_under_the_current_folder(tmp_path, monkeypatch, no_runs):
    monkeypatch.chdir(tmp_path)
    args = driver.parse_args([])
    assert args.root is None and args.out is None  # resolved in main: outputs/league, ROOT/report
    assert driver.main(["--problems", "toy", "--optimizers", "adam", "--paper", "", "--trials", "1", "--studies", "1",
                        "--seeds", "1", "--seconds", "1"]) == 0  # fmt: skip
    assert (tmp_path / "outputs" / "league" / "report" / "league.json").is_file()
    manifest = json.loads((tmp_path / "outputs" / "league" / "report" / "league.json").read_text())
    assert manifest["protocol"]["root"] == "outputs/league"  # relative to the current folder: no machine's path published


def test_another_league_s_report_is_never_overwritten(tmp_path, no_runs, capsys):
    published = tmp_path / "published"
    published.mkdir()
    (published / "league.json").write_text(json.dumps({"calibration": []}))  # a report of the old script: no protocol
    argv = ["--problems", "toy", "--optimizers", "adam", "--paper", "", "--trials", "1", "--studies", "1", "--seeds", "1"]
    root = ["--root", str(tmp_path / "runs")]
    assert driver.main([*argv, "--seconds", "1", *root, "--out", str(published)]) == 2
    assert "holds files but no league report" in capsys.readouterr().err
    assert json.loads((published / "league.json").read_text()) == {"calibration": []} and not (tmp_path / "runs").exists()
    assert driver.main([*argv, "--seconds", "1", *root]) == 0
    capsys.readouterr()
    assert driver.main([*argv, "--seconds", "2", *root]) == 2  # the same root and problem, another budget
    assert "another protocol for toy (seconds 1.0 -> 2.0)" in capsys.readouterr().err


# -- your own problem and optimizer ---------------------------------------------------------


def test_a_user_s_problem_and_search_space_through_searchpath(tmp_path, monkeypatch, no_runs, capsys):
    """A problem outside conf/ was a raw Hydra traceback ("Could not find 'problem/heat'");
    through --searchpath it composes, its shipped-settings rows are 'default' (higbench has no
    paper settings for it), and an optimizer of the user's takes its space from DIR/search/."""
    conf = tmp_path / "conf"
    (conf / "optimizer").mkdir(parents=True)
    (conf / "problem").mkdir()
    heat = (HEAT / "conf" / "problem" / "heat.yaml").read_text()
    assert "val_size: 64" in heat  # the example declares its validation set; this copy drops it
    (conf / "problem" / "heat.yaml").write_text(heat.replace("val_size: 64", "val_size: 0"))
    (conf / "optimizer" / "mysgd.yaml").write_text(yaml.safe_dump({"_target_": "torch.optim.SGD", "name": "mysgd", "lr": 0.01}))
    monkeypatch.syspath_prepend(str(HEAT))
    argv = ["--searchpath", str(conf), "--problems", "heat", "--trials", "1", "--studies", "1", "--seeds", "1",
            "--seconds", "1", "--root", str(tmp_path / "runs")]  # fmt: skip
    assert driver.main([*argv, "--optimizers", "adam"]) == 2  # a problem without a validation set
    assert "problem=heat: no validation set" in capsys.readouterr().err
    argv += ["--set", "heat:++problem.val_size=64"]
    assert driver.main([*argv, "--optimizers", "adam,mysgd"]) == 2
    assert "optimizer=mysgd: no search space" in capsys.readouterr().err and not (tmp_path / "runs").exists()
    (conf / "search").mkdir()
    (conf / "search" / "mysgd.yaml").write_text(yaml.safe_dump({"space": {"optimizer.lr": {"low": 1e-3, "high": 1e-1}}}))
    assert driver.main([*argv, "--optimizers", "adam,mysgd", "--paper", "adam"]) == 0
    launched = [j for jobs, _ in no_runs for j in jobs]
    assert {j.overrides["problem"] for j in launched} == {"heat"}
    # no tuned setting (faked runs): the references' trials, the trials, and the defaults only
    assert {j.sweep.split("/")[0] for j in launched} == {"target-tune", "tune", "default"}
    assert any(j.overrides["optimizer"] == "mysgd" and "optimizer.lr" in j.overrides for j in launched)


def test_shipped_settings_are_paper_only_where_higbench_has_the_paper_s():
    assert driver.has_paper_settings("toy", "hig") and not driver.has_paper_settings("heat", "hig")
    jobs = driver.confirmation_jobs("toy", "hig", None, [0], 1.0, [])
    assert jobs[0].sweep == "paper/toy/base/hig"


# -- launchers, plan, progress -----------------------------------------------------------------


def test_launcher_flags_reach_run_missing(tmp_path, no_runs):
    argv = ["--problems", "toy", "--optimizers", "adam", "--paper", "", "--references", "",
            "--trials", "1", "--studies", "2", "--seeds", "1",
            "--seconds", "1", "--root", str(tmp_path), "--launcher", "submitit_slurm", "--launcher-set", "partition=gpu",
            "--launcher-set", "timeout_min=30", "--set", "progress=false"]  # fmt: skip
    assert driver.main(argv) == 0
    jobs, kw = no_runs[0]
    assert kw["launcher"] == "submitit_slurm"
    assert kw["launcher_overrides"] == ["hydra.launcher.partition=gpu", "hydra.launcher.timeout_min=30"]
    assert sorted(j.sweep for j in jobs) == ["tune/toy/adam/0/0", "tune/toy/adam/1/0"]  # a study index in each name
    assert sorted(j.seed for j in jobs) == [1000, 1001]
    assert {j.overrides["eval_every"] for j in jobs} == {0.01}  # 100 evaluations per run


def test_a_launcher_setting_submitit_has_not_is_one_line_before_any_run(tmp_path, no_runs, capsys):
    argv = ["--problems", "toy", "--optimizers", "adam", "--paper", "", "--references", "",
            "--trials", "1", "--studies", "1", "--seeds", "1",
            "--seconds", "1", "--root", str(tmp_path / "runs"), "--launcher", "submitit_slurm",
            "--launcher-set", "partiton=gpu"]  # fmt: skip
    assert driver.main(argv) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "hydra.launcher.partiton=gpu: not a setting of the submitit_slurm launcher" in line
    assert not no_runs and not (tmp_path / "runs").exists()


def test_a_missing_optimizer_extra_stops_a_training_league_before_any_run(tmp_path, no_runs, monkeypatch, capsys):
    """Without pytorch-optimizer a league used to leave SOAP out with a line among its progress
    and publish tables without it; it now refuses to train, naming the pip install."""
    monkeypatch.setitem(sys.modules, "pytorch_optimizer", None)  # as if the extra were not installed
    argv = ["--problems", "toy", "--optimizers", "adam,soap", "--paper", "", "--references", "",
            "--trials", "1", "--studies", "1", "--seeds", "1", "--seconds", "1", "--root", str(tmp_path / "runs")]  # fmt: skip
    assert driver.main(argv) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.endswith('optimizer=soap: pytorch_optimizer.SOAP comes with the optimizers extra: '
                         'pip install -e ".[optimizers]" (or leave soap out of --optimizers)'), line  # fmt: skip
    assert not no_runs and not (tmp_path / "runs").exists()


def test_a_problem_an_optimizer_cannot_run_on_is_left_out_with_a_line(tmp_path, no_runs, capsys):
    """The other kind of refusal stays one: SIP needs an inverse simulator, which the dipole has not."""
    argv = ["--problems", "dipole", "--optimizers", "adam,sip", "--paper", "", "--references", "",
            "--trials", "1", "--studies", "1", "--seeds", "1", "--seconds", "1", "--root", str(tmp_path / "runs")]  # fmt: skip
    assert driver.main(argv) == 0
    assert "[league] dipole: sip left out: optimizer=sip: problem dipole has no inverse simulator" in capsys.readouterr().err
    assert {j.overrides["optimizer"] for jobs, _ in no_runs for j in jobs} == {"adam"}


def test_runs_the_ledger_refused_for_good_are_named_not_promised_to_the_same_command(tmp_path, monkeypatch, capsys):
    """A job the ledger records as final (refused for memory) comes back not done every time: the
    league must say so and where to clear it, not that the same command continues it."""

    def refusing(jobs, root, **kw):
        assert kw["progress"] is False  # the league prints its own count; the launch's would be a second line
        for j in jobs:
            j.status, j.reason = "refused", "not even batch_size=1 fits"
        return list(jobs)

    monkeypatch.setattr(driver, "run_missing", refusing)
    runner = driver.Runner(tmp_path, 1, "basic", [], driver_progress())
    job = driver.Job("league", "tune/toy/adam/0/0", {"problem": "toy", "optimizer": "adam", "budget.seconds": 1.0}, 1000)
    with pytest.raises(SystemExit) as stop:
        runner.run([job], "toy tuning")
    assert "1 refused for good (not even batch_size=1 fits)" in str(stop.value) and "ledger" in str(stop.value)
    assert "the same command continues" not in str(stop.value)


def driver_progress():
    from higbench.runner.progress import CountProgress

    return CountProgress(False, "league", 1)


def test_the_plan_counts_runs_and_hours_and_runs_nothing(tmp_path, no_runs, capsys):
    argv = ["--problems", "toy", "--optimizers", "adam,sgd", "--paper", "adam", "--trials", "3", "--studies", "2",
            "--seeds", "5", "--seconds", "60", "--variants", "1", "--jobs", "2", "--root", str(tmp_path / "runs"),
            "--plan"]  # fmt: skip
    assert driver.main(argv) == 0
    out = capsys.readouterr().out
    # target setting: 2 references (adam, adamw) x (3 x 2 trials + (base + 1 variant) x 5 reruns) = 32, at the toy's
    # target_seconds (10 s); tuning 2 x 3 x 2 = 12; confirmation (2 tuned + 1 paper) x (base + 1 variant) x 5 seeds = 30
    # training: 32 x 10 s + 42 x 60 s = 2840 s
    assert "toy: 74 runs (32 target setting, 12 tuning, 30 confirmation), 47 min of training, hardware cpu threads=1" in out
    assert "about 24 min wall clock at --jobs 2" in out
    assert not no_runs and not (tmp_path / "runs").exists()


def test_help_lists_the_flags_with_examples(capsys):
    from higbench.league.__main__ import main

    with pytest.raises(SystemExit) as done:
        main(["--help"])
    out = capsys.readouterr().out
    assert done.value.code == 0 and out.startswith("usage: higbench-league")
    assert "examples:" in out and "higbench-league --report-only --root runs-a --root runs-b" in out
    for flag in ("--searchpath", "--launcher-set", "--studies", "--plan", "--report-only", "--root", "--out"):
        assert flag in out


def test_progress_counts_runs_and_is_quiet_under_progress_false(tmp_path, no_runs, capsys):
    argv = ["--problems", "toy", "--optimizers", "adam", "--paper", "", "--references", "",
            "--trials", "2", "--studies", "1", "--seeds", "1",
            "--seconds", "3", "--variants", "0"]  # fmt: skip
    assert driver.main([*argv, "--root", str(tmp_path / "a")]) == 0
    err = capsys.readouterr().err
    # no trial completed (no runs are made here), so adam has no setting: its confirmation run leaves the count
    assert "[league] 0 of 3 runs done, about 9 s left" in err and "[league] 2 of 2 runs done" in err
    assert driver.main([*argv, "--root", str(tmp_path / "b"), "--set", "progress=false"]) == 0
    assert "runs done" not in capsys.readouterr().err


def test_a_problem_without_targets_gets_its_report_without_a_profile(tmp_path):
    """A problem of your own may declare no targets: the league crashed drawing an empty profile
    after all its training (numpy: need at least one array to concatenate)."""
    scored = pd.DataFrame({"task": ["heat"], "league_setting": ["adam"], "seed": [0], "status": ["completed"]})
    reached = pd.DataFrame(columns=["task", "setting", "seed", "target", "seconds", "updates"])
    driver.write_report(tmp_path / "out", "scores\n", {}, scored, reached)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["league.json", "league.txt", "runs.csv"]


def test_set_hydra_searchpath_is_the_searchpath_flag():
    rest, folders = driver.searchpath_of_set(["threads=1", "hydra.searchpath=[file://examples/heat/conf,file:///x/conf]"])
    assert rest == ["threads=1"] and folders == [Path("examples/heat/conf"), Path("/x/conf")]


# -- --set values and the root's folders (the adversarial re-check of issue 51) -----------------


def test_a_list_in_set_reaches_the_jobs_as_a_list_not_a_quoted_string(tmp_path, no_runs):
    """`--set optimizer.betas=[0.8,0.99]` was kept as text and rendered `optimizer.betas='[0.8,0.99]'`:
    every job failed (Adam compared a float with a str) and the league said the same command continues."""
    argv = ["--problems", "toy", "--optimizers", "adam", "--paper", "", "--references", "",
            "--trials", "1", "--studies", "1", "--seeds", "1",
            "--seconds", "1", "--root", str(tmp_path), "--set", "adam:optimizer.betas=[0.8,0.99]",
            "--set", "progress=false"]  # fmt: skip
    assert driver.main(argv) == 0
    (job,) = no_runs[0][0]
    assert job.overrides["optimizer.betas"] == [0.8, 0.99]
    assert "optimizer.betas=[0.8,0.99]" in job.launch_overrides()


def test_a_problem_key_in_set_is_what_the_driver_reads_too(tmp_path, no_runs):
    """`--set problem.target_seconds=2` reached the jobs' config (which no run reads) while the
    driver kept the shipped 10 s for the target-setting runs: silently not what was asked."""
    argv = ["--problems", "toy", "--optimizers", "adam", "--references", "adam", "--paper", "", "--trials", "1",
            "--studies", "1", "--seeds", "5", "--variants", "0", "--targets-only", "--root", str(tmp_path),
            "--set", "problem.target_seconds=2"]  # fmt: skip
    assert driver.main(argv) == 0
    budgets = {j.overrides["budget.seconds"] for jobs, _ in no_runs for j in jobs}
    assert budgets == {2.0}


def test_held_out_through_set_is_the_league_s_own(tmp_path, no_runs, capsys):
    argv = ["--problems", "toy", "--optimizers", "adam", "--root", str(tmp_path / "r"), "--set", "toy:problem.held_out=[{a:1}]"]
    assert driver.main(argv) == 2
    assert "problem.held_out is the league's own" in capsys.readouterr().err and not no_runs


def test_a_planted_manifests_link_in_a_new_root_is_refused_before_the_calibration(tmp_path, no_runs, monkeypatch, capsys):
    """It was refused only when the manifest was written, after all training."""
    calibrated = []
    monkeypatch.setattr(driver, "calibration", lambda: calibrated.append(1) or {})
    (tmp_path / "victim").mkdir()
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "manifests").symlink_to(tmp_path / "victim")
    argv = ["--problems", "toy", "--optimizers", "adam", "--paper", "", "--trials", "1", "--studies", "1", "--seeds", "1",
            "--seconds", "1", "--root", str(tmp_path / "r")]  # fmt: skip
    assert driver.main(argv) == 2
    assert "a symbolic link" in capsys.readouterr().err
    assert not calibrated and not no_runs and not any((tmp_path / "victim").iterdir())


# -- the target setting (issue 46: validation targets and budgets from reference reruns) ------


def _reruns(task: str, problem: str, finals: dict[str, list[float]], reach_at: dict[str, list[float]]):
    """Hand-made reruns: per reference its final validation losses, and the second at which each
    rerun's validation curve first drops to 0.01 (inf: never)."""
    runs, curves = [], []
    for optimizer, losses in finals.items():
        for i, loss in enumerate(losses):
            run = f"{task}/{optimizer}/{i}"
            runs.append({"run": run, "task": task, "problem.name": problem, "optimizer.name": optimizer,
                         "status": "completed", "final_val_loss": loss, "league_role": "target"})  # fmt: skip
            at = reach_at.get(optimizer, [float("inf")] * len(losses))[i]
            for t in (0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0):
                curves.append({"run": run, "step": int(t * 10), "wall_time": t,
                               "val_loss": 0.005 if t >= at else 0.5})  # fmt: skip
    return pd.DataFrame(runs), pd.DataFrame(curves)


def test_the_validation_target_is_the_best_reference_s_median_and_the_budget_three_times_its_time():
    # adam's median final 0.01 beats adamw's 0.02; adam's reruns reach 0.01 at 1, 2, 3 s and two never:
    # the median time is 3 s, the budget 9 s
    runs, curves = _reruns("toy", "toy", {"adam": [0.005, 0.008, 0.01, 0.03, 0.04], "adamw": [0.02] * 5},
                           {"adam": [1.0, 2.0, 3.0, float("inf"), float("inf")]})  # fmt: skip
    found = driver.league.targets_from_reruns(runs, curves)
    row = found.iloc[0]
    assert (row["task"], row["reference"], row["target"], row["budget_s"]) == ("toy", "adam", 0.01, 9.0)
    assert row["medians"] == {"adam": 0.01, "adamw": 0.02} and row["reruns"] == 5
    assert driver.league_budget(found, "toy") == 9.0 and driver.league_budget(found, "dipole") is None


def test_a_reference_with_fewer_than_five_reruns_sets_no_target():
    runs, curves = _reruns("toy", "toy", {"adam": [0.01] * 4}, {"adam": [1.0] * 4})
    with pytest.warns(UserWarning, match="adam has 4 reruns; need at least 5"):
        assert driver.league.targets_from_reruns(runs, curves).empty


def test_the_report_finds_targets_budgets_and_gates_in_the_tables_alone():
    """--report-only scores from the tables: the reruns there give each task its target; a held-out
    variant is judged within its problem's budget (its runs ran that long) and is a gate."""
    base = _reruns("toy", "toy", {"adam": [0.01] * 5}, {"adam": [2.0] * 5})
    variant = _reruns("toy gamma=0.01", "toy", {"adam": [0.02] * 5}, {"adam": [5.0] * 5})
    runs, curves = (pd.concat([a, b], ignore_index=True) for a, b in zip(base, variant, strict=True))
    targets, budgets, held_out = driver.scoring_targets(runs, curves)
    assert targets == {"toy": 0.01, "toy gamma=0.01": 0.02}
    assert budgets == {"toy": 6.0, "toy gamma=0.01": 6.0} and held_out == {"toy": ["toy gamma=0.01"]}
    assert driver.scoring_targets(runs.assign(league_role="confirm"), curves) == ({}, {}, {})


def test_tuning_selects_the_trial_that_reaches_the_validation_target_first(monkeypatch):
    """Trial 0 ends lower (0.001) but reaches 0.01 at 5 s; trial 1 ends at 0.008 and reaches it at 1 s,
    and has the better test loss only by construction elsewhere: with a target trial 1 wins,
    without one (no target setting) the lowest final validation loss, trial 0."""
    jobs = [driver.Job("league", f"tune/toy/adam/0/{i}", {"problem": "toy", "optimizer": "adam", "optimizer.lr": lr},
                       1000, path=Path(f"/runs/{i}/run.h5")) for i, lr in enumerate((0.1, 0.01))]  # fmt: skip
    runs = pd.DataFrame({"path": [str(j.path) for j in jobs], "trial": [j.sweep for j in jobs], "status": "completed",
                         "final_val_loss": [0.001, 0.008], "final_test_loss": [0.5, 0.0001]})  # fmt: skip
    curves = pd.DataFrame({"path": [str(jobs[0].path)] * 2 + [str(jobs[1].path)] * 2, "step": [1, 2, 1, 2],
                           "wall_time": [1.0, 5.0, 1.0, 5.0], "val_loss": [0.5, 0.001, 0.009, 0.008]})  # fmt: skip
    monkeypatch.setattr(driver, "done_runs", lambda js: (runs, curves))
    setting, rule = driver.choose(jobs, target=0.01)
    assert setting == {"optimizer.lr": 0.01} and rule.startswith("time to the validation target 0.01")
    setting, rule = driver.choose(jobs)
    assert setting == {"optimizer.lr": 0.1} and rule.startswith("final validation loss")


def test_the_league_runs_at_the_budget_the_target_setting_derived(tmp_path, no_runs, monkeypatch):
    """The target setting's budget (ceil of 3x the reference's median time) is every league run's
    budget, and tuning is given the validation target; --seconds, when given, is the budget."""
    found = pd.DataFrame([{"task": "toy", "reference": "adam", "target": 0.01, "budget_s": 7.2, "reruns": 5,
                           "medians": {}, "seconds_to_target": []}])  # fmt: skip
    monkeypatch.setattr(driver, "target_setting", lambda *a, **k: found)
    targets_seen = []
    monkeypatch.setattr(driver, "choose", lambda jobs, target=None: (targets_seen.append(target), (None, "none"))[1])
    argv = ["--problems", "toy", "--optimizers", "adam", "--paper", "adam", "--trials", "1", "--studies", "1", "--seeds",
            "1", "--variants", "0"]  # fmt: skip
    assert driver.main([*argv, "--root", str(tmp_path / "a")]) == 0
    assert {j.overrides["budget.seconds"] for jobs, _ in no_runs for j in jobs} == {8.0} and targets_seen == [0.01]
    no_runs.clear()
    assert driver.main([*argv, "--seconds", "3", "--root", str(tmp_path / "b")]) == 0
    assert {j.overrides["budget.seconds"] for jobs, _ in no_runs for j in jobs} == {3.0}
    manifest = json.loads((tmp_path / "a" / "report" / "league.json").read_text())
    assert manifest["problems"]["toy"]["budget_from"] == "target setting"


def test_a_sitting_stopped_in_confirmation_records_what_tuning_chose(tmp_path, no_runs, monkeypatch):
    """The manifest's problem entry is filled as the phases end: a sitting stopped while its
    confirmation runs (hours, across sessions) still records the chosen settings and the budget."""
    found = pd.DataFrame([{"task": "toy", "reference": "adam", "target": 0.01, "budget_s": 7.2, "reruns": 5,
                           "medians": {}, "seconds_to_target": []}])  # fmt: skip
    monkeypatch.setattr(driver, "target_setting", lambda *a, **k: found)
    monkeypatch.setattr(driver, "choose", lambda jobs, target=None: ({"optimizer.lr": 0.02}, "time to the target"))

    def stop_in_confirmation(jobs, root, **kw):
        if any(j.sweep.startswith("confirm") for j in jobs):
            raise KeyboardInterrupt
        return []

    monkeypatch.setattr(driver, "run_missing", stop_in_confirmation)
    argv = ["--problems", "toy", "--optimizers", "adam", "--paper", "", "--trials", "1", "--studies", "1", "--seeds",
            "1", "--variants", "0", "--root", str(tmp_path)]  # fmt: skip
    assert driver.main(argv) == 128 + signal.SIGINT
    (manifest,) = (tmp_path / "manifests").glob("*.json")
    entry = json.loads(manifest.read_text())["problems"]["toy"]
    assert entry["chosen"] == {"adam": {"optimizer.lr": 0.02}} and entry["chosen_by"] == {"adam": "time to the target"}
    assert entry["seconds"] == 8.0 and entry["budget_from"] == "target setting"


def test_an_earlier_league_s_tables_are_reused_never_rerun(tmp_path, monkeypatch, capsys):
    """Long leagues accumulate across machines and sessions: with a second --root holding an
    earlier league's tables (a published one), its done runs count as done (read from the tables,
    never launched again), its reruns set the validation target, and the new runs go to the
    first root at the budget they give."""
    from higbench import jobs as jobs_module

    earlier = _earlier_league(tmp_path / "published")
    launched = []
    monkeypatch.setattr(jobs_module, "launch", lambda todo, *a, **k: launched.extend(todo))
    monkeypatch.setattr(driver, "calibration", lambda: {})
    argv = ["--problems", "toy", "--optimizers", "adam", "--references", "adam", "--paper", "", "--trials", "1",
            "--studies", "1", "--seeds", "5", "--variants", "0", "--root", str(tmp_path / "new"),
            "--root", str(earlier)]  # fmt: skip
    with pytest.raises(SystemExit, match="1 toy tuning run"):  # the new tuning run was not trained (launch faked)
        driver.main(argv)
    err = capsys.readouterr().err
    # reruns reach the target 0.005 at 1, 2, 3, 4, 5 s: median 3 s, budget 9 s
    assert "toy: validation target 0.005 (adam, median of 5 reruns at 10 s), budget 9 s" in err
    assert {j.sweep.split("/")[0] for j in launched} == {"tune"}  # nothing of the earlier league ran again
    assert {j.overrides["budget.seconds"] for j in launched} == {9.0}


def test_a_published_league_re_scores_byte_for_byte_from_its_own_tables(tmp_path, capsys):
    """The report folder holds the tables it scored: --report-only on it writes the same report."""
    published = _earlier_league(tmp_path / "published", confirm=True)
    argv = ["--problems", "toy", "--optimizers", "adam", "--references", "adam", "--paper", "", "--trials", "1",
            "--studies", "1", "--seeds", "5", "--report-only"]  # fmt: skip
    assert driver.main([*argv, "--root", str(published), "--out", str(tmp_path / "report")]) == 0
    report = tmp_path / "report"
    first = {p.name: p.read_bytes() for p in [*report.glob("*.txt"), *report.glob("*.csv"), *(report / "tables").glob("*")]}
    assert "AlgoPerf: seconds to the validation target" in first["league.txt"].decode()
    assert driver.main([*argv, "--root", str(report), "--out", str(report)]) == 0
    again = {p.name: p.read_bytes() for p in [*report.glob("*.txt"), *report.glob("*.csv"), *(report / "tables").glob("*")]}
    assert again == first and set(first) == {"league.txt", "runs.csv", "runs.csv.gz", "curves.csv.gz"}


def _earlier_league(earlier: Path, confirm: bool = False) -> Path:
    """Hand-made tables of a league: adam's target-setting trial and 5 reruns on the toy (at the
    toy's target_seconds, the identities the driver gives them), each reaching the validation loss
    0.004 at 1, 1, 2, 3, 4, 5 s; with ``confirm``, also 5 confirmation runs of the tuned setting."""
    from higbench import jobs as jobs_module

    trials = driver.tuning_jobs("toy", "adam", 1, 10.0, 1, role="target-tune")
    setting = {k: v for k, v in trials[0].overrides.items() if k in driver.space_of("adam")}
    reruns = driver.confirmation_jobs("toy", "adam", setting, range(5), 10.0, [], role=driver.RERUN_ROLE)
    jobs_module.resolve([*trials, *reruns], {})
    rows, curves = [], []
    for i, (job, reach_s) in enumerate(zip([*trials, *reruns], [1.0, 1.0, 2.0, 3.0, 4.0, 5.0], strict=True)):
        role = job.sweep.split("/")[0]
        rows.append({"run": f"old/{i}/run.h5", "identity": job.identity, "config_id": job.identity,
                     "league_role": role, "league_job": job.sweep,
                     "seed": job.seed, "problem.name": "toy", "task": "toy", "optimizer.name": "adam", "overrides": "",
                     "status": "completed", "final_val_loss": 0.005, "final_test_loss": 0.005, "train_time_s": 10.0,
                     "steps": 100})  # fmt: skip
        curves += [{"run": f"old/{i}/run.h5", "step": s, "wall_time": float(s), "val_loss": 0.004 if s >= reach_s else 0.5}
                   for s in range(1, 11)]  # fmt: skip
    for seed in range(5 if confirm else 0):
        run = f"new/{seed}/run.h5"
        rows.append({**rows[-1], "run": run, "identity": f"confirm-{seed}", "config_id": f"confirm-{seed}",
                     "league_role": "confirm", "seed": seed,
                     "league_job": "confirm/toy/base/adam", "final_test_loss": 0.006 + seed / 1000})  # fmt: skip
        curves += [{"run": run, "step": s, "wall_time": float(s), "val_loss": 0.004 if s >= 2 + seed else 0.5,
                    "test_loss": 0.5} for s in range(1, 11)]  # fmt: skip
    runs = pd.DataFrame(rows).reindex(columns=list(tables.RUN_COLUMNS))
    tables._write_tables(earlier, runs, pd.DataFrame(curves).reindex(columns=list(tables.CURVE_COLUMNS)))
    return earlier


def test_targets_only_runs_the_target_setting_alone_and_the_plan_uses_an_earlier_one(tmp_path, no_runs, capsys):
    argv = ["--problems", "toy", "--optimizers", "adam,sgd", "--references", "adam", "--paper", "", "--trials", "1",
            "--studies", "1", "--seeds", "5", "--variants", "0"]  # fmt: skip
    assert driver.main([*argv, "--targets-only", "--root", str(tmp_path / "a")]) == 0
    assert {j.sweep.split("/")[0] for jobs, _ in no_runs for j in jobs} == {"target-tune"}
    published = _earlier_league(tmp_path / "published")
    capsys.readouterr()
    assert driver.main([*argv, "--plan", "--root", str(tmp_path / "b"), "--root", str(published)]) == 0
    # 6 target-setting runs at 10 s (the toy's target_seconds); 2 trials and 2 x 5 confirmations at the earlier
    # target setting's budget, 9 s: 60 + 12 x 9 = 168 s
    # (3 min; at league_seconds, 30 s, it would be 60 + 12 x 30 = 420 s, 7 min)
    assert "toy: 18 runs (6 target setting, 2 tuning, 10 confirmation), 3 min of training" in capsys.readouterr().out


def test_the_targets_do_not_move_with_a_piece_s_seed_count(tmp_path, no_runs, capsys):
    """A toy piece at 10 confirmation seeds (runs of 30 s or less) reruns the references on the
    first 5 only: the same reruns, the same targets, as the 5-seed target setting published."""
    assert driver.rerun_seeds(list(range(10))) == [0, 1, 2, 3, 4]
    argv = ["--problems", "toy", "--optimizers", "adam", "--references", "adam", "--paper", "", "--trials", "1",
            "--studies", "1", "--variants", "0", "--targets-only", "--plan", "--root", str(tmp_path)]  # fmt: skip
    assert driver.main([*argv, "--seeds", "10"]) == 0
    assert "toy: 6 runs (6 target setting" in capsys.readouterr().out  # 1 trial + 5 reruns, not 10


def test_a_targets_only_piece_and_a_full_piece_share_a_report_folder(tmp_path, no_runs):
    """Pieces of one league write one report folder: a --targets-only piece records only the keys
    that set the targets, and comparing it with a full piece's protocol was a KeyError traceback."""
    argv = ["--problems", "toy", "--optimizers", "adam", "--references", "adam", "--paper", "", "--trials", "1",
            "--studies", "1", "--seeds", "5", "--variants", "0", "--root", str(tmp_path / "r")]  # fmt: skip
    assert driver.main(argv) == 0
    assert driver.main([*argv, "--targets-only"]) == 0
    assert driver.main(argv) == 0


def test_a_stopped_league_keeps_the_runs_it_finished_and_the_same_command_continues(tmp_path, monkeypatch, capsys):
    """Ctrl-C (or SIGTERM, or a failed run) in the middle of a phase: the runs finished so far are
    written to the tables of the root and of the report folder, with their roles, and the manifest
    says it stopped; the same command then launches only what is left. One real toy run of 1 s, in this process."""
    from in_process import launch_in_process, restored_process_state

    from higbench import jobs as jobs_module

    launch_in_process(monkeypatch)  # the one run trains in this process
    with restored_process_state():
        _stop_a_league_after_one_run(tmp_path, monkeypatch, capsys, jobs_module)


def _stop_a_league_after_one_run(tmp_path, monkeypatch, capsys, jobs_module):
    real = driver.run_missing

    def stopped_after_one(jobs, root, **kw):
        real(jobs[:1], root, **kw)  # one trial trains, then the user presses Ctrl-C
        raise KeyboardInterrupt

    monkeypatch.setattr(driver, "run_missing", stopped_after_one)
    monkeypatch.setattr(driver, "calibration", lambda: {})
    root, out = tmp_path / "root", tmp_path / "report"
    argv = ["--problems", "toy", "--optimizers", "adam", "--references", "", "--paper", "", "--trials", "3",
            "--studies", "1", "--seeds", "5", "--variants", "0", "--seconds", "1",
            "--root", str(root), "--out", str(out)]  # fmt: skip
    assert driver.main(argv) == 128 + signal.SIGINT
    assert "stopped (KeyboardInterrupt): the 1 run(s) done so far are in the tables" in capsys.readouterr().err
    for folder in (root, out):
        runs, _ = tables.read(folder)
        assert list(runs["league_role"]) == ["tune"] and list(runs["status"]) == ["completed"]
    (manifest,) = (root / "manifests").glob("*.json")
    assert json.loads(manifest.read_text())["stopped"] == "KeyboardInterrupt"
    done = set(tables.read(root)[0]["identity"])
    launched = []
    monkeypatch.setattr(driver, "run_missing", real)
    monkeypatch.setattr(jobs_module, "launch", lambda todo, *a, **k: launched.extend(todo))
    with pytest.raises(SystemExit, match="2 toy tuning run"):  # the two trials left (launch faked: not trained)
        driver.main(argv)
    assert len(launched) == 2 and not {j.identity for j in launched} & done


@pytest.mark.process  # the job is a process: the point
def test_a_stopped_driver_gives_its_running_job_and_its_workers_time_to_close_their_runs(tmp_path):
    """SIGTERM reaches the driver alone: its job's whole group gets SIGINT and time to close its run
    files (what a run does on SIGINT), not subprocess.run's kill after a quarter of a second. The
    stand-in job is a launcher's parent that ignores SIGINT (as a sweep started in the background
    does) and waits for its worker: only a signal to the group reaches the run."""
    import sys
    import time

    from higbench.jobs import close_on_interrupt, start_job

    closed, ready = tmp_path / "closed", tmp_path / "ready"
    # a run installs its own SIGINT handler (a shell's background job may inherit SIGINT ignored)
    worker = ("import pathlib, signal, time\nsignal.signal(signal.SIGINT, signal.default_int_handler)\n"
              f"pathlib.Path({str(ready)!r}).touch()\n"
              "try:\n    time.sleep(60)\nexcept KeyboardInterrupt:\n    time.sleep(0.5)\n"
              f"    pathlib.Path({str(closed)!r}).write_text('rows written')\n    raise SystemExit(130)\n")  # fmt: skip
    parent = (f"import signal, subprocess, sys\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\n"
              f"sys.exit(subprocess.call([sys.executable, '-c', {worker!r}]))\n")  # fmt: skip
    proc = start_job([sys.executable, "-c", parent])
    while not ready.exists():  # the worker's handler is in place: a loaded machine may take seconds to start Python
        assert proc.poll() is None
        time.sleep(0.05)
    close_on_interrupt(proc)
    assert proc.returncode == 130 and closed.read_text() == "rows written"


@pytest.mark.process  # the job is a process: the point
def test_a_driver_started_in_the_background_stops_a_job_that_is_still_starting(monkeypatch):
    """A shell starts a background driver with SIGINT ignored, and exec keeps it ignored: the job
    must not inherit that, or the SIGINT of a stop sent before its run sets a handler (the sweep's
    start-up: tens of seconds on a loaded machine) is lost and the run killed after CLOSE_S
    (a league sitting stopped between two phases left a run file saying `running` so)."""
    import subprocess
    import sys

    import higbench.jobs as jobs

    monkeypatch.setattr(jobs, "CLOSE_S", 30.0)  # without the fix: SIGKILL after 30 s, not 60
    child = "import signal, sys, time\nprint(signal.getsignal(signal.SIGINT) is signal.SIG_IGN, flush=True)\ntime.sleep(60)\n"
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)  # as `higbench-league ... &` from a script
    try:
        proc = jobs.start_job([sys.executable, "-c", child], stdout=subprocess.PIPE, text=True)
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN  # the driver's own disposition is kept
    finally:
        signal.signal(signal.SIGINT, previous)
    assert proc.stdout.readline().strip() == "False", "the job inherited SIGINT ignored"
    jobs.close_on_interrupt(proc)  # no handler of its own yet: SIGINT's default ends it at once
    assert proc.returncode == -signal.SIGINT, "the job outlived the stop (killed after CLOSE_S: -9)"


def test_the_long_budget_trains_the_chosen_and_shipped_settings_longer_on_its_own_seeds(tmp_path, no_runs, monkeypatch):
    """--long: after a problem's confirmation, each long optimizer's chosen setting (role long) and
    the shipped one of those in --paper (role long-paper) on the first --long-seeds seeds, at the
    long budget, on the problem alone."""
    monkeypatch.setattr(driver, "choose", lambda jobs, target=None: ({"optimizer.lr": 0.01}, "test"))
    argv = ["--problems", "toy", "--optimizers", "adam,sgd,hig", "--references", "", "--paper", "hig", "--trials", "1",
            "--studies", "1", "--seeds", "5", "--seconds", "2", "--long", "600", "--long-optimizers", "adam,hig",
            "--long-seeds", "3", "--root", str(tmp_path)]  # fmt: skip
    assert driver.main(argv) == 0
    long = [j for jobs, _ in no_runs for j in jobs if j.sweep.startswith("long")]
    assert sorted({j.sweep for j in long}) == ["long-paper/toy/base/hig", "long/toy/base/adam", "long/toy/base/hig"]
    assert {j.overrides["budget.seconds"] for j in long} == {600.0} and sorted({j.seed for j in long}) == [0, 1, 2]
    assert all(j.overrides.get("optimizer.lr") == 0.01 for j in long if j.sweep.startswith("long/"))
    (manifest,) = (tmp_path / "manifests").glob("*.json")
    assert json.loads(manifest.read_text())["problems"]["toy"]["long"] == {
        "seconds": 600.0,
        "optimizers": ["adam", "hig"],
        "seeds": 3,
    }


@pytest.mark.parametrize(
    ("flags", "says"),
    [
        (["--long", "0"], "--long 0: a budget is a positive, finite number of seconds"),
        (["--long", "dipole=600"], "--long dipole=600: dipole is not in --problems"),
        (["--long", "600", "--long-optimizers", "soap"], "--long-optimizers soap: soap is not in --optimizers"),
        (["--long", "600", "--long-seeds", "0"], "--long-seeds 0: must be at least 1"),
        (["--long", "600", "--targets-only"], "--long 600: --targets-only trains no league setting"),
    ],
)
def test_a_bad_long_budget_is_one_line_before_any_run(tmp_path, no_runs, capsys, flags, says):
    argv = ["--problems", "toy", "--optimizers", "adam", "--references", "", "--trials", "1", "--root", str(tmp_path / "r")]
    assert driver.main([*argv, *flags]) == 2
    assert says in capsys.readouterr().err and not no_runs and not (tmp_path / "r").exists()
