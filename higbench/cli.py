"""`higbench` console script: compose the config with Hydra, validate, train, report.

    higbench problem=oscillator optimizer=hig
    higbench -m problem=toy optimizer=adam,hig        # one run file per job
"""

from __future__ import annotations

import math
import sys
from importlib import resources
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from higbench.config import ConfigError, validate

RUN_FILE_NAME = "run.h5"


def config_dir() -> str:
    """conf/ of a checkout (or editable install), else the copy shipped in the wheel."""
    checkout = Path(__file__).resolve().parent.parent / "conf"
    if (checkout / "config.yaml").is_file():
        return str(checkout)
    return str(resources.files("higbench") / "conf")


@hydra.main(version_base="1.3", config_path=config_dir(), config_name="config")
def main(cfg: DictConfig) -> float:
    try:
        validate(cfg)
    except ConfigError as exc:
        print(f"higbench: error: {exc}", file=sys.stderr)
        sys.exit(2)
    from higbench.runner.train import train  # torch import after the cheap checks

    hydra_cfg = HydraConfig.get()
    run_path = Path(hydra_cfg.runtime.output_dir) / RUN_FILE_NAME
    try:
        summary = train(cfg, run_path, overrides=list(hydra_cfg.overrides.task))
    except ValueError as exc:  # a problem or optimizer refusing its arguments
        print(f"higbench: error: {exc}", file=sys.stderr)
        sys.exit(2)
    print(
        f"{summary.status}: {cfg.problem.name}/{cfg.optimizer.name} {summary.steps} updates in "
        f"{summary.wall_time:.1f}s, final test loss {summary.final_test_loss:.4e}"
        + (f" ({summary.reason})" if summary.reason else "")
    )
    print(f"run file: {summary.path}")
    # The return value is what sweepers (Optuna) minimise; a diverged run scores worst.
    loss = summary.final_test_loss
    return loss if summary.status == "completed" and math.isfinite(loss) else float("inf")


if __name__ == "__main__":
    main()
