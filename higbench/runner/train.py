"""The training loop: mini-batch updates under a budget, evaluations, the run file.

Clock semantics (as in the paper, appendix B): ``wall_time`` is the training clock. It
starts once the data set exists, before the network and optimizer are built, so framework
warm-up and the first (slow) updates count; evaluations of the test loss are excluded.
"""

from __future__ import annotations

import math
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from higbench.problems.base import Batch, Problem, build_problem
from higbench.runfile.reader import load_weights
from higbench.runfile.writer import RunFileWriter
from higbench.runner.environment import MemoryMonitor, environment, resolve_device
from higbench.runner.updates import build_update

DTYPES = {"float32": torch.float32, "float64": torch.float64}


class Interrupted(Exception):
    """Raised by the SIGTERM handler so the loop can close the run file cleanly."""


@dataclass
class RunSummary:
    status: str
    steps: int
    wall_time: float
    final_test_loss: float
    path: Path
    reason: str = ""


class TrainingClock:
    """Wall clock that can be paused (evaluations do not count)."""

    def __init__(self):
        self._start = time.perf_counter()
        self._paused_total = 0.0
        self._paused_at: float | None = None

    def pause(self) -> None:
        self._paused_at = time.perf_counter()

    def resume(self) -> None:
        if self._paused_at is not None:
            self._paused_total += time.perf_counter() - self._paused_at
            self._paused_at = None

    def __call__(self) -> float:
        now = self._paused_at if self._paused_at is not None else time.perf_counter()
        return now - self._start - self._paused_total


@torch.no_grad()
def evaluate(problem: Problem, model: torch.nn.Module, batch: Batch, chunk: int = 1024) -> dict[str, float]:
    """Mean test loss and extra metrics over ``batch`` (in chunks to bound memory)."""
    sums: dict[str, float] = {}
    for start in range(0, len(batch), chunk):
        part = batch[start : start + chunk]
        y = problem.outputs(model, part)
        values = {"test_loss": problem.loss(y, part.targets)}
        values.update({f"test_{k}": v for k, v in problem.metrics(y, part).items()})
        for k, v in values.items():
            sums[k] = sums.get(k, 0.0) + float(v.double().sum())
    return {k: v / len(batch) for k, v in sums.items()}


def load_initial_weights(model: torch.nn.Module, path: str, problem_name: str) -> None:
    """Start from another run's final weights; refuse if the networks do not match."""
    from higbench.runfile.reader import load_run

    meta, _ = load_run(path)
    other = meta["config"].get("problem", {})
    if other.get("name") != problem_name:
        raise ValueError(f"init_from={path}: run is of problem {other.get('name')!r}, not {problem_name!r}")
    weights = load_weights(path)
    state = model.state_dict()
    if set(weights) != set(state) or any(tuple(weights[k].shape) != tuple(state[k].shape) for k in state):
        theirs = {k: tuple(v.shape) for k, v in weights.items()}
        ours = {k: tuple(v.shape) for k, v in state.items()}
        raise ValueError(f"init_from={path}: network does not match (run has {theirs}, this model {ours})")
    model.load_state_dict({k: torch.as_tensor(v) for k, v in weights.items()})


