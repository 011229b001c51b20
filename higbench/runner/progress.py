"""What a run shows while it goes: a start line at once, then a bar (terminal) or lines (pipe).

On a terminal: one tqdm bar named after the run (``oscillator/hig``), moving at every update
(redrawn at most twice a second) with the training clock against the budget, tqdm's ETA,
and the last evaluation's train and test losses. Piped (a log, a sweep): one line per
evaluation with the same words. In a multirun every line starts with the job's label
(``[job 3]``), so the lines of parallel jobs can be told apart; each line is written with
one ``write`` call so parallel jobs do not share a line.
"""

from __future__ import annotations

import math
import sys
import time

REDRAW_S = 0.5  # a bar redraw at most this often: per-update redraws would cost time on tiny updates


def job_label() -> str:
    """``[job N] `` inside a Hydra multirun, else empty."""
    try:
        from hydra.core.hydra_config import HydraConfig
        from hydra.types import RunMode

        if HydraConfig.initialized() and HydraConfig.get().mode == RunMode.MULTIRUN:
            return f"[job {HydraConfig.get().job.num}] "
    except Exception:  # noqa: BLE001 - outside Hydra (library use, tests): no label
        pass
    return ""


def start_text(cfg) -> str:
    """The first line of a run: what it is, its batch size and its budget."""
    budget = [f"{cfg.budget.seconds:g} s" if cfg.budget.seconds is not None else None]
    budget.append(f"{cfg.budget.max_updates} updates" if cfg.budget.max_updates is not None else None)
    budget_text = " or ".join(b for b in budget if b) or "none"
    verb = "resuming" if cfg.get("resume") else "starting"
    return f"{cfg.problem.name}/{cfg.optimizer.name}: {verb}, batch size {cfg.batch_size}, budget {budget_text} (training clock)"


_transient = False  # a start line without newline on the terminal, to be replaced


def announce(enabled: bool, text: str, transient: bool = False) -> None:
    """A line before the (possibly slow) set-up, so the terminal is never silent.

    transient: only on a terminal, and replaced by whatever comes next (the real start line,
    or the one-line error of a refused config), so refused input still shows one line.
    """
    global _transient
    if not enabled:
        return
    if transient:
        if sys.stderr.isatty():
            sys.stderr.write(f"{job_label()}{text}")
            sys.stderr.flush()
            _transient = True
        return
    clear_transient()
    _line(f"{job_label()}{text}")


def clear_transient() -> None:
    global _transient
    if _transient:
        sys.stderr.write("\r\033[K")  # back to the line's start, erase it
        sys.stderr.flush()
        _transient = False


def _line(text: str) -> None:
    sys.stderr.write(text + "\n")  # one write: parallel jobs never share a line
    sys.stderr.flush()


def _fmt(value: float | None) -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.3e}"


class Progress:
    """tqdm on a terminal, one plain line per evaluation otherwise; nothing when disabled."""

    def __init__(
        self,
        enabled: bool,
        budget_s: float | None,
        start: float = 0.0,
        *,
        name: str = "",
        max_updates: int | None = None,
        step: int = 0,
    ):
        self.enabled = enabled
        self.tty = enabled and sys.stderr.isatty()
        self.label = job_label()
        self.name = name
        self.bar = None
        self.by_updates = budget_s is None and max_updates is not None
        self.train: float | None = None
        self.test: float | None = None
        self.step = step
        self._drawn = 0.0
        if self.tty:
            from tqdm import tqdm

            unit = "updates" if self.by_updates else "s"
            total = max_updates if self.by_updates else budget_s
            self.bar = tqdm(
                total=total,
                initial=step if self.by_updates else start,
                desc=f"{self.label}{name}",
                bar_format="{desc} {percentage:3.0f}%|{bar}| {n:.0f}/{total_fmt}" + unit + " [{elapsed}<{remaining}{postfix}]",
                file=sys.stderr,
                dynamic_ncols=True,
            )
            self._postfix()

    def _postfix(self) -> None:
        # Inside tqdm's brackets, after its ", ": "[00:04<00:12, step 53 train ... test ...]".
        self.bar.set_postfix_str(f"step {self.step} train {_fmt(self.train)} test {_fmt(self.test)}", refresh=False)

    def _move(self, step: int, wall: float) -> None:
        self.step = step
        if self.bar is not None:
            n = step if self.by_updates else wall
            self.bar.n = min(n, self.bar.total) if self.bar.total else n
            self._postfix()

    def tick(self, step: int, wall: float) -> None:
        """After an update: move the bar (redrawn at most every REDRAW_S)."""
        if self.bar is None:
            return
        now = time.monotonic()
        if now - self._drawn >= REDRAW_S:
            self._move(step, wall)
            self.bar.refresh()
            self._drawn = now

    def update(self, step: int, wall: float, train_loss: float, test_loss: float | None) -> None:
        """After an evaluation."""
        if not self.enabled:
            return
        self.train, self.test = train_loss, test_loss
        if self.bar is not None:
            self._move(step, wall)
            self.bar.refresh()
            self._drawn = time.monotonic()
        elif test_loss is not None:
            _line(f"{self.label}{self.name} step {step:7d}  t {wall:8.2f}s  train {_fmt(train_loss)}  test {_fmt(test_loss)}")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
