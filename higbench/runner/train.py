"""The training loop: mini-batch updates under a budget, evaluations, the run file.

Clock semantics (as in the paper, appendix B): ``wall_time`` is the training clock. It
starts once the data set exists, before the network and optimizer are built, so framework
warm-up and the first (slow) updates count; evaluations of the test loss, checkpoints and
the creation of the run file are excluded. A resumed run continues the clock of its
checkpoint. (Through the CLI, the pre-flight check has already built the problem and an
optimizer on the CPU, so one-off Python imports are paid before the clock starts.)

Reliability (see also ``checkpoint.py`` and ``runfile/writer.py``):

* Before the run file exists: the checks that need the network (``init_from`` weights
  that fit it, the GN/HIG memory guard) raise ``ConfigError``; nothing is written.
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

import math
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch._dynamo  # noqa: F401  torch.optim imports it lazily on the first optimizer (3-4 s here):

# import it up front, so that no launcher's first run pays it inside the training clock.
from omegaconf import DictConfig, OmegaConf

from higbench.config import init_from_path
from higbench.errors import ConfigError
from higbench.problems.base import Batch, Problem, build_problem
from higbench.runfile.reader import load_weights
from higbench.runfile.writer import RunFileFault, RunFileWriter
from higbench.runner import checkpoint, memory_guard
from higbench.runner.environment import MemoryMonitor, environment, resolve_device
from higbench.runner.progress import Progress
from higbench.runner.threads import resolve_threads
from higbench.runner.updates import JacobianPowerUpdate, build_update

DTYPES = {"float32": torch.float32, "float64": torch.float64}
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_UPDATE_COLUMNS = ("step", "wall_time", "loss", "jacobian_s", "inversion_s", "apply_s", "update_s")


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
    """SIGINT/SIGTERM handlers: the first asks the loop to stop, the second stops it now."""

    def __init__(self):
        self.signum: int | None = None
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
        if self.signum is not None:
            raise Interrupted(signal.Signals(self.signum).name)


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


# -- checks that need the network; run before the run file exists ---------------------------


def check_init_from(model: torch.nn.Module, path: str, problem_name: str) -> dict[str, np.ndarray]:
    """The weights of run ``path`` if they fit ``model``; ConfigError otherwise."""
    from higbench.config import check_init_from_file

    check_init_from_file(path, problem_name)
    weights = load_weights(init_from_path(path))
    state = model.state_dict()
    if set(weights) != set(state) or any(tuple(weights[k].shape) != tuple(state[k].shape) for k in state):
        theirs = {k: tuple(v.shape) for k, v in weights.items()}
        ours = {k: tuple(v.shape) for k, v in state.items()}
        raise ConfigError("init_from", path, f"network does not match (run has {theirs}, this config builds {ours})")
    bad = sorted(k for k, v in weights.items() if not np.isfinite(v).all())
    if bad:
        raise ConfigError(
            "init_from", path, f"final weights hold NaN or inf ({', '.join(bad)}); a diverged run cannot start another"
        )
    return weights


def load_initial_weights(model: torch.nn.Module, path: str, problem_name: str) -> None:
    """Start from another run's final weights; refuse (ConfigError) if the networks differ."""
    weights = check_init_from(model, path, problem_name)
    model.load_state_dict({k: torch.as_tensor(v) for k, v in weights.items()})


def check_memory(cfg: DictConfig, problem: Problem, model: torch.nn.Module, update) -> memory_guard.Estimate | None:
    """GN/HIG only: refuse a batch size whose Jacobian/inversion step cannot fit in memory."""
    if not isinstance(update, JacobianPowerUpdate):
        return None
    with torch.no_grad():
        y = problem.outputs(model, problem.test_set()[:1])
    output_size = int(y[0].numel())
    n_params = sum(p.numel() for p in model.parameters() if p.requires_grad)
    opt = update.optimizer
    return memory_guard.check(
        int(cfg.batch_size),
        output_size,
        n_params,
        dtype=cfg.dtype,
        solver=opt.group["solver"],  # resolved per batch size by the optimizer's rule (tau, truncation)
        tau=opt.group["tau"],
        truncation=opt.group["truncation"],
        precision=str(opt.group["precision"]),
        device=str(problem.device),
        limit_mb=cfg.get("memory_limit_mb"),
        jacobian="structured" if getattr(update, "structured", False) else "naive",
    )


