"""The training loop: mini-batch updates under a budget, evaluations, the run file.

Clock semantics (as in the paper, appendix B): ``wall_time`` is the training clock. It
starts at the first update, once the data set exists, the solvers are compiled
(``warmup.py``: numba's compile or cache load, recorded apart as ``/env`` ``warmup_s``) and
the network and optimizer are built and checked; the first (slow) updates count, and so
does any framework warm-up inside them. Evaluations of the test loss, checkpoints and the
creation of the run file are excluded. A resumed run continues the clock of its checkpoint.

Reliability (see also ``checkpoint.py`` and ``runfile/writer.py``):

* Before the run file exists: the checks that need the network (``init_from`` weights
  that fit it, a checkpoint that fits it and its optimizer, the GN/HIG memory guard) raise
  ``ConfigError``; nothing is written.
* Divergence: a non-finite loss, gradient, Jacobian or update direction, a failed
  inversion (``UpdateResult.finite`` is False), a linear-algebra error, or a non-finite
  test loss ends the run as ``diverged`` with the step and reason; everything logged so
  far stays, and the run returns normally (exit code 0: a sweep goes on).
* SIGINT/SIGTERM: the first one stops the run after the current update: pending rows are
  written, a checkpoint is saved, the file is closed with status ``interrupted``. A second
  one stops it at once (the last checkpoint stays valid). Further signals are ignored
  while the file is being closed.
* ``checkpoint_every`` (seconds of training clock; null: off): periodic checkpoints, so a
  run killed with SIGKILL loses at most that much work; ``resume=...`` continues it.
  A checkpoint carries its run file's ``run_id``; resume refuses one of another run.
* Any other failure, including one while the file is being closed (final weights, a full
  disk, the file deleted under the run: ``RunFileFault``), closes the file as ``failed``
  and re-raises; rows not yet written are dropped only after a file-system fault.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch._dynamo  # noqa: F401  torch.optim imports it lazily on the first optimizer (3-4 s here):

# import it up front, so that no launcher's first run pays it inside the training clock.
from omegaconf import OmegaConf

from higbench.config import RunConfig
from higbench.dtypes import DTYPES
from higbench.errors import ConfigError, MemoryRefusal, show
from higbench.optim import memory_guard
from higbench.optim.contract import uses_jacobian
from higbench.optim.structured import mlp_factor_values
from higbench.problems.base import LATER_DRAWS, Batch, Problem, build_problem
from higbench.runfile.reader import RunTables
from higbench.runfile.writer import RunFileWriter
from higbench.runner import checkpoint, placement
from higbench.runner.environment import CpuUse, MemoryMonitor, environment, resolve_device
from higbench.runner.plan import Plan
from higbench.runner.progress import Progress, announce, start_text
from higbench.runner.sinks import (
    ProgressSink,
    RunFileSink,
    Sinks,
    build_side_sinks,
    check_side_sinks,
    spectrum_columns,
    spectrum_quantiles,
)
from higbench.runner.threads import fit_to_work, resolve_threads
from higbench.runner.updates import Update, build_update
from higbench.runner.warmup import warm_up

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
DRIVER_ENV = "HIGBENCH_DRIVER_PID"  # set by a driver (league, figures) for the sweeps it launches: their parent


class Interrupted(Exception):
    """The run was asked to stop (SIGINT/SIGTERM)."""


@dataclass
class RunSummary:
    status: str
    steps: int
    wall_time: float
    final_test_loss: float
    path: Path
    reason: str = ""
    initial_test_loss: float = math.nan  # the test loss at step 0
    tables: RunTables | None = None  # what its summary reads of the file, kept as it was closed


class TrainingClock:
    """Wall clock that can be paused (evaluations do not count), starting at ``offset``."""

    def __init__(self, offset: float = 0.0):
        self._start = time.perf_counter() - offset
        self._paused_total = 0.0
        self._paused_at: float | None = None

    def pause(self) -> None:
        if self._paused_at is None:
            self._paused_at = time.perf_counter()

    def resume(self) -> None:
        if self._paused_at is not None:
            self._paused_total += time.perf_counter() - self._paused_at
            self._paused_at = None

    def __call__(self) -> float:
        now = self._paused_at if self._paused_at is not None else time.perf_counter()
        return now - self._start - self._paused_total


class StopSignals:
    """SIGINT/SIGTERM handlers: the first asks the loop to stop, the second stops it now.

    ``parent``: a sweep worker's launcher; once it is gone (killed alone, its workers
    re-parented), the run stops as if sent SIGTERM: interrupted, checkpointed, resumable.
    """

    def __init__(self, parent: int | None = None):
        self.signum: int | None = None
        self.parent = parent
        self._previous: dict[int, object] = {}

    def _handler(self, signum, frame):
        if self.signum is None:
            self.signum = signum
            return
        raise Interrupted(f"{signal.Signals(signum).name} (second signal, stopped mid-update)")

    def install(self) -> StopSignals:
        if threading.current_thread() is threading.main_thread():
            for s in STOP_SIGNALS:
                self._previous[s] = signal.signal(s, self._handler)
        return self

    def ignore(self) -> None:
        """While the file is closed: no signal may cut that short."""
        if self._previous:
            for s in STOP_SIGNALS:
                signal.signal(s, signal.SIG_IGN)

    def restore(self) -> None:
        for s, handler in self._previous.items():
            signal.signal(s, handler)
        self._previous.clear()

    def check(self) -> None:
        if self.signum is None and self.parent is not None and os.getppid() != self.parent:
            self.signum = signal.SIGTERM  # the sweep that launched this job is gone
        if self.signum is not None:
            raise Interrupted(signal.Signals(self.signum).name)


@torch.no_grad()
def evaluate_samples(problem: Problem, model: torch.nn.Module, batch: Batch, chunk: int = 1024) -> tuple[dict, np.ndarray]:
    """Mean test loss and extra metrics over ``batch`` (in chunks to bound memory), and the test
    loss of each sample (float64: the values whose mean is ``test_loss``)."""
    sums: dict[str, float] = {}
    losses = []
    for start in range(0, len(batch), chunk):
        part = batch[start : start + chunk]
        y = problem.outputs(model, part)
        values = {"test_loss": problem.loss(y, part.targets)}
        values.update({f"test_{k}": v for k, v in problem.metrics(y, part).items()})
        losses.append(values["test_loss"].double().cpu().numpy())
        for k, v in values.items():
            sums[k] = sums.get(k, 0.0) + float(v.double().sum())
    return {k: v / len(batch) for k, v in sums.items()}, np.concatenate(losses)


def evaluate(problem: Problem, model: torch.nn.Module, batch: Batch, chunk: int = 1024) -> dict[str, float]:
    """Mean test loss and extra metrics over ``batch``."""
    return evaluate_samples(problem, model, batch, chunk)[0]


# -- the build, and the checks that need the network; before the run file exists ------------


def check_initial_weights(model: torch.nn.Module, weights, path: str) -> None:
    """``init_from``: the run's weights (read by the plan) fit this network; ConfigError otherwise."""
    state = model.state_dict()
    if set(weights) != set(state) or any(tuple(weights[k].shape) != tuple(state[k].shape) for k in state):
        theirs = {k: tuple(v.shape) for k, v in weights.items()}
        ours = {k: tuple(v.shape) for k, v in state.items()}
        raise ConfigError("init_from", path, f"network does not match (run has {theirs}, this config builds {ours})")


