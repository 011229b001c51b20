"""The console script end to end: run files, multirun, bad input, divergence.

In this process (``higbench.cli.main``, the ``higbench`` fixture) except where the process is
the point (a closed pipe) or the launcher starts its own (joblib's workers).
"""

from pathlib import Path

import h5py
import pytest
from cases import PROBLEM_CONFIGS, SMALL_RUN

from higbench.results import load_run, load_updates, load_weights


def run_files(root: Path) -> list[Path]:
    return sorted(root.rglob("run.h5"))


def test_single_run_writes_a_complete_run_file(higbench, tmp_path):
    code, out, err = higbench("problem=toy", "optimizer=hig", "problem.gamma=0.01")
    assert code == 0, err
    files = run_files(tmp_path / "outputs")
    assert len(files) == 1 and f"run file: {files[0]}" in out
    meta, curves = load_run(files[0])
    assert meta["status"] == "completed"
    assert meta["config"]["problem"]["gamma"] == 0.01 and meta["config"]["optimizer"]["kappa"] == -0.5
    assert "problem.gamma=0.01" in meta["overrides"]
    assert {"step", "epoch", "wall_time", "train_loss", "test_loss"} <= set(curves.columns)
    assert list(curves["step"]) == [0, 1, 2, 3]
    assert curves["wall_time"].is_monotonic_increasing
    for key in ("torch_version", "python_version", "hostname", "torch_threads", "device", "git_revision", "cpu_share"):
        assert key in meta["env"]
    updates = load_updates(files[0])
    assert len(updates) == 3 and (updates[["jacobian_s", "inversion_s", "apply_s"]] > 0).all().all()
    assert meta["memory"]["peak_rss_mb"] > 0
    weights = load_weights(files[0])
    assert weights["0.weight"].shape == (7, 1)
    with h5py.File(files[0]) as f:  # saturation and probe logs, one row per evaluation
        assert f["logs/neuron_mean"].shape == (4, 7) and f["logs/probe_output"].shape == (4, 2)


def test_multirun_writes_one_file_per_job(higbench, tmp_path):
    code, _, err = higbench("-m", "problem=toy", "optimizer=adam,hig")
    assert code == 0, err
    files = run_files(tmp_path / "outputs" / "sweeps")
    assert len(files) == 2
    assert sorted(load_run(f)[0]["optimizer"] for f in files) == ["adam", "hig"]


def test_an_init_from_path_names_a_flat_sweep_job_directory(higbench, tmp_path):
    """A path in a value (init_from) must not nest the job's directory; distinct paths stay distinct."""
    code, _, err = higbench("problem=toy", "optimizer=adam", f"hydra.run.dir={tmp_path / 'first' / 'run'}")
    assert code == 0, err
    start = tmp_path / "first" / "run" / "run.h5"
    code, _, err = higbench("-m", "problem=toy", "optimizer=adam,sgd", f"init_from={start}", f"hydra.sweep.dir={tmp_path / 'sw'}")
    assert code == 0, err
    jobs = sorted(p.parent for p in (tmp_path / "sw").rglob("run.h5"))
    assert [p.parent for p in jobs] == [tmp_path / "sw"] * 2, jobs  # one level below the sweep
    assert all(f"init_from={str(start).replace('/', '%2F')}," in p.name for p in jobs), jobs
    assert [load_run(p / "run.h5")[0]["config"]["init_from"] for p in jobs] == [str(start)] * 2


def test_flat_dirname_keeps_distinct_values_distinct():
    from higbench.config import flat_dirname

    assert flat_dirname("init_from=a/b.h5,seed=1") == "init_from=a%2Fb.h5,seed=1"
    assert flat_dirname("x=a%2Fb") != flat_dirname("x=a/b")


def test_a_long_init_from_path_makes_a_job_directory_name_the_file_system_takes(tmp_path):
    from higbench.config import flat_dirname

    deep = "/".join(["a_rather_long_folder_name_of_runs"] * 12) + "/run.h5"  # 407 characters
    names = {flat_dirname(f"init_from={deep},seed={s}") for s in (0, 1)}
    assert len(names) == 2 and flat_dirname(f"init_from={deep},seed=0") in names  # distinct, and the same again
    for name in names:
        assert len(f"999_{name}".encode()) <= 255
        (tmp_path / f"999_{name}").mkdir()  # the file system takes it