def _setup(cfg: DictConfig, device: torch.device | None = None):
    device = resolve_device(cfg.device) if device is None else device
    dtype = DTYPES[cfg.dtype]
    threads = resolve_threads(cfg.get("threads"))
    if threads:
        torch.set_num_threads(threads)
    torch.manual_seed(cfg.seed)
    problem = build_problem(cfg.problem, dtype=dtype, device=device, seed=cfg.seed)
    return device, problem


def preflight(cfg: DictConfig) -> None:
    """Build the problem and network once and run the checks that need them (no file written).

    Raises ConfigError for an ``init_from`` run whose weights do not fit this network and
    for a GN/HIG batch size that cannot fit in memory. Problems and optimizers refusing
    their arguments (ValueError) are reported as ConfigError too.

    Everything is built on the CPU, so no GPU context exists before the run's clock starts
    (CUDA start-up stays part of the measured warm-up); for a CUDA run the memory guard
    runs in ``train`` instead, on the device, before the run file is created. Python-level
    imports triggered here (the first torch.optim optimizer imports torch._dynamo) are then
    no longer inside the run's training clock.
    """
    target = resolve_device(cfg.device)
    try:
        _device, problem = _setup(cfg, device=torch.device("cpu"))
        model = problem.build_model()
        update = build_update(problem, model, cfg.optimizer)
    except ConfigError:
        raise
    except (ValueError, TypeError) as exc:
        raise ConfigError("config", "?", f"refused by the problem or optimizer: {exc}") from None
    if cfg.get("init_from"):
        check_init_from(model, cfg.init_from, cfg.problem.name)
    if target.type == "cpu":
        check_memory(cfg, problem, model, update)


# -- the loop --------------------------------------------------------------------------------


def _close_failed(writer: RunFileWriter, exc: BaseException, step: int, flush_pending=None) -> None:
    """Close the run file as ``failed``, whatever else goes wrong on the way.

    Pending rows are written if the file can still take them (not after a file-system
    fault: the file then keeps what its last flush holds).
    """
    if flush_pending is not None and not isinstance(exc, RunFileFault):
        try:
            flush_pending()
        except Exception:  # noqa: BLE001 - the original error is the one to report
            pass
    try:
        writer.close("failed", f"{type(exc).__name__}: {exc}", step)
    except Exception:  # noqa: BLE001
        pass