def build(plan: Plan, problem: Problem) -> tuple[torch.nn.Module, Update]:
    """The network and its optimizer; a network or arguments they refuse become ConfigError."""
    try:
        check_network_size(plan, problem)
        model = problem.build_model()
        return model, build_update(problem, model, plan.optimizer)
    except ConfigError:
        raise
    except (ValueError, TypeError) as exc:
        raise ConfigError("config", "?", f"refused by the problem or optimizer: {exc}") from None
    except (MemoryError, RuntimeError) as exc:  # torch's allocator: a network far too large
        if not isinstance(exc, MemoryError) and "allocat" not in str(exc):
            raise
        first = " ".join(str(exc).split())[:200]
        raise MemoryRefusal(*_network_key(plan), f"the network does not fit in memory ({first})") from None


def _network_key(plan: Plan) -> tuple[str, str]:
    """The key and value a refusal of the network's size names: its hidden sizes, where it has them."""
    if "hidden" in plan.problem:
        return "problem.hidden", show(OmegaConf.to_container(plan.problem)["hidden"])
    return "problem", show("?")


SMALL_NETWORK_BYTES = 64 << 20  # below this a network is not what exhausts memory


def check_network_size(plan: Plan, problem: Problem) -> None:
    """The network, built on the meta device (no memory), fits in the memory there is. torch's
    allocator over-commits: a network far too large is otherwise killed by the kernel mid-way."""
    try:
        with torch.device("meta"):
            meta = problem.make_model()
    except Exception:  # noqa: BLE001 - one the meta device cannot build: the real build says what is wrong
        return
    n = sum(t.numel() for t in [*meta.parameters(), *meta.buffers()])
    need = 4 * n * DTYPES[plan.run.dtype].itemsize  # weights, gradients and an optimizer's two moments
    if need < SMALL_NETWORK_BYTES:  # comes from memory the process holds; the step's own guard sizes the rest
        return
    available, where = memory_guard.available_bytes(str(problem.device))
    if need > available:
        need_mb, have_mb = memory_guard.mb(need), memory_guard.mb(available)
        why = f"{need_mb} for {n:,} parameters (weights, gradients, optimizer state), {have_mb} is {where}"
        raise MemoryRefusal(*_network_key(plan), f"the network does not fit in memory ({why})")