@pytest.mark.parametrize(
    "override,key",
    [
        ("optimizer.lr=-1", "optimizer.lr"),
        ("optimizer.lr=0", "optimizer.lr"),
        ("budget.seconds=0", "budget.seconds"),
        ("batch_size=5000", "batch_size"),
        ("optimizer.tau=-0.001", "optimizer.tau"),
        ("optimizer.kappa=1.5", "optimizer.kappa"),
        ("device=tpu", "device"),
    ],
)
def test_bad_input_is_refused_before_training(higbench, tmp_path, override, key):
    code, _, err = higbench("problem=toy", "optimizer=hig", override)
    assert code == 2, err
    lines = [line for line in err.strip().splitlines() if line]
    assert len(lines) == 1 and key in lines[0] and override.split("=", 1)[1] in lines[0]
    assert list(tmp_path.rglob("*")) == []


def test_diverging_run_is_recorded_not_crashed(higbench, tmp_path):
    code, _, err = higbench("problem=toy", "optimizer=sgd", "optimizer.lr=1e30", "budget.max_updates=20")
    assert code == 0, err
    (path,) = run_files(tmp_path / "outputs")
    meta, curves = load_run(path)
    assert meta["status"] == "diverged" and meta["status_reason"]
    assert meta["status_step"] >= 1 and len(curves) >= 1  # the curve so far is kept


@pytest.mark.parametrize("problem", PROBLEM_CONFIGS)
@pytest.mark.parametrize("optimizer", ["adam", "hig"])  # every optimizer on the toy: tests/optim/test_every_optimizer.py
def test_every_problem_trains_a_few_updates(higbench, tmp_path, problem, optimizer):
    code, _, err = higbench(f"problem={problem}", f"optimizer={optimizer}", *SMALL_RUN, "budget.max_updates=2")
    assert code == 0, err
    meta, curves = load_run(run_files(tmp_path / "outputs")[0])
    assert meta["status"] == "completed" and curves["test_loss"].notna().all()


def test_help_lists_every_choice_and_the_outputs(higbench, tmp_path):
    code, out, err = higbench("--help", tiny=False)
    assert code == 0, err
    conf = Path(__file__).resolve().parent.parent / "conf"
    for group in ("problem", "optimizer", "experiment"):
        for name in sorted(p.stem for p in (conf / group).glob("*.yaml")):
            assert f" {name} " in out.replace("\n", " \n"), f"--help does not list {group} {name}"
    assert "problem_optimizer:" not in out and "powered by Hydra" not in out
    assert "outputs/runs/" in out and "budget.seconds" in out
    assert list(tmp_path.rglob("*")) == []


def test_hydra_log_is_named_after_the_tool_and_not_empty(higbench, tmp_path):
    code, _, err = higbench("problem=toy", "optimizer=adam")
    assert code == 0, err
    (run,) = run_files(tmp_path / "outputs")
    log = run.parent / "higbench.log"
    assert log.is_file() and not (run.parent / "cli.log").exists()
    assert "completed: toy/adam" in log.read_text()  # the summary goes through logging too


# -- the front door's one-line answers (issue 19 item 10, issue 20 items 3 and 9), in-process --


def one_line(code, err, key: str, value: str) -> str:
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("higbench: error: "), err
    assert f"{key}={value}" in lines[0], lines[0]
    return lines[0]


def test_an_integer_too_long_to_print_is_one_line(higbench, tmp_path):
    code, _, err = higbench("optimizer.lr=1" + "0" * 5000)
    one_line(code, err, "optimizer.lr", "1000")
    assert list(tmp_path.rglob("*")) == []


def test_a_run_dir_nested_too_deep_is_one_line(higbench, tmp_path):
    code, _, err = higbench("hydra.run.dir=" + "a/" * 1900)
    assert "nested too deep" in one_line(code, err, "hydra.run.dir", "a/a/a")
    assert list(tmp_path.rglob("*")) == []


def test_a_repeated_key_names_the_value_that_wins(higbench):
    code, _, err = higbench("progress=false", "progress=maybe")
    one_line(code, err, "progress", "maybe")


def test_a_non_number_for_a_numeric_optimizer_argument_is_one_line(higbench):
    code, _, err = higbench("optimizer=hig", "optimizer.kappa=abc")
    assert "must be a number" in one_line(code, err, "optimizer.kappa", "abc")


def test_multirun_cfg_job_prints_each_jobs_config(higbench, tmp_path):
    code, out, err = higbench("-m", "problem=toy", "optimizer=adam,hig", "--cfg", "job", tiny=False)
    assert code == 0, err
    assert out.count("# job ") == 2 and "name: adam" in out and "name: hig" in out
    code, out, err = higbench("-m", "+experiment=fig5_adagrad", "--cfg", "job", tiny=False)  # docs/sweeps.md
    assert code == 0 and out.count("# job ") >= 2, err
    assert list(tmp_path.rglob("*")) == []


