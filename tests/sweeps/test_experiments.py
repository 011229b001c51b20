"""conf/experiment/*.yaml and conf/hydra/launcher/*.yaml, checked by composition (no training)."""

from __future__ import annotations

import itertools
import re

import pytest
from conftest import REPO
from hydra import compose, initialize_config_dir
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import OmegaConf

from higbench.config import config_dir, validate

CONF = REPO / "conf"
EXPERIMENTS = sorted(p.stem for p in (CONF / "experiment").glob("*.yaml"))
# (problem config, optimizer, swept keys) each grid must have; its size is stated in its header.
EXPECTED = {
    "fig5_adadelta": ("oscillator", "adadelta", {"optimizer.lr", "batch_size"}),
    "fig5_adagrad": ("oscillator", "adagrad", {"optimizer.lr", "batch_size"}),
    "fig5_sgd": ("oscillator", "sgd", {"optimizer.lr", "batch_size"}),
    "fig5_rmsprop": ("oscillator", "rmsprop", {"optimizer.lr", "batch_size"}),
    "fig6_adam": ("oscillator", "adam", {"optimizer.lr", "batch_size"}),
    "table2_oscillator_hig": ("oscillator", "hig", {"optimizer.lr", "batch_size", "optimizer.tau"}),
    "table2_oscillator_gn": ("oscillator", "gn", {"batch_size", "optimizer.tau"}),
    "fig8_dipole_adam": ("dipole", "adam", {"optimizer.lr", "batch_size"}),
    "fig9_dipole_hig": ("dipole", "hig", {"optimizer.lr", "batch_size", "optimizer.tau"}),
    "fig10_dipole_cnn_adam": ("dipole_cnn", "adam", {"optimizer.lr", "batch_size"}),
    "fig11_dipole_cnn_hig": ("dipole_cnn", "hig", {"optimizer.lr", "batch_size", "optimizer.tau"}),
    "fig12a_beta": ("oscillator", "hig", {"optimizer.beta"}),
    "fig12b_kappa": ("oscillator", "hig", {"optimizer.kappa"}),
    "fig13_tau": ("oscillator", "hig", {"optimizer", "optimizer.tau"}),
    "poisson_authors": ("poisson", "hig", {"optimizer.lr"}),
    "toy_lr_grid": ("toy", "adam", {"optimizer.lr", "batch_size"}),
    "toy_optuna": ("toy", "hig", {"optimizer.lr", "optimizer.tau", "batch_size"}),
}


@pytest.fixture(scope="module")
def hydra_compose():
    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        yield compose


def test_every_experiment_is_listed():
    assert set(EXPERIMENTS) == set(EXPECTED)


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.optuna) if "optuna" in n else n for n in EXPERIMENTS])
def test_experiment_composes_and_its_grid_validates(name, hydra_compose):
    problem, optimizer, keys = EXPECTED[name]
    if not (CONF / "problem" / f"{problem}.yaml").is_file():
        pytest.skip(f"conf/problem/{problem}.yaml not there yet")
    cfg = hydra_compose("config", overrides=[f"+experiment={name}"], return_hydra_config=True)
    assert cfg.hydra.runtime.choices.problem == problem and cfg.optimizer.name == optimizer
    params = OmegaConf.to_container(cfg.hydra.sweeper.params)
    assert set(params) == keys
    assert name in cfg.hydra.sweep.dir  # the sweep directory names the experiment
    if "Optuna" in cfg.hydra.sweeper._target_:
        assert cfg.hydra.sweeper.direction == "minimize"
        return
    parsed = OverridesParser.create().parse_overrides([f"{k}={v}" for k, v in params.items()])
    axes = [
        [f"{o.get_key_element()}={v}" for v in o.sweep_string_iterator()] if o.is_sweep_override() else [o.input_line]
        for o in parsed
    ]
    jobs = [list(job) for job in itertools.product(*axes)]  # as Hydra's basic sweeper crosses them
    stated = re.search(r"^# (\d+) runs:", (CONF / "experiment" / f"{name}.yaml").read_text(), re.M)
    assert stated and int(stated.group(1)) == len(jobs)
    job = jobs[-1]  # the grid's far corner is a valid config with the swept values
    job_cfg = hydra_compose("config", overrides=[f"+experiment={name}", *job])
    validate(job_cfg)
    for override in job:
        key, value = override.split("=", 1)
        if key == "optimizer":
            assert job_cfg.optimizer.name == value
        else:
            assert OmegaConf.select(job_cfg, key) == OverridesParser.create().parse_override(override).value()


def test_slurm_launcher_writes_the_sbatch_script(hydra_compose, tmp_path, monkeypatch):
    """hydra/launcher=slurm: partition, time, cpus, gpus as overrides -> #SBATCH lines."""
    submitit = pytest.importorskip("submitit")
    from hydra_plugins.hydra_submitit_launcher.config import BaseQueueConf

    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "srun").write_text("#!/bin/sh\nexit 0\n")
    (fake / "srun").chmod(0o755)
    monkeypatch.setenv("PATH", f"{fake}:{__import__('os').environ['PATH']}")  # SlurmExecutor insists on srun
    overrides = [
        "hydra/launcher=slurm",
        "hydra.launcher.partition=gpu",
        "hydra.launcher.timeout_min=90",
        "hydra.launcher.cpus_per_task=8",
        "hydra.launcher.gpus_per_node=1",
        f"hydra.sweep.dir={tmp_path}",
    ]
    cfg = hydra_compose("config", overrides=overrides, return_hydra_config=True)
    params = OmegaConf.to_container(cfg.hydra.launcher, resolve=True)
    assert params["_target_"].endswith("SlurmLauncher")
    # what hydra_submitit_launcher's BaseSubmititLauncher.launch does with these keys
    for key in ("_target_", "submitit_folder", "max_num_timeout"):
        params.pop(key)
    base = set(OmegaConf.structured(BaseQueueConf).keys())
    executor = submitit.AutoExecutor(folder=tmp_path / "submitit", cluster="slurm")
    executor.update_parameters(**{k if k in base else f"slurm_{k}": v for k, v in params.items()})
    script = executor._executor._make_submission_file_text("python -m submitit.core._submit x", "uid")
    for line in (
        "#SBATCH --partition=gpu",
        "#SBATCH --time=90",
        "#SBATCH --cpus-per-task=8",
        "#SBATCH --gpus-per-node=1",
        "#SBATCH --job-name=higbench",
        "export OMP_NUM_THREADS=8",
    ):
        assert line in script, script


def test_joblib_launcher_is_available(hydra_compose):
    cfg = hydra_compose("config", overrides=["hydra/launcher=joblib", "hydra.launcher.n_jobs=2"], return_hydra_config=True)
    assert cfg.hydra.launcher._target_.endswith("JoblibLauncher") and cfg.hydra.launcher.n_jobs == 2