def check_memory(plan: Plan, problem: Problem, model: torch.nn.Module, update) -> memory_guard.Estimate | None:
    """GN/HIG only: refuse a batch size whose Jacobian/inversion step cannot fit in memory."""
    if not uses_jacobian(update.optimizer):  # only the Jacobian-power family builds J (optim.contract)
        return None
    with torch.no_grad():
        y = problem.outputs(model, problem.test_set()[:1])
    output_size = int(y[0].numel())
    n_params = sum(p.numel() for p in model.parameters() if p.requires_grad)
    opt = update.optimizer
    return memory_guard.check(
        plan.run.batch_size,
        output_size,
        n_params,
        dtype=plan.run.dtype,
        solver=opt.group["solver"],  # resolved per batch size by the optimizer's rule (tau, truncation)
        tau=opt.group["tau"],
        truncation=opt.group["truncation"],
        precision=str(opt.group["precision"]),
        device=str(problem.device),
        limit_mb=plan.run.memory_limit_mb,
        jacobian="structured" if getattr(update, "structured", False) else "naive",
        krylov_steps=opt.group.get("krylov_steps", 200),
        factor_values=mlp_factor_values(model),
    )


def check_data_memory(plan: Plan, problem: Problem) -> None:
    """The validation and fresh test sets (drawn when first asked for, after this) fit in memory."""
    sizes = {f"problem.{key}": int(plan.problem[key] or 0) for key in LATER_DRAWS}
    memory_guard.check_samples(
        {k: n for k, n in sizes.items() if n}, problem.sample_bytes(), str(problem.device), plan.run.memory_limit_mb
    )


def _setup(plan: Plan, device: torch.device | None = None):
    run = plan.run
    device = resolve_device(run.device) if device is None else device
    threads = resolve_threads(run.threads)
    if threads:
        torch.set_num_threads(threads)
    torch.manual_seed(run.seed)
    problem = build_problem(plan.problem, dtype=DTYPES[run.dtype], device=device, seed=run.seed)
    return device, problem


def _update_cost(plan: Plan, device: torch.device) -> float:
    """Seconds of one update of this run's optimizer and batch size on ``device`` (the least of
    ``placement.TIMED_UPDATES`` after one untimed update; inf if it cannot fit in memory there).
    Throwaway problem, network and optimizer; the caller's random streams are left as they were."""
    threads = torch.get_num_threads()
    with torch.random.fork_rng(devices=[device] if device.type == "cuda" else []):
        try:
            _device, problem = _setup(plan, device=device)
            model, update = build(plan, problem)
            warm_up(problem, model, jacobian=uses_jacobian(plan.optimizer.cls))
            estimate = check_memory(plan, problem, model, update)
        except ConfigError:  # too large for this device's memory
            return math.inf
        if plan.run.threads == "auto" and estimate is not None:
            torch.set_num_threads(fit_to_work(torch.get_num_threads(), estimate.work_rows))
        generator = torch.Generator().manual_seed(plan.run.seed)
        batches = problem.epoch(plan.run.batch_size, generator)
        seconds = []
        for _ in range(1 + placement.TIMED_UPDATES):
            batch = next(batches, None) or next(problem.epoch(plan.run.batch_size, generator))
            t0 = time.perf_counter()
            update(batch)  # synchronizes a GPU before returning
            seconds.append(time.perf_counter() - t0)
    torch.set_num_threads(threads)
    return min(seconds[1:])