def train(cfg: DictConfig, run_path: Path, overrides: list[str] | None = None, *, resume: bool = False) -> RunSummary:
    """Run one experiment described by a validated config; write ``run_path``.

    resume: continue the run file ``run_path`` from its checkpoint (``cfg`` is then the
    run's stored config, see ``checkpoint.resume_config``) instead of creating it.
    """
    run_path = Path(run_path)
    name = f"{cfg.problem.name}/{cfg.optimizer.name}"
    state = checkpoint.load(run_path) if resume else None
    if state is not None:
        checkpoint.check_owner(state, run_path, str(run_path))  # never continue from another run's state
    device, problem = _setup(cfg)
    test = problem.test_set()

    clock = TrainingClock(offset=state["wall_time"] if state else 0.0)
    model = problem.build_model()
    if cfg.get("init_from") and not resume:
        load_initial_weights(model, cfg.init_from, cfg.problem.name)
    update = build_update(problem, model, cfg.optimizer)
    check_memory(cfg, problem, model, update)
    shuffle = torch.Generator().manual_seed(cfg.seed)

    clock.pause()  # creating/reopening the file is not training
    config_yaml = OmegaConf.to_yaml(cfg, resolve=True)
    if state is None:
        writer = RunFileWriter(
            run_path,
            config_yaml=config_yaml,
            overrides=overrides or [],
            env=environment(device),
            meta={"problem": cfg.problem.name, "optimizer": cfg.optimizer.name},
        )
    else:
        writer = RunFileWriter.reopen(
            run_path,
            rows=state["rows"],
            resume_info={
                "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                "from_step": state["step"],
                "wall_time": state["wall_time"],
                "overrides": list(overrides or []),
            },
            config_yaml=config_yaml,
        )
    memory = MemoryMonitor(device)
    budget_s = cfg.budget.seconds if cfg.budget.seconds is not None else math.inf
    max_updates = cfg.budget.max_updates if cfg.budget.max_updates is not None else math.inf
    by_updates = cfg.get("eval_unit", "seconds") == "updates"
    ckpt_every = cfg.get("checkpoint_every")

    step, epoch, position = 0, 0, 0
    batch_losses: list[float] = []
    pending: dict[str, list[float]] = {k: [] for k in _UPDATE_COLUMNS}
    next_eval = 0.0
    last_eval_step = -1
    epoch_iter = None
    epoch_start_rng = shuffle.get_state()
    if state is not None:
        model.load_state_dict(state["model"])
        update.optimizer.load_state_dict(state["optimizer"])
        step, epoch, position = state["step"], state["epoch"], state["position"]
        next_eval, batch_losses = state["next_eval"], list(state["batch_losses"])
        last_eval_step = state["last_eval_step"]
        memory.peak_rss_mb = max(memory.peak_rss_mb, state.get("peak_rss_mb", 0.0))
        # Replay the epoch's first `position` batches: the data order is the original one.
        epoch_start_rng = state["shuffle_epoch_start"]
        shuffle.set_state(epoch_start_rng)
        epoch_iter = iter(problem.epoch(cfg.batch_size, shuffle))
        for _ in range(position):
            next(epoch_iter)
        torch.set_rng_state(state["torch_rng"])
        if device.type == "cuda" and state.get("cuda_rng") is not None:
            torch.cuda.set_rng_state(state["cuda_rng"], device)
    progress = Progress(
        cfg.get("progress", True), cfg.budget.seconds, start=clock(), name=name, max_updates=cfg.budget.max_updates, step=step
    )
    last_ckpt = clock()
    clock.resume()
    status, reason = "completed", ""

    def flush_pending() -> None:
        rows = {k: list(v) for k, v in pending.items()}
        for values in pending.values():  # cleared first: a stop mid-write never writes them twice
            values.clear()
        writer.append_rows("updates", rows)

    def record_evaluation() -> float:
        nonlocal last_eval_step
        clock.pause()
        last_eval_step = step
        model.eval()
        metrics = evaluate(problem, model, test)
        model.train()
        train_loss = float(np.mean(batch_losses)) if batch_losses else math.nan
        batch_losses.clear()
        row = {"step": step, "epoch": epoch, "wall_time": clock(), "train_loss": train_loss, "rss_mb": memory.sample(), **metrics}
        writer.append_row("curves", row)
        for name, value in problem.eval_logs(model).items():
            writer.append_row("logs", {name: value})
        flush_pending()
        writer.flush()
        progress.update(step, row["wall_time"], train_loss, metrics["test_loss"])
        clock.resume()
        return metrics["test_loss"]

    def save_checkpoint() -> None:
        nonlocal last_ckpt
        clock.pause()
        flush_pending()
        writer.flush()  # the file holds at least the rows the checkpoint records
        checkpoint.save(
            run_path,
            {
                "step": step,
                "epoch": epoch,
                "position": position,
                "wall_time": clock(),
                "next_eval": next_eval,
                "last_eval_step": last_eval_step,
                "batch_losses": list(batch_losses),
                "model": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
                "optimizer": update.optimizer.state_dict(),
                "shuffle_epoch_start": epoch_start_rng,
                "torch_rng": torch.get_rng_state(),
                "cuda_rng": torch.cuda.get_rng_state(device) if device.type == "cuda" else None,
                "rows": writer.row_counts(),
                "peak_rss_mb": memory.peak_rss_mb,
                "run_id": writer.run_id,
            },
        )
        last_ckpt = clock()
        clock.resume()

    signals = StopSignals().install()
    final_test = math.nan
    if state is not None:  # its last evaluation: a resume with nothing left to do evaluates nothing
        final_test = writer.last_value("curves", "test_loss")
    try:
        if state is None:
            final_test = record_evaluation()
            next_eval = cfg.eval_every
        done = step >= max_updates or clock() >= budget_s
        while not done:
            signals.check()
            if epoch_iter is None:
                epoch_start_rng = shuffle.get_state()
                epoch_iter = iter(problem.epoch(cfg.batch_size, shuffle))
                position = 0
            batch = next(epoch_iter, None)
            if batch is None:
                if position == 0:
                    raise ConfigError("batch_size", cfg.batch_size, "the problem's epoch yields no batch of this size")
                epoch, epoch_iter = epoch + 1, None
                continue
            position += 1
            try:
                result = update(batch)
            except torch.linalg.LinAlgError as exc:  # a solver or inversion that failed outright
                step += 1
                status, reason = "diverged", f"linear algebra failed: {exc}"
                break
            step += 1
            if not result.finite or not math.isfinite(result.loss):
                status, reason = "diverged", result.reason or "non-finite loss"
                break
            batch_losses.append(result.loss)
            t = result.timings
            for k, v in (
                ("step", step),
                ("wall_time", clock()),
                ("loss", result.loss),
                ("update_s", sum(t.values())),
                *t.items(),
            ):
                pending[k].append(v)
            memory.sample()
            progress.tick(step, clock())
            if step >= max_updates or clock() >= budget_s:
                break
            if (step if by_updates else clock()) >= next_eval:
                final_test = record_evaluation()
                next_eval += cfg.eval_every
                if not math.isfinite(final_test):
                    status, reason = "diverged", "non-finite test loss"
                    break
            if ckpt_every is not None and clock() - last_ckpt >= ckpt_every:
                save_checkpoint()
        signals.ignore()
        if step != last_eval_step:  # one curve row per step: no second row after a diverged evaluation
            final_test = record_evaluation()
        if status == "completed" and not math.isfinite(final_test):
            status, reason = "diverged", "non-finite test loss"
    except Interrupted as exc:
        signals.ignore()
        status, reason = "interrupted", str(exc)
        try:
            if signals.signum is not None and "second signal" not in reason:
                save_checkpoint()  # a clean stop between updates: resumable from exactly here
            else:
                flush_pending()
        except BaseException as fault:  # the disk or file failed on the way out
            _close_failed(writer, fault, step, flush_pending)
            progress.close()
            signals.restore()
            raise
    except BaseException as exc:
        signals.ignore()
        _close_failed(writer, exc, step, flush_pending)
        progress.close()
        signals.restore()
        raise
    progress.close()
    try:
        writer.set_attrs("memory", memory.summary())
        writer.write_weights({k: v.detach().cpu().numpy() for k, v in model.state_dict().items()}, step)
        writer.f.attrs["steps"] = step
        writer.f.attrs["wall_time"] = clock()
        writer.check_file()
    except BaseException as exc:  # a failure while closing: the file says failed, not running
        signals.ignore()
        _close_failed(writer, exc, step)
        signals.restore()
        raise
    writer.close(status, reason, step)
    if status in ("completed", "diverged"):
        checkpoint.remove(run_path)  # nothing left to resume
    signals.restore()
    return RunSummary(status, step, clock(), final_test, run_path, reason)
