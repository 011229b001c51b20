"""scripts/probe_runs.py: the probes' runs are jobs of the one launcher (no training here)."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
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