def choose_placement(plan: Plan) -> placement.Placement | None:
    """``device=auto``: the measured choice (a resumed run keeps its device); else None."""
    if plan.run.device != "auto":
        return None
    if plan.checkpoint is not None:
        return placement.resumed(plan.checkpoint)
    return placement.place(lambda device: _update_cost(plan, device))


def check_checkpoint(plan: Plan, problem: Problem, model: torch.nn.Module, update) -> None:
    """A resumed run's checkpoint against the network and optimizer its stored config builds
    (``checkpoint.check_fits``); ConfigError on ``resume`` when any part of it does not fit."""
    train_set = getattr(problem, "train", None)
    per_epoch = len(train_set) // plan.run.batch_size if train_set is not None else None
    checkpoint.check_fits(plan.checkpoint, model, update.optimizer, per_epoch, plan.run_path)


def check_sinks(plan: Plan) -> None:
    """The side sinks the plan names import as sinks, and TensorBoard's extra is installed."""
    check_side_sinks(plan.sinks)
    if "tensorboard" in plan.sinks:
        from higbench.runner.tensorboard import summary_writer_class  # the optional extra, only when asked for

        summary_writer_class()


def check_build(plan: Plan) -> None:
    """A sweep's up-front check of one distinct network (``preflight.check_sweep``): build the
    problem, network and optimizer on the CPU and run the checks that need them, writing
    nothing, so that a bad job refuses the sweep before any job runs. (A single run does these
    checks once, in ``train``, on its own objects.)"""
    _device, problem = _setup(plan, device=torch.device("cpu"))
    model, update = build(plan, problem)
    if plan.initial_weights is not None:
        check_initial_weights(model, plan.initial_weights, plan.run.init_from)
    check_sinks(plan)
    if resolve_device(plan.run.device).type == "cpu":
        check_memory(plan, problem, model, update)
        check_data_memory(plan, problem)


# -- the loop --------------------------------------------------------------------------------


def _open_run_file(plan: Plan, env: dict) -> RunFileWriter:
    """A new run file, or the checkpoint's file reopened at the rows it recorded."""
    config_yaml = OmegaConf.to_yaml(OmegaConf.create(plan.task()), resolve=True)
    run_path, state, overrides = plan.run_path, plan.checkpoint, plan.overrides
    if state is None:
        meta = {"problem": plan.problem.name, "optimizer": plan.optimizer.name}
        return RunFileWriter(run_path, config_yaml=config_yaml, overrides=list(overrides), env=env, meta=meta)
    return RunFileWriter.reopen(
        run_path,
        rows=state["rows"],
        resume_info={
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "from_step": state["step"],
            "wall_time": state["wall_time"],
            "overrides": list(overrides),
        },
        config_yaml=config_yaml,
    )


