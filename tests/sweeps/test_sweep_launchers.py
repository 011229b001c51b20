"""A 2x2 toy sweep (conf/experiment/toy_lr_grid.yaml) through three Hydra launchers.

Each must leave four completed run files that the results index finds, with the swept
values in their configs, readable directory names and Hydra's multirun.yaml. The basic and
joblib launchers are started from this process (joblib's workers are processes of their own);
submitit and Optuna (slow) through the CLI as a process.
"""

from __future__ import annotations

import joblib
import pytest
import yaml
from cases import TINY_RUN
from cli_runner import cli_env, run_cli
from conftest import GRID

from higbench.results import load_runs

TINY = [*TINY_RUN, "problem=toy"]


def sweep_cli(args: list[str], cwd, timeout: float = 180):
    """A sweep that must succeed; its launcher chooses the workers' threads."""
    return run_cli(args, cwd, timeout=timeout, env=cli_env(launcher_threads=True), check=True)


def check_sweep(sweep_dir):
    runs = load_runs(sweep_dir)
    assert len(runs) == 4, runs[["path", "status"]]
    assert set(runs["status"]) == {"completed"}, runs[["path", "status", "error"]]
    assert set(zip(runs["optimizer.lr"], runs["batch_size"])) == GRID
    assert set(runs["problem.name"]) == {"toy"} and set(runs["optimizer.name"]) == {"adam"}
    assert (runs["steps"] == 3).all()
    assert runs["final_test_loss"].notna().all()
    # readable names: job number plus the swept values
    for path, lr, b in zip(runs["path"], runs["optimizer.lr"], runs["batch_size"]):
        name = path.split("/")[-2]
        assert name.split("_", 1)[0].isdigit() and f"optimizer.lr={lr}" in name and f"batch_size={b}" in name, name
    multirun = yaml.safe_load((sweep_dir / "multirun.yaml").read_text())
    assert multirun["hydra"]["sweeper"]["params"] == {"optimizer.lr": "0.01,0.1", "batch_size": "64,128"}
    return runs


def test_basic_launcher(higbench, tmp_path):
    sweep = tmp_path / "sweep"
    code, _, err = higbench("-m", "+experiment=toy_lr_grid", "problem=toy", f"hydra.sweep.dir={sweep}")
    assert code == 0, err
    runs = check_sweep(sweep)
    assert list(runs["parallel_jobs"]) == [1.0] * 4  # one job at a time


@pytest.mark.process  # joblib's workers
def test_joblib_two_workers_cap_threads(higbench, tmp_path, monkeypatch, fresh_joblib_workers):
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.delenv(var, raising=False)  # the launcher chooses its workers' threads
    sweep = tmp_path / "sweep"
    code, _, err = higbench(
        "-m",
        "+experiment=toy_lr_grid",
        "problem=toy",
        "threads=null",  # torch's default thread count (the tiny run sets threads=1)
        f"hydra.sweep.dir={sweep}",
        "hydra/launcher=joblib",
        "hydra.launcher.n_jobs=2",
    )
    assert code == 0, err
    runs = check_sweep(sweep)
    # loky starts its workers with OMP_NUM_THREADS = cores // n_jobs; torch takes its default from it
    assert set(runs["env.torch_threads"]) == {max(joblib.cpu_count() // 2, 1)}
    assert runs["env.hostname"].notna().all()
    assert list(runs["parallel_jobs"]) == [2.0] * 4  # each run file says how many jobs shared the machine


@pytest.mark.process
@pytest.mark.slow
def test_joblib_explicit_threads(tmp_path):
    """`threads=N` wins over the launcher's cap (torch.set_num_threads in the job)."""
    sweep = tmp_path / "sweep"
    sweep_cli(
        [
            "-m",
            "+experiment=toy_lr_grid",
            *TINY,
            "optimizer.lr=0.1",
            "batch_size=64",
            "threads=3",
            f"hydra.sweep.dir={sweep}",
            "hydra/launcher=joblib",
            "hydra.launcher.n_jobs=2",
        ],
        tmp_path,
    )
    runs = load_runs(sweep)
    assert len(runs) == 1 and runs["env.torch_threads"].tolist() == [3]


@pytest.mark.process
@pytest.mark.slow
def test_submitit_local(tmp_path):
    sweep = tmp_path / "sweep"
    sweep_cli(
        [
            "-m",
            "+experiment=toy_lr_grid",
            *TINY,
            "threads=1",
            f"hydra.sweep.dir={sweep}",
            "hydra/launcher=submitit_local",
            "hydra.launcher.timeout_min=5",
        ],
        tmp_path,
        timeout=300,
    )
    runs = check_sweep(sweep)
    assert (sweep / ".submitit").is_dir()  # submitit's pickles and logs, next to the runs
    assert set(runs["env.torch_threads"]) == {1}


@pytest.mark.process
@pytest.mark.slow
@pytest.mark.optuna
def test_optuna_sweeper(tmp_path):
    """Optuna proposes lr/tau/batch_size, minimises what the job returns (the final test loss)."""
    sweep = tmp_path / "sweep"
    sweep_cli(
        [
            "-m",
            "+experiment=toy_optuna",
            *TINY,
            "hydra.sweeper.n_trials=3",
            "hydra.sweeper.n_jobs=1",
            f"hydra.sweep.dir={sweep}",
        ],
        tmp_path,
    )
    runs = load_runs(sweep)
    assert len(runs) == 3 and set(runs["status"]) == {"completed"}
    assert runs["optimizer.lr"].between(0.01, 3.0).all() and runs["optimizer.tau"].between(1e-10, 1e-2).all()
    assert set(runs["batch_size"]) <= {32, 64, 128, 256}
    result = yaml.safe_load((sweep / "optimization_results.yaml").read_text())
    assert result["best_value"] == pytest.approx(runs["final_test_loss"].min())
