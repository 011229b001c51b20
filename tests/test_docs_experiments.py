"""docs/experiments.md's table of defaults is what conf/ composes."""

import re
from pathlib import Path

from hydra import compose, initialize_config_dir

import higbench.config  # noqa: F401  registers the schema conf/config.yaml names (higbench_schema)
from higbench.config import config_dir

ROOT = Path(__file__).resolve().parent.parent
ROW = re.compile(r"^\| `(\w+)` \| `(\w+)` \| (\d+) \| ([^|]+) \| ([^|]*) \| (\d+) \|$", re.M)


def test_every_pair_default_in_docs_matches_conf():
    rows = ROW.findall((ROOT / "docs" / "experiments.md").read_text())
    pairs = {p.stem for p in (ROOT / "conf" / "problem_optimizer").glob("*.yaml")}
    assert {f"{p}_{o}" for p, o, *_ in rows} == pairs  # one row per specialised pair
    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        for problem, optimizer, batch, lr, tau, seconds in rows:
            cfg = compose("config", overrides=[f"problem={problem}", f"optimizer={optimizer}"])
            assert cfg.batch_size == int(batch), (problem, optimizer)
            assert cfg.optimizer.lr == float(lr), (problem, optimizer)
            assert cfg.optimizer.get("tau") == (float(tau) if tau.strip() else None), (problem, optimizer)
            assert cfg.budget.seconds == int(seconds), (problem, optimizer)