class TrainingRun:
    """The state of one run between updates, and what happens at updates, evaluations and checkpoints."""

    def __init__(self, run: RunConfig, run_path, problem, model, update: Update, device, state, clock, file: RunFileSink, sinks):
        self.cfg, self.run_path, self.problem, self.model, self.update = run, run_path, problem, model, update
        self.device, self.clock, self.file, self.sinks = device, clock, file, sinks
        self.test = problem.test_set()
        self.val = problem.val_set()  # its loss is the curve val_loss (what tuning reads)
        self.memory = MemoryMonitor(device)
        self.cpu = CpuUse(torch.get_num_threads(), earlier=state.get("cpu_use") if state is not None else None)
        self.shuffle = torch.Generator().manual_seed(run.seed)
        self.budget_s = run.budget.seconds if run.budget.seconds is not None else math.inf
        self.max_updates = run.budget.max_updates if run.budget.max_updates is not None else math.inf
        self.by_updates = run.eval_unit == "updates"
        self.records_spectrum = uses_jacobian(update.optimizer)
        self.spectrum: dict = {}
        self.step, self.epoch, self.position = 0, 0, 0
        self.batch_losses: list[float] = []
        self.next_eval, self.last_eval_step = 0.0, -1
        self.epoch_iter = None
        self.epoch_start_rng = self.shuffle.get_state()
        self.resumed = state is not None
        self.initial_test_loss = math.nan
        self.test_losses: np.ndarray | None = None  # of the last evaluation, sample by sample (the file's /final)
        if state is not None:
            self._restore(state)
        self.last_ckpt = clock()

    def _restore(self, state: dict) -> None:
        curves = self.file.writer.f["curves"]
        if "test_loss" in curves and curves["test_loss"].shape[0]:
            self.initial_test_loss = float(curves["test_loss"][0])
        self.model.load_state_dict(state["model"])
        self.update.optimizer.load_state_dict(state["optimizer"])
        self.step, self.epoch, self.position = state["step"], state["epoch"], state["position"]
        self.next_eval, self.batch_losses = state["next_eval"], list(state["batch_losses"])
        self.last_eval_step = state["last_eval_step"]
        self.memory.peak_rss_mb = max(self.memory.peak_rss_mb, state.get("peak_rss_mb", 0.0))
        # Replay the epoch's first `position` batches: the data order is the original one.
        self.epoch_start_rng = state["shuffle_epoch_start"]
        self.shuffle.set_state(self.epoch_start_rng)
        self.epoch_iter = iter(self.problem.epoch(self.cfg.batch_size, self.shuffle))
        for _ in range(self.position):
            next(self.epoch_iter)
        torch.set_rng_state(state["torch_rng"])
        if self.device.type == "cuda" and state.get("cuda_rng") is not None:
            torch.cuda.set_rng_state(state["cuda_rng"], self.device)

    def out_of_budget(self) -> bool:
        return self.step >= self.max_updates or self.clock() >= self.budget_s

    def record_evaluation(self) -> float:
        """Test loss and logs at this step (clock paused); every sink flushed."""
        self.clock.pause()
        self.last_eval_step = self.step
        self.model.eval()
        metrics, self.test_losses = evaluate_samples(self.problem, self.model, self.test)
        if self.val is not None:
            metrics["val_loss"] = evaluate(self.problem, self.model, self.val)["test_loss"]
        self.model.train()
        train_loss = float(np.mean(self.batch_losses)) if self.batch_losses else math.nan
        self.batch_losses.clear()
        row = {"step": self.step, "epoch": self.epoch, "wall_time": self.clock(), "train_loss": train_loss}
        self.sinks.on_eval({**row, "rss_mb": self.memory.sample(), **metrics})
        for name, value in self.problem.eval_logs(self.model).items():
            self.sinks.on_log(name, value)
        if self.records_spectrum:  # the whole spectrum of the last update, as quantiles
            self.sinks.on_log("sv_quantiles", spectrum_quantiles(self.spectrum))
        self.sinks.flush()
        self.clock.resume()
        return metrics["test_loss"]

    def save_checkpoint(self) -> None:
        self.clock.pause()
        self.sinks.flush()  # the file holds at least the rows the checkpoint records
        writer = self.file.writer
        checkpoint.save(
            self.run_path,
            {
                "step": self.step,
                "epoch": self.epoch,
                "position": self.position,
                "wall_time": self.clock(),
                "next_eval": self.next_eval,
                "last_eval_step": self.last_eval_step,
                "batch_losses": list(self.batch_losses),
                "model": {k: v.detach().cpu().clone() for k, v in self.model.state_dict().items()},
                "optimizer": self.update.optimizer.state_dict(),
                "shuffle_epoch_start": self.epoch_start_rng,
                "torch_rng": torch.get_rng_state(),
                "cuda_rng": torch.cuda.get_rng_state(self.device) if self.device.type == "cuda" else None,
                "rows": writer.row_counts(),
                "peak_rss_mb": self.memory.peak_rss_mb,
                "cpu_use": self.cpu.totals(),  # a resumed run's CPU share counts this segment too
                "run_id": writer.run_id,
            },
        )
        self.last_ckpt = self.clock()
        self.clock.resume()

    def next_batch(self) -> Batch:
        while True:
            if self.epoch_iter is None:
                self.epoch_start_rng = self.shuffle.get_state()
                self.epoch_iter = iter(self.problem.epoch(self.cfg.batch_size, self.shuffle))
                self.position = 0
            batch = next(self.epoch_iter, None)
            if batch is not None:
                self.position += 1
                return batch
            if self.position == 0:
                raise ConfigError("batch_size", self.cfg.batch_size, "the problem's epoch yields no batch of this size")
            self.epoch, self.epoch_iter = self.epoch + 1, None

    def take_update(self) -> str:
        """One update; the reason it diverged, or empty."""
        try:
            result = self.update(self.next_batch())
        except torch.linalg.LinAlgError as exc:  # a solver or inversion that failed outright
            self.step += 1
            self.spectrum = {}  # this step's evaluation row has no spectrum, not the previous step's
            return f"linear algebra failed: {exc}"
        self.step += 1
        # The spectrum of *this* update, also of one that diverged: the evaluation at its step
        # logs it (empty: NaN quantiles where it stopped before an inversion).
        self.spectrum = result.spectrum
        if not result.finite or not math.isfinite(result.loss):
            return result.reason or "non-finite loss"
        self.batch_losses.append(result.loss)
        t = result.timings
        row = {"step": self.step, "wall_time": self.clock(), "loss": result.loss, "update_s": sum(t.values()), **t}
        row.update(result.metrics)  # an optimizer's own values (SIP: proxy_loss)
        if self.records_spectrum:
            row.update(spectrum_columns(result.spectrum))
        self.sinks.on_update(row)
        self.memory.sample()
        return ""

    def loop(self, signals: StopSignals) -> tuple[str, str, float]:
        """Updates until the budget, a divergence or a stop signal; (status, reason, last test loss)."""
        final_test = math.nan
        if self.resumed:  # its last evaluation: a resume with nothing left to do evaluates nothing
            final_test = self.file.writer.last_value("curves", "test_loss")
        else:
            final_test = self.initial_test_loss = self.record_evaluation()
            self.next_eval = self.cfg.eval_every
        status, reason = "completed", ""
        while not self.out_of_budget():
            signals.check()
            reason = self.take_update()
            if reason:
                status = "diverged"
                break
            if self.out_of_budget():
                break
            if (self.step if self.by_updates else self.clock()) >= self.next_eval:
                final_test = self.record_evaluation()
                self.next_eval += self.cfg.eval_every
                if not math.isfinite(final_test):
                    status, reason = "diverged", "non-finite test loss"
                    break
            ckpt_every = self.cfg.checkpoint_every
            if ckpt_every is not None and self.clock() - self.last_ckpt >= ckpt_every:
                self.save_checkpoint()
        signals.ignore()
        if self.step != self.last_eval_step:  # one curve row per step: no second row after a diverged evaluation
            final_test = self.record_evaluation()
        if status == "completed" and not math.isfinite(final_test):
            status, reason = "diverged", "non-finite test loss"
        return status, reason, final_test

    def finish(self, status: str, reason: str) -> None:
        """Final weights and attributes, then the file closed with its status."""
        writer = self.file.writer
        writer.set_attrs("memory", self.memory.summary())
        writer.set_attrs("env", self.cpu.summary())  # what the run had of its cores
        writer.write_weights({k: v.detach().cpu().numpy() for k, v in self.model.state_dict().items()}, self.step)
        writer.f.attrs["steps"] = self.step
        writer.f.attrs["wall_time"] = self.clock()
        # The final evaluation's test loss sample by sample (kept by ``record_evaluation``): a few
        # samples can carry most of a mean (the oscillator's heavy tail), and the median or a
        # percentile are then read from the file without training again.
        if status in ("completed", "diverged"):  # an interrupted run has no final evaluation yet
            self.model.eval()
            if self.test_losses is None:  # resumed with nothing left to do: its last evaluation was another process's
                self.test_losses = evaluate_samples(self.problem, self.model, self.test)[1]
            final = {"test_losses": self.test_losses}
            fresh = self.problem.fresh_test_set()  # problem.fresh_test_size: a large second draw, once
            if fresh is not None:
                final["fresh_test_losses"] = evaluate_samples(self.problem, self.model, fresh)[1]
            writer.write_final(final, self.step)
        writer.check_file()
        self.sinks.close(status, reason, self.step)


