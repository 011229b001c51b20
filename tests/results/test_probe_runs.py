"""scripts/probe_runs.py: the probes' runs are jobs of the one launcher (no training here)."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
import probe_oscillator_tail  # noqa: E402
import probe_poisson_data  # noqa: E402
import probe_runs  # noqa: E402

sys.path.remove(str(ROOT / "scripts"))


def test_a_probe_run_is_a_job_with_hydra_values_and_its_parent():
    parent = probe_runs.as_job(probe_poisson_data.job("fourier", "adam", 1e-4, 30), "scratch")
    assert parent.overrides["problem.hidden"] == [64, 128, 64] and parent.overrides["optimizer.lr"] == 1e-4
    parent.path = Path("/runs/adam/run.h5")
    child = probe_runs.as_job([*probe_poisson_data.job("fourier", "hig", 0.01, 20), "seed=3"], "continued", parent)
    assert child.seed == 3 and child.parent is parent
    assert child.override_list()[-1] == "init_from=/runs/adam/run.h5"  # the reuse rule knows it by its parent's identity


def test_the_probes_paper_adam_rate_is_the_pair_configs():
    import yaml

    pair = yaml.safe_load((ROOT / "conf" / "problem_optimizer" / "poisson_adam.yaml").read_text())
    assert probe_poisson_data.paper_adam_lr() == pair["optimizer"]["lr"]


def test_run_missing_launches_only_what_is_not_done(monkeypatch, tmp_path):
    """The one reuse rule: done jobs are reused, waiting ones wait, the rest go to jobs.launch once,
    and the jobs are resolved again after it; what is still not done is returned."""
    from higbench import jobs

    done, todo, waiting = (probe_runs.as_job([f"seed={s}"], "x") for s in range(3))
    state = {"resolved": 0, "launched": []}

    def resolve(js, index):
        state["resolved"] += 1
        done.status, waiting.status = "completed", "waiting"
        todo.status = "completed" if state["launched"] else "missing"

    monkeypatch.setattr(jobs, "resolve", resolve)
    monkeypatch.setattr(jobs, "run_index", lambda root: {})
    monkeypatch.setattr(jobs, "launch", lambda js, root, **kw: state["launched"].append(list(js)))
    left = jobs.run_missing([done, todo, waiting], tmp_path, n_jobs=1, log=lambda text: None)
    assert state["launched"] == [[todo]] and state["resolved"] == 2 and left == [waiting]


def test_the_oscillator_tail_reads_the_final_per_sample_losses(tmp_path):
    import numpy as np

    from higbench.runfile.writer import RunFileWriter

    losses = np.full(1000, 1e-8)
    losses[-10:] = 1e-5  # ten samples carry almost all of the mean
    w = RunFileWriter(tmp_path / "run.h5", "problem: {name: oscillator}\n", [], env={}, meta={"problem": "oscillator"})
    w.write_final({"test_losses": losses}, 100)
    w.close("completed", "", 100)
    row = probe_oscillator_tail.tail_row(str(tmp_path / "run.h5"))
    assert np.isclose(row["mean"], losses.mean()) and row["median"] == 1e-8
    assert np.isclose(row["worst_share"], 1e-4 / (1e-4 + 990e-8)) and np.isclose(row["max_share"], 1e-5 / losses.sum())
    assert len(probe_oscillator_tail.jobs(300)) == 6  # 3 data draws x 2 seeds
