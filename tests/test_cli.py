"""The console script end to end: run files, multirun, bad input, divergence."""

from pathlib import Path

import h5py
import pytest

from higbench.results import load_run, load_updates, load_weights


def run_files(root: Path) -> list[Path]:
    return sorted(root.rglob("run.h5"))


def test_single_run_writes_a_complete_run_file(cli, tmp_path):
    proc = cli("problem=toy", "optimizer=hig", "problem.gamma=0.01")
    assert proc.returncode == 0, proc.stderr
    files = run_files(tmp_path / "outputs")
    assert len(files) == 1 and f"run file: {files[0]}" in proc.stdout
    meta, curves = load_run(files[0])
    assert meta["status"] == "completed"
    assert meta["config"]["problem"]["gamma"] == 0.01 and meta["config"]["optimizer"]["kappa"] == -0.5
    assert "problem.gamma=0.01" in meta["overrides"]
    assert {"step", "epoch", "wall_time", "train_loss", "test_loss"} <= set(curves.columns)
    assert list(curves["step"]) == [0, 1, 2, 3]
    assert curves["wall_time"].is_monotonic_increasing
    for key in ("torch_version", "python_version", "hostname", "torch_threads", "device", "git_revision"):
        assert key in meta["env"]
    updates = load_updates(files[0])
    assert len(updates) == 3 and (updates[["jacobian_s", "inversion_s", "apply_s"]] > 0).all().all()
    assert meta["memory"]["peak_rss_mb"] > 0
    weights = load_weights(files[0])
    assert weights["0.weight"].shape == (7, 1)
    with h5py.File(files[0]) as f:  # saturation and probe logs, one row per evaluation
        assert f["logs/neuron_mean"].shape == (4, 7) and f["logs/probe_output"].shape == (4, 2)


def test_multirun_writes_one_file_per_job(cli, tmp_path):
    proc = cli("-m", "problem=toy", "optimizer=adam,hig")
    assert proc.returncode == 0, proc.stderr
    files = run_files(tmp_path / "outputs" / "sweeps")
    assert len(files) == 2
    assert sorted(load_run(f)[0]["optimizer"] for f in files) == ["adam", "hig"]


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
def test_bad_input_is_refused_before_training(cli, tmp_path, override, key):
    proc = cli("problem=toy", "optimizer=hig", override)
    assert proc.returncode == 2, proc.stderr
    lines = [line for line in proc.stderr.strip().splitlines() if line]
    assert len(lines) == 1 and key in lines[0] and override.split("=", 1)[1] in lines[0]
    assert run_files(tmp_path) == []


def test_diverging_run_is_recorded_not_crashed(cli, tmp_path):
    proc = cli("problem=toy", "optimizer=sgd", "optimizer.lr=1e30", "budget.max_updates=20")
    assert proc.returncode == 0, proc.stderr
    (path,) = run_files(tmp_path / "outputs")
    meta, curves = load_run(path)
    assert meta["status"] == "diverged" and meta["status_reason"]
    assert meta["status_step"] >= 1 and len(curves) >= 1  # the curve so far is kept


@pytest.mark.parametrize("problem", ["oscillator", "poisson", "dipole", "dipole_cnn"])
@pytest.mark.parametrize("optimizer", ["adam", "hig"])
def test_every_problem_trains_a_few_updates(cli, tmp_path, problem, optimizer):
    small = ["batch_size=4", "problem.test_size=16"]
    proc = cli(f"problem={problem}", f"optimizer={optimizer}", *small, "budget.max_updates=2")
    assert proc.returncode == 0, proc.stderr
    meta, curves = load_run(run_files(tmp_path / "outputs")[0])
    assert meta["status"] == "completed" and curves["test_loss"].notna().all()


def test_help_lists_every_choice_and_the_outputs(cli, tmp_path):
    proc = cli("--help", tiny=False)
    assert proc.returncode == 0, proc.stderr
    conf = Path(__file__).resolve().parent.parent / "conf"
    for group in ("problem", "optimizer", "experiment"):
        for name in sorted(p.stem for p in (conf / group).glob("*.yaml")):
            assert f" {name} " in proc.stdout.replace("\n", " \n"), f"--help does not list {group} {name}"
    assert "problem_optimizer:" not in proc.stdout and "powered by Hydra" not in proc.stdout
    assert "outputs/runs/" in proc.stdout and "budget.seconds" in proc.stdout
    assert not (tmp_path / "outputs").exists()


def test_hydra_log_is_named_after_the_tool_and_not_empty(cli, tmp_path):
    proc = cli("problem=toy", "optimizer=adam")
    assert proc.returncode == 0, proc.stderr
    (run,) = run_files(tmp_path / "outputs")
    log = run.parent / "higbench.log"
    assert log.is_file() and not (run.parent / "cli.log").exists()
    assert "completed: toy/adam" in log.read_text()  # the summary goes through logging too
