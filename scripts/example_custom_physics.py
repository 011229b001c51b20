"""HIG in your own PyTorch code: learn to identify a damped spring, no Hydra, no runner.

The "physics" is a user-written, differentiable, batched simulation: a damped spring
x'' = -k x - c x' started at x = 1, v = 0, integrated with semi-implicit Euler; we observe
the position at 10 times. A small network sees the 10 observations and predicts
(log k, log c); the simulation turns that prediction back into 10 positions, and the loss
is their squared distance to the observations. So the network must learn to invert the
simulator, and every update goes through it:

    opt = HIG(model.parameters(), lr=1.0, tau=1e-6)
    loss = opt.step_structured(model, observations, physics=spring, loss=per_sample_loss)

``step_structured`` differentiates the simulator (10 batched reverse passes for all samples)
and the network (per-layer factors) apart and never forms J. Run it:

    python scripts/example_custom_physics.py            # HIG for ~10 s
    python scripts/example_custom_physics.py --adam     # and Adam for the same time, to compare

Another example, in a notebook with its plot (a ball through air drag):
examples/hig_in_your_code.ipynb.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from functools import partial
from pathlib import Path

import torch
from torch import nn

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # run from a checkout

from higbench.optim import HIG  # noqa: E402

DT, STEPS, EVERY = 0.05, 100, 10  # 5 time units, an observation every 0.5


def spring(log_kc: torch.Tensor) -> torch.Tensor:
    """Positions at 10 times for (log k, log c) (b, 2) -> (b, 10). Pure torch, batched."""
    k, c = log_kc.exp().unbind(-1)
    x = torch.ones_like(k)
    v = torch.zeros_like(k)
    seen = []
    for step in range(1, STEPS + 1):
        v = v - DT * (k * x + c * v)
        x = x + DT * v
        if step % EVERY == 0:
            seen.append(x)
    return torch.stack(seen, dim=-1)


def per_sample_loss(y: torch.Tensor, observed: torch.Tensor) -> torch.Tensor:
    return ((y - observed) ** 2).sum(-1)


def sample(n: int, gen: torch.Generator) -> torch.Tensor:
    """Observations of springs with k in [0.5, 4], c in [0.05, 1] (log-uniform)."""
    lo = torch.tensor([math.log(0.5), math.log(0.05)])
    hi = torch.tensor([math.log(4.0), math.log(1.0)])
    log_kc = lo + (hi - lo) * torch.rand(n, 2, generator=gen)
    return spring(log_kc)


def make_model(seed: int = 0) -> nn.Module:
    torch.manual_seed(seed)
    return nn.Sequential(nn.Linear(10, 32), nn.Tanh(), nn.Linear(32, 32), nn.Tanh(), nn.Linear(32, 2))


def train(
    optimizer: str = "hig", seconds: float = 10.0, max_steps: int | None = None, batch_size: int = 64, seed: int = 0, log=print
):
    """Train for ``seconds`` (or ``max_steps`` updates); returns [(time, step, test loss)]."""
    gen = torch.Generator().manual_seed(seed)
    test = sample(512, gen)
    model = make_model(seed)

    def test_loss() -> float:
        with torch.no_grad():
            return per_sample_loss(spring(model(test)), test).mean().item()

    if optimizer == "hig":
        opt = HIG(model.parameters(), lr=1.0, tau=1e-6)
    else:
        opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    history = [(0.0, 0, test_loss())]
    clock, step = 0.0, 0
    while clock < seconds and (max_steps is None or step < max_steps):
        obs = sample(batch_size, gen)
        t0 = time.perf_counter()
        if optimizer == "hig":
            # The network, the simulator and the per-sample loss, as three callables.
            opt.step_structured(model, obs, physics=spring, loss=partial(per_sample_loss, observed=obs))
        else:
            opt.zero_grad()
            per_sample_loss(spring(model(obs)), obs).mean().backward()
            opt.step()
        clock += time.perf_counter() - t0
        step += 1
        if step % 20 == 0 or clock >= seconds or step == max_steps:
            history.append((clock, step, test_loss()))
            log(f"{optimizer:5s} t={clock:6.2f}s step={step:5d} test loss={history[-1][2]:.3e}")
    return history


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--adam", action="store_true", help="also train with Adam for the same time")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    hig = train("hig", args.seconds)
    print(f"HIG:  test loss {hig[0][2]:.3e} -> {hig[-1][2]:.3e} in {hig[-1][1]} updates")
    if args.adam:
        adam = train("adam", args.seconds)
        print(f"Adam: test loss {adam[0][2]:.3e} -> {adam[-1][2]:.3e} in {adam[-1][1]} updates")


if __name__ == "__main__":
    main()
