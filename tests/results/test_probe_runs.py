"""scripts/probe_runs.py: the probes' runs are jobs of the one launcher (no training here)."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
import probe_league_device  # noqa: E402
import probe_oscillator_draws  # noqa: E402
import probe_poisson_data  # noqa: E402
import probe_runs  # noqa: E402
import probe_target_machine  # noqa: E402

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


def test_the_oscillator_draws_probe_reads_the_final_per_sample_losses(tmp_path):
    import numpy as np

    from higbench.runfile.writer import RunFileWriter

    losses = np.full(1000, 1e-8)
    losses[-10:] = 1e-5  # ten samples carry almost all of the mean
    fresh = np.full(5000, 2e-8)
    w = RunFileWriter(tmp_path / "run.h5", "problem: {name: oscillator}\n", [], env={}, meta={"problem": "oscillator"})
    w.write_final({"test_losses": losses, "fresh_test_losses": fresh}, 100)
    w.close("completed", "", 100)
    row = probe_oscillator_draws.tail_row(str(tmp_path / "run.h5"))
    assert np.isclose(row["mean"], losses.mean()) and row["median"] == 1e-8
    assert np.isclose(row["worst_share"], 1e-4 / (1e-4 + 990e-8)) and np.isclose(row["max_share"], 1e-5 / losses.sum())
    assert row["fresh_samples"] == 5000 and np.isclose(row["fresh_mean"], 2e-8)


def test_the_oscillator_draws_probe_runs_the_paper_hour_at_each_batch_size():
    """Updates, not seconds: the authors' hour on the paper's GPU at each b (table 3's cost ratio),
    3 (draw, seed) pairs per setting and 6 for HIG at b=128."""
    from collections import Counter

    from higbench.jobs import parse_overrides

    runs = [parse_overrides(j) for j in probe_oscillator_draws.jobs()]
    per_setting = Counter((r["optimizer"], r["batch_size"]) for r in runs)
    assert per_setting[("hig", 128)] == 6 and all(n >= 3 for n in per_setting.values())
    assert len({(r["problem.data_seed"], r["seed"]) for r in runs if r["batch_size"] == 128}) == 6
    updates = {r["batch_size"]: r["budget.max_updates"] for r in runs}
    assert updates[128] == 24657 and round(updates[32] / updates[128], 2) == 1.68  # 3600 s / 0.146 s; 0.146 / 0.087
    assert all(r["budget.seconds"] is None for r in runs)


def test_the_target_probe_reruns_each_published_rerun_with_its_seed_and_seconds():
    import pandas as pd

    reruns = pd.DataFrame({"overrides": ["progress=false threads=4 problem=toy optimizer=adam seed=3 budget.seconds=10.0 "
                                         "eval_every=0.1 optimizer.lr=0.0354 batch_size=256"]})  # fmt: skip
    (job,) = probe_target_machine.jobs(reruns)
    assert job == ["threads=1", "progress=false", "problem=toy", "optimizer=adam", "seed=3", "budget.seconds=10.0",
                   "eval_every=0.1", "optimizer.lr=0.0354", "batch_size=256"]  # fmt: skip


def test_the_device_probe_chooses_one_point_of_one_study_and_reruns_it_at_the_leagues_budget():
    """The tables number trials within a study, so trial 0 of study 0 and trial 0 of study 1 are two
    points: the choice (fastest to the target) is one of them, and its CPU figures are that point's."""
    import pandas as pd

    def trial(study, lr, seconds_to_target):
        return {"path": f"s{study}-{lr}", "run": f"s{study}-{lr}", "trial": 0, "study": study, "status": "completed",
                "league_job": f"tune/poisson/adam/{study}/0", "optimizer.name": "adam", "final_val_loss": 1.0,
                "steps": 100 * (study + 1), "train_time_s": 10.0,
                "overrides": f"progress=false threads=1 problem=poisson optimizer=adam seed={1000 + study} "
                             f"budget.seconds=10.0 eval_every=0.1 optimizer.lr={lr}"}, seconds_to_target  # fmt: skip

    rows, reach = zip(trial(0, 0.1, 6.0), trial(1, 0.01, 3.0), strict=True)
    tune = pd.DataFrame(rows)
    curves = pd.DataFrame([{"path": r["path"], "run": r["run"], "wall_time": t, "step": t, "val_loss": loss}
                           for r, at in zip(rows, reach, strict=True) for t, loss in ((0.0, 9.0), (at, 1.0))])  # fmt: skip
    overrides, rule, cpu = probe_league_device.chosen(tune, curves, "adam", target=2.0)
    assert overrides == ["problem=poisson", "optimizer=adam", "optimizer.lr=0.01"] and "time to the validation target" in rule
    assert list(cpu["study"]) == [1]  # the other study's trial 0 is another point
    figures = probe_league_device.cpu_figures({"cpu": cpu.assign(curve=[curves[curves["path"] == "s1-0.01"]])}, 2.0, 10.0)
    assert figures == {"cpu_updates_per_s": 20.0, "cpu_time_to_target_s": 3.0}
    job = probe_league_device.job_overrides({"overrides": overrides}, seed=4, budget=58.0, extra=["device=cuda"])
    assert job == ["threads=1", "progress=false", "problem=poisson", "optimizer=adam", "optimizer.lr=0.01", "seed=4",
                   "budget.seconds=58", "eval_every=0.58", "device=cuda"]  # fmt: skip
