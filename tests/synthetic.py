"""Small synthetic run files written with the real RunFileWriter (no training), and
``short_run``: a few real toy updates trained in this process."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from higbench.runfile.writer import RunFileWriter
from higbench.runner.plan import Plan


def write_run(
    path: Path,
    *,
    problem: str = "toy",
    optimizer: str = "adam",
    lr: float = 0.1,
    batch_size: int = 64,
    test_loss: list[float] | None = None,
    status: str = "completed",
    close: bool = True,
    n_updates: int = 20,
    problem_extra: dict | None = None,
    config_extra: dict | None = None,
) -> Path:
    """A run file as the runner leaves it; ``close=False`` returns the open writer's file."""
    test_loss = [1.0, 0.1, 0.02, 0.005] if test_loss is None else test_loss
    config = {
        "problem": {"name": problem, "gamma": 1.0, **(problem_extra or {})},
        "optimizer": {"name": optimizer, "lr": lr, "betas": [0.9, 0.999]},
        "batch_size": batch_size,
        "seed": 0,
        "budget": {"seconds": None, "max_updates": n_updates},
        **(config_extra or {}),
    }
    overrides = [f"optimizer={optimizer}", f"optimizer.lr={lr}", f"batch_size={batch_size}"]
    w = RunFileWriter(
        path,
        yaml.safe_dump(config),
        overrides,
        env={"hostname": "test", "torch_threads": 1},
        meta={"problem": problem, "optimizer": optimizer},
    )
    n = len(test_loss)
    steps = np.linspace(0, n_updates, n).astype(int)
    for i in range(n):
        w.append_row(
            "curves",
            {
                "step": steps[i],
                "epoch": 0,
                "wall_time": 0.5 * i,
                "train_loss": test_loss[i] * 1.1,
                "test_loss": test_loss[i],
                "rss_mb": 100.0,
            },
        )
    w.append_rows(
        "updates",
        {"step": np.arange(1, n_updates + 1), "update_s": np.full(n_updates, 0.01), "jacobian_s": np.full(n_updates, 0.004)},
    )
    w.set_attrs("memory", {"peak_rss_mb": 123.0, "baseline_rss_mb": 100.0, "cuda_peak_mb": 0.0})
    w.flush()
    if not close:
        return w
    w.f.attrs["steps"] = n_updates
    w.f.attrs["wall_time"] = 0.5 * (n - 1)
    w.close(status, "" if status == "completed" else "because", n_updates)
    return path


def short_run(tmp_path: Path, optimizer: str, *overrides: str, updates: int = 9, eval_every: int = 3) -> Path:
    """Train the toy problem for ``updates`` updates in this process (composed as the CLI does);
    the run file's path. Restores torch's thread count."""
    import torch
    from hydra import compose, initialize_config_dir

    from higbench.config import config_dir
    from higbench.runner import train as train_mod

    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        cfg = compose(
            "config",
            overrides=["problem=toy", f"optimizer={optimizer}", f"budget.max_updates={updates}", "eval_unit=updates",
                       f"eval_every={eval_every}", "threads=1", "progress=false", "checkpoint_every=null", *overrides],
        )  # fmt: skip
    threads = torch.get_num_threads()
    try:
        train_mod.train(Plan.for_run(cfg, tmp_path / "run.h5"))
    finally:
        torch.set_num_threads(threads)
    return tmp_path / "run.h5"