def _run(run: TrainingRun, signals: StopSignals) -> tuple[str, str, float]:
    """The loop with the reliability rules of the module docstring around it."""
    final_test = math.nan
    try:
        status, reason, final_test = run.loop(signals)
    except Interrupted as exc:
        signals.ignore()
        status, reason = "interrupted", str(exc)
        try:
            if signals.signum is not None and "second signal" not in reason:
                run.save_checkpoint()  # a clean stop between updates: resumable from exactly here
            else:
                run.file.write_pending()
        except BaseException as fault:  # the disk or file failed on the way out
            _fail(run, fault, signals)
            raise
    except BaseException as exc:
        signals.ignore()
        _fail(run, exc, signals)
        raise
    try:
        run.finish(status, reason)
    except BaseException as exc:  # a failure while closing: the file says failed, not running
        signals.ignore()
        _fail(run, exc, signals, write_pending=False)
        raise
    return status, reason, final_test


def _fail(run: TrainingRun, exc: BaseException, signals: StopSignals, write_pending: bool = True) -> None:
    run.file.close_failed(exc, run.step, write_pending)
    for sink in run.sinks.sinks:
        if sink is not run.file:
            with contextlib.suppress(Exception):  # a side sink's failure must not hide the run's
                sink.close("failed", str(exc), run.step)
    signals.restore()