class Progress:
    """tqdm on a terminal, one plain line per evaluation otherwise."""

    def __init__(self, enabled: bool, budget_s: float | None):
        self.tty = enabled and sys.stderr.isatty()
        self.bar = None
        if self.tty:
            from tqdm import tqdm

            self.bar = tqdm(total=budget_s, unit="s", bar_format="{l_bar}{bar}| {n:.0f}/{total_fmt}s {postfix}", file=sys.stderr)
        self.enabled = enabled

    def update(self, step: int, wall: float, train_loss: float, test_loss: float | None) -> None:
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.n = min(wall, self.bar.total or wall)
            self.bar.set_postfix_str(f"step {step} loss {train_loss:.3e}" + (f" test {test_loss:.3e}" if test_loss is not None else ""))
        elif test_loss is not None:
            print(f"step {step:7d}  t {wall:8.2f}s  train {train_loss:.4e}  test {test_loss:.4e}", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def train(cfg: DictConfig, run_path: Path, overrides: list[str] | None = None) -> RunSummary:
    """Run one experiment described by a validated config; write ``run_path``."""
    device = resolve_device(cfg.device)
    dtype = DTYPES[cfg.dtype]
    if cfg.get("threads"):
        torch.set_num_threads(int(cfg.threads))
    torch.manual_seed(cfg.seed)
    problem = build_problem(cfg.problem, dtype=dtype, device=device, seed=cfg.seed)
    test = problem.test_set()

    writer = RunFileWriter(
        run_path,
        config_yaml=OmegaConf.to_yaml(cfg, resolve=True),
        overrides=overrides or [],
        env=environment(device),
        meta={"problem": cfg.problem.name, "optimizer": cfg.optimizer.name},
    )
    memory = MemoryMonitor(device)
    clock = TrainingClock()
    budget_s = cfg.budget.seconds if cfg.budget.seconds is not None else math.inf
    max_updates = cfg.budget.max_updates if cfg.budget.max_updates is not None else math.inf
    by_updates = cfg.get("eval_unit", "seconds") == "updates"

    model = problem.build_model()
    if cfg.get("init_from"):
        load_initial_weights(model, cfg.init_from, cfg.problem.name)
    update = build_update(problem, model, cfg.optimizer)
    shuffle = torch.Generator().manual_seed(cfg.seed)
    progress = Progress(cfg.get("progress", True), cfg.budget.seconds)

    step, epoch = 0, 0
    batch_losses: list[float] = []
    pending: dict[str, list[float]] = {k: [] for k in ("step", "wall_time", "loss", "jacobian_s", "inversion_s", "apply_s", "update_s")}
    next_eval = 0.0
    status, reason = "completed", ""

    def record_evaluation() -> float:
        clock.pause()
        model.eval()
        metrics = evaluate(problem, model, test)
        model.train()
        train_loss = float(np.mean(batch_losses)) if batch_losses else math.nan
        batch_losses.clear()
        row = {"step": step, "epoch": epoch, "wall_time": clock(), "train_loss": train_loss, "rss_mb": memory.sample(), **metrics}
        writer.append_row("curves", row)
        for name, value in problem.eval_logs(model).items():
            writer.append_row("logs", {name: value})
        writer.append_rows("updates", pending)
        for values in pending.values():
            values.clear()
        writer.flush()
        progress.update(step, row["wall_time"], train_loss, metrics["test_loss"])
        clock.resume()
        return metrics["test_loss"]

    def on_sigterm(signum, frame):
        raise Interrupted(f"signal {signum}")

    previous_handler = signal.signal(signal.SIGTERM, on_sigterm) if _main_thread() else None
    final_test = math.nan
    try:
        final_test = record_evaluation()
        next_eval = cfg.eval_every
        done = step >= max_updates or clock() >= budget_s
        while not done:
            for batch in problem.epoch(cfg.batch_size, shuffle):
                result = update(batch)
                step += 1
                if not result.finite or not math.isfinite(result.loss):
                    status, reason = "diverged", result.reason or "non-finite loss"
                    done = True
                    break
                batch_losses.append(result.loss)
                t = result.timings
                for k, v in (("step", step), ("wall_time", clock()), ("loss", result.loss), ("update_s", sum(t.values())), *t.items()):
                    pending[k].append(v)
                memory.sample()
                done = step >= max_updates or clock() >= budget_s
                if done:
                    break
                if (step if by_updates else clock()) >= next_eval:
                    final_test = record_evaluation()
                    next_eval += cfg.eval_every
                    if not math.isfinite(final_test):
                        status, reason, done = "diverged", "non-finite test loss", True
                        break
            else:
                epoch += 1
        final_test = record_evaluation()
        if status == "completed" and not math.isfinite(final_test):
            status, reason = "diverged", "non-finite test loss"
    except (KeyboardInterrupt, Interrupted) as exc:
        status, reason = "interrupted", str(exc) or "KeyboardInterrupt"
        writer.append_rows("updates", pending)
    except BaseException as exc:
        writer.append_rows("updates", pending)
        writer.close("failed", f"{type(exc).__name__}: {exc}", step)
        raise
    finally:
        progress.close()
        if previous_handler is not None:
            signal.signal(signal.SIGTERM, previous_handler)
    writer.set_attrs("memory", memory.summary())
    writer.write_weights({k: v.detach().cpu().numpy() for k, v in model.state_dict().items()}, step)
    writer.f.attrs["steps"] = step
    writer.f.attrs["wall_time"] = clock()
    writer.close(status, reason, step)
    return RunSummary(status, step, clock(), final_test, Path(run_path), reason)


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()