@pytest.mark.process  # the pipe is the point
def test_help_into_a_closed_pipe_is_quiet(tmp_path):
    import subprocess
    import sys

    proc = subprocess.Popen(
        [sys.executable, "-m", "higbench.cli", "--help"], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    proc.stdout.close()  # `higbench --help | head -0`: the reader is gone before the text comes
    assert proc.wait(timeout=60) == 0 and b"Traceback" not in proc.stderr.read()


def _fake_train(status: str, fail_for: str | None = None):
    """A stand-in for the runner: a run that ends ``status`` (or a full disk for one optimizer)."""
    from higbench.runfile.writer import DiskFull
    from higbench.runner.train import RunSummary

    def train(plan):
        run_path = plan.run_path
        if plan.config["optimizer"]["name"] == fail_for:
            raise DiskFull(f"no space left on the device writing {run_path}")
        return RunSummary(status, 1, 0.1, 0.5, run_path, "SIGINT" if status == "interrupted" else "")

    return train


def test_a_sweep_with_a_failed_job_exits_1_and_says_how_many(higbench, monkeypatch):
    monkeypatch.setattr("higbench.runner.train.train", _fake_train("completed", fail_for="adam"))
    code, _, err = higbench("-m", "optimizer=adam,hig,sgd")
    assert code == 1 and "1 of 3 sweep jobs failed" in err, err


def test_a_failed_job_does_not_stop_the_later_batches(higbench, monkeypatch, tmp_path):
    """Hydra's basic sweeper raised a failure after its batch, so with max_batch_size the later
    batches never ran; higbench's default sweeper runs them all, then says how many failed."""
    ran = []
    fake = _fake_train("completed", fail_for="adam")

    def train(plan):
        ran.append(plan.config["optimizer"]["name"])
        return fake(plan)

    monkeypatch.setattr("higbench.runner.train.train", train)
    batches = ["hydra.sweeper.max_batch_size=1", f"hydra.sweep.dir={tmp_path / 'sw'}"]
    code, _, err = higbench("-m", "optimizer=adam,hig,sgd", *batches)
    assert code == 1 and "1 of 3 sweep jobs failed" in err, err
    assert ran == ["adam", "hig", "sgd"]


def test_ctrl_c_in_a_sweep_says_how_to_complete_the_sweep(higbench, monkeypatch, tmp_path):
    monkeypatch.setattr("higbench.runner.train.train", _fake_train("interrupted"))
    code, _, err = higbench("-m", "optimizer=adam,hig", f"hydra.sweep.dir={tmp_path / 'sw'}")
    assert code == 130, err
    assert "complete the sweep with: higbench -m" in err and f"hydra.sweep.dir={tmp_path / 'sw'} resume=true" in err, err
    assert "Traceback" not in err


def test_resume_with_is_said_only_when_a_checkpoint_exists(higbench, monkeypatch, tmp_path):
    monkeypatch.setattr("higbench.runner.train.train", _fake_train("interrupted"))
    code, _, err = higbench(f"hydra.run.dir={tmp_path / 'r'}")
    assert code == 130 and "resume with:" not in err and "cannot be resumed" in err, err


def test_gn_diverging_says_what_the_figures_do(higbench, monkeypatch):
    monkeypatch.setattr("higbench.runner.train.train", _fake_train("diverged"))
    code, out, err = higbench("optimizer=gn")
    assert code == 0 and "seed=7" in out, out


def test_an_unknown_flag_is_one_line_not_argparse_usage(higbench, tmp_path):
    code, _, err = higbench("seed=0", "-m", "--bogus")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--bogus" in err and "usage:" not in err, err
    assert list(tmp_path.rglob("*")) == []


@pytest.mark.process  # joblib's workers
def test_joblib_jobs_from_a_job_list_record_that_they_shared_the_machine(higbench, tmp_path, fresh_joblib_workers):
    """The figures' launch: the joblist sweeper on joblib. Its jobs come from a file, not the
    command line: two of them on two workers ran together, and both run files say so. (A
    sweep from the command line on joblib: tests/sweeps/test_sweep_launchers.py.)"""
    import json

    from hydra_plugins.higbench_joblist_sweeper.joblist_sweeper import register

    register()  # where Hydra's plugin scan does not see the repository's hydra_plugins (an editable install)
    jobs = tmp_path / "jobs.json"
    jobs.write_text(json.dumps([["optimizer=adam"], ["optimizer=sgd"]]))
    args = ["hydra/sweeper=joblist", f"hydra.sweeper.jobs_file={jobs}", "hydra/launcher=joblib", "hydra.launcher.n_jobs=2"]
    code, _, err = higbench("-m", "problem=toy", *args)
    assert code == 0, err
    envs = [load_run(path)[0]["env"] for path in run_files(tmp_path / "outputs")]
    assert [env["parallel_jobs"] for env in envs] == [2, 2], envs
    code, _, err = higbench("problem=toy", "hydra/launcher=joblib", "hydra.launcher.n_jobs=2")  # a single run is alone
    assert code == 0 and sorted(load_run(p)[0]["env"]["parallel_jobs"] for p in run_files(tmp_path / "outputs")) == [1, 2, 2]


def test_a_missing_launcher_names_the_extra_that_has_it(monkeypatch):
    from hydra.errors import MissingConfigException

    from higbench.preflight import composition_error

    exc = MissingConfigException("no joblib", "hydra/launcher/joblib", ["basic", "slurm"])
    assert 'pip install -e ".[cluster]"' in str(composition_error(exc, ["hydra/launcher=joblib"]))


# -- one place per rule: the lists of keys come from the schema's field metadata -------------


def test_the_key_lists_are_derived_from_the_schema():

    from hydra import compose, initialize_config_dir

    from higbench import config
    from higbench.jobs import LAUNCH_OVERRIDES
    from higbench.results import index
    from higbench.runner import stored

    with initialize_config_dir(config_dir=config.config_dir(), version_base="1.3"):
        composed = compose("config", return_hydra_config=True)
    excluded = list(composed.hydra.job.config.override_dirname.exclude_keys)  # from the schema, resolved
    assert sorted(excluded) == sorted(config.JOB_DIR_EXCLUDED_KEYS), "conf/config.yaml exclude_keys differ from the schema"
    assert index.COSMETIC_KEYS is config.COSMETIC_KEYS and stored.RESUMABLE_KEYS is config.RESUMABLE_KEYS
    assert set(config.COSMETIC_KEYS) <= set(config.RESUMABLE_KEYS)  # what changes no result may change on resume
    assert {o.split("=")[0] for o in LAUNCH_OVERRIDES} <= set(config.COSMETIC_KEYS), "figures launch with identity keys"
    assert "seed" not in config.COSMETIC_KEYS and "batch_size" in config.SIZING_KEYS


def test_the_optimizer_arguments_rule_is_one_definition():
    from higbench import config
    from higbench.runner import updates

    assert updates.optimizer_kwargs is config.optimizer_kwargs
    assert config.optimizer_kwargs({"name": "adam", "_target_": "torch.optim.Adam", "lr": 1, "betas": [0.9, 0.99]}) == {
        "lr": 1,
        "betas": (0.9, 0.99),
    }


def test_resume_announces_the_stored_run_not_the_config_defaults(higbench, tmp_path):
    """``higbench resume=<an oscillator run>`` used to say ``toy/hig: resuming, batch size 256``."""
    import signal

    from in_process import signal_when

    run = tmp_path / "osc"
    args = ["problem=oscillator", "optimizer=adam", "batch_size=8", "problem.test_size=16", "budget.seconds=60"]
    args += ["checkpoint_every=0.05", "eval_every=0.05", "progress=false", "threads=1", f"hydra.run.dir={run}"]
    with signal_when(run / "run.h5.ckpt", signal.SIGINT):  # Ctrl-C once it has a checkpoint
        code, _, err = higbench(*args, tiny=False)
    assert code == 128 + signal.SIGINT, err
    code, _, err = higbench(f"resume={run}", "budget.seconds=0.01", "progress=true", tiny=False)
    assert code == 0 and "oscillator/adam: resuming, batch size 8" in err, err


@pytest.mark.parametrize("value", [None, True, 0.001, 3, "cuda:0", "a b", "it's", "x\\y", "a b\\", "", [1, "a,b"], {"k": 1.5}])
def test_override_value_parses_back_to_the_value(value):
    from hydra.core.override_parser.overrides_parser import OverridesParser

    from higbench.errors import override_value

    (parsed,) = OverridesParser.create().parse_overrides([f"key={override_value(value)}"])
    assert parsed.value() == value


def test_summary_times_thresholds_below_where_the_loss_started(higbench):
    """Poisson's loss starts at ~440: the summary times 1e1..1e-1, not the oscillator's 1e-3..1e-5."""
    code, out, err = higbench("problem=poisson", "optimizer=adam", "batch_size=8", "problem.test_size=8")
    assert code == 0, err
    line = next(ln for ln in out.splitlines() if "time to test loss" in ln)
    assert "1e+01:" in line and "1e-03" not in line, line