def train(plan: Plan) -> RunSummary:
    """Run one experiment as planned (``higbench.runner.plan``); write its run file.

    The problem, the network and the optimizer are built once, here; the plan's inputs are
    checked against them (``init_from`` weights, a checkpoint) and the memory guard runs, all
    before the run file is created or reopened: a refusal (ConfigError) writes nothing.
    ``Plan.for_run(cfg, run_path)`` makes the plan of a config in code.
    """
    cfg, run_path, state = plan.run, plan.run_path, plan.checkpoint
    placed = choose_placement(plan)
    device, problem = _setup(plan, device=placed.device if placed else None)
    model, update = build(plan, problem)
    warmup_s = warm_up(problem, model, jacobian=uses_jacobian(plan.optimizer.cls))  # numba compiles: not training
    if plan.initial_weights is not None:
        check_initial_weights(model, plan.initial_weights, cfg.init_from)
        model.load_state_dict({k: torch.as_tensor(v) for k, v in plan.initial_weights.items()})
    if state is not None:  # all of it fits this network and optimizer, before the run file is touched
        check_checkpoint(plan, problem, model, update)
    estimate = check_memory(plan, problem, model, update)
    check_data_memory(plan, problem)
    if cfg.threads == "auto" and estimate is not None:  # a small eigen-solve loses from a second thread
        torch.set_num_threads(fit_to_work(torch.get_num_threads(), estimate.work_rows))
    check_sinks(plan)
    announce(cfg.progress, start_text(plan.start_config()))  # the checks passed: replaces "checking"

    clock = TrainingClock(offset=state["wall_time"] if state else 0.0)
    clock.pause()  # creating/reopening the file is not training
    extra = build_side_sinks(plan.sinks, run_path.parent)  # the sink group's and tensorboard=true's, beside the run file
    env = {**environment(device, plan.parallel_jobs), "warmup_s": warmup_s, **(placed.record() if placed else {})}
    file = RunFileSink(_open_run_file(plan, env))
    step = state["step"] if state else 0
    name = f"{plan.problem.name}/{plan.optimizer.name}"
    progress = Progress(cfg.progress, cfg.budget.seconds, start=clock(), name=name, max_updates=cfg.budget.max_updates, step=step)
    sinks = Sinks(file, ProgressSink(progress), side=extra)
    run = TrainingRun(cfg, run_path, problem, model, update, device, state, clock, file, sinks)
    clock.resume()
    signals = StopSignals(parent=plan.stop_with_parent).install()
    status, reason, final_test = _run(run, signals)
    if status in ("completed", "diverged"):
        checkpoint.remove(run_path)  # nothing left to resume
    signals.restore()
    tables = run.file.writer.final_tables
    return RunSummary(status, run.step, clock(), final_test, run_path, reason, run.initial_test_loss, tables)
