"""Shared set-up for the optimizer tests: a problem in float64 with a small batch."""

from __future__ import annotations

import copy
import functools

import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from higbench.config import config_dir
from higbench.problems import build_problem

# Every problem (and the dipole CNN) with short horizons so the naive reference stays fast.
CASES = {
    "toy": ("toy", []),
    "oscillator": ("oscillator", ["problem.steps=12"]),
    "poisson": ("poisson", []),
    "dipole": ("dipole", ["problem.steps=10"]),
    "dipole_cnn": ("dipole", ["problem.model=cnn", "problem.steps=10"]),
}


@functools.lru_cache(maxsize=64)
def _composed(problem: str, overrides: tuple[str, ...], optimizer: str):
    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        return compose(config_name="config", overrides=[f"problem={problem}", f"optimizer={optimizer}", *overrides])


def compose_cfg(problem: str, *overrides: str, optimizer: str = "hig"):
    """Composed once per problem (Hydra takes ~0.2-0.5 s here); ``optimizer.*`` values set after."""
    opt = [o for o in overrides if o.startswith("optimizer.")]
    cfg = copy.deepcopy(_composed(problem, tuple(o for o in overrides if o not in opt), optimizer))
    for item in opt:
        key, value = item.split("=", 1)
        OmegaConf.update(cfg, key, _value(value), merge=False)
    return cfg


def _value(text: str):
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def setup(case: str, batch_size: int = 3, *overrides: str, dtype=torch.float64, optimizer: str = "hig"):
    """(cfg, problem, model, batch) for a case of CASES."""
    problem, extra = CASES[case]
    cfg = compose_cfg(problem, *extra, *overrides, optimizer=optimizer)
    p = build_problem(cfg.problem, dtype=dtype, device=torch.device("cpu"), seed=0)
    model = p.build_model()
    gen = torch.Generator().manual_seed(1)
    batch = next(p.epoch(batch_size, gen)) if p.train_size() is not None else p._sample(batch_size, gen)
    return cfg, p, model, batch


def flat(model) -> torch.Tensor:
    return torch.cat([q.detach().reshape(-1).clone() for q in model.parameters()]).double()
