"""``device=auto``: run where one update of this run costs least, measured on this machine.

Which device is faster depends on the problem, the optimizer and the batch size, and on the
machine: on one H100 box the oscillator's and the dipole's HIG updates were about as fast on
its CPU as on its GPU, Poisson's 30x faster on the GPU (docs/benchmarks.md, "On a GPU"). A
table written on one machine would be wrong on the next, so ``auto`` measures: before the
run, outside its training clock, it times a few updates of the run's own optimizer and batch
size on each device it could use (throwaway network and optimizer, the run's random streams
untouched) and takes the cheaper. The choice, its reason and the measured costs go into the
run file (``/env``: ``device``, ``device_reason``, ``placement_s``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import torch

# Updates timed per device after one untimed update (compilation, allocator, caches); the
# least disturbed one counts.
TIMED_UPDATES = 2


@dataclass(frozen=True)
class Placement:
    device: torch.device
    reason: str
    costs: dict[str, float] = field(default_factory=dict)  # seconds per update, per device measured
    seconds: float = 0.0  # spent measuring

    def record(self) -> dict:
        """The run file's ``/env`` attributes of this choice."""
        return {"device_requested": "auto", "device_reason": self.reason, "placement_s": round(self.seconds, 3)}


def candidates(cuda_available: bool | None = None) -> list[torch.device]:
    """The devices ``auto`` may choose: the CPU, and the current GPU if CUDA is available."""
    cuda = torch.cuda.is_available() if cuda_available is None else cuda_available
    return [torch.device("cpu")] + ([torch.device("cuda")] if cuda else [])


def choose(costs: dict[torch.device, float]) -> tuple[torch.device, str]:
    """The device of the lowest finite cost, and a one-line reason with every cost."""
    if len(costs) == 1:
        (only,) = costs
        return only, f"{only.type}: the only device available"
    finite = {d: c for d, c in costs.items() if math.isfinite(c)}
    if not finite:
        raise ValueError("device=auto: no device could run one update of this configuration")
    best = min(finite, key=finite.get)
    listed = ", ".join(f"{d.type} {_seconds(c)}" for d, c in costs.items())
    return best, f"{best.type}: least time per update of this run's optimizer and batch size ({listed})"


def place(cost_of: Callable[[torch.device], float], cuda_available: bool | None = None) -> Placement:
    """Measure ``cost_of(device)`` (seconds per update; inf where it cannot run) on each candidate
    device and choose. With a single candidate nothing is measured."""
    t0 = time.perf_counter()
    devices = candidates(cuda_available)
    costs = {d: (cost_of(d) if len(devices) > 1 else math.nan) for d in devices}
    device, reason = choose(costs)
    return Placement(device, reason, {d.type: c for d, c in costs.items()}, time.perf_counter() - t0)


def resumed(state: dict, cuda_available: bool | None = None) -> Placement:
    """A resumed ``auto`` run stays on the device it started on (its checkpoint says which): a
    run that changed device halfway would not be one run."""
    cuda = torch.cuda.is_available() if cuda_available is None else cuda_available
    if state.get("cuda_rng") is not None:
        if not cuda:
            raise ValueError("device=auto: this run started on a GPU and no CUDA device is available to resume it")
        return Placement(torch.device("cuda"), "cuda: the device this run started on")
    return Placement(torch.device("cpu"), "cpu: the device this run started on")


def _seconds(cost: float) -> str:
    if not math.isfinite(cost):
        return "cannot run"
    return f"{cost:.3g} s"
