"""What a run shows while it goes: a start line at once, then a bar (terminal) or lines (pipe).

On a terminal: one tqdm bar named after the run (``oscillator/hig``), moving at every update
(redrawn at most twice a second) with the training clock against the budget in whole
seconds, the time left (the budget minus the clock: exact, never tqdm's rate guess, which
read ``13:53:29`` on the first frame), and the last evaluation's train and test losses. The
bar keeps at least ``MIN_BAR`` characters and the line fits the terminal: the step count and
then the losses' digits go first. Piped (a log, a sweep): the first evaluation, then one
line per tenth of the budget (``PIPE_LINES``), and the last one at the end. In a multirun every line starts with the job's label
(``[job 3]``), so the lines of parallel jobs can be told apart; each line is written with
one ``write`` call so parallel jobs do not share a line.
"""

from __future__ import annotations

import sys
import time

from higbench.display import fmt

REDRAW_S = 0.5  # a bar redraw at most this often: per-update redraws would cost time on tiny updates
MIN_BAR = 10  # characters of bar kept at any terminal width
PIPE_LINES = 10  # piped output: about this many lines per run (one per tenth of the budget)


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


def announce(enabled: bool, text: str, transient: bool = False) -> None:
    """A line before the (possibly slow) set-up, so the terminal is never silent.

    transient: only on a terminal, and replaced by whatever comes next (the real start line,
    or the one-line error of a refused config), so refused input still shows one line.
    """
    if not enabled:
        return
    if transient:
        if sys.stderr.isatty():
            sys.stderr.write(f"{job_label()}{text}")
            sys.stderr.flush()
        return
    clear_transient()
    _line(f"{job_label()}{text}")


def clear_transient() -> None:
    """Erase a transient line (nothing to remember: on a terminal, erasing the current line
    is harmless where the cursor already stands at the start of an empty one)."""
    if sys.stderr.isatty():
        sys.stderr.write("\r\033[K")  # back to the line's start, erase it
        sys.stderr.flush()


def _line(text: str) -> None:
    sys.stderr.write(text + "\n")  # one write: parallel jobs never share a line
    sys.stderr.flush()


def _clock(seconds: float) -> str:
    m, s = divmod(int(seconds + 0.5), 60)
    h, m = divmod(m, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m:02d}:{s:02d}"


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
        self.budget_s, self.max_updates = budget_s, max_updates
        self._next_line = 0.0  # piped: the fraction of the budget at which the next line is due
        self._unprinted: str | None = None
        if self.tty:
            from tqdm import tqdm

            unit = "updates" if self.by_updates else "s"
            total = max_updates if self.by_updates else budget_s
            self.bar = tqdm(
                total=total,
                initial=step if self.by_updates else start,
                desc=f"{self.label}{name}",
                bar_format="{desc} {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f}" + unit + " [{elapsed}{postfix}]",
                file=sys.stderr,
                dynamic_ncols=True,
            )
            self._postfix()

    def _remaining(self, wall: float) -> str:
        if not self.by_updates and self.budget_s is not None:
            left = max(0.0, self.budget_s - wall)
        elif self.max_updates and self.step > 0:
            left = (self.max_updates - self.step) * wall / self.step
        else:
            return "?"
        return _clock(left)

    def _postfix(self, wall: float = 0.0) -> None:
        # Inside the brackets: "[00:04, left 00:56, step 53, train ..., test ...]", shortened to fit.
        width = self.bar.ncols if self.bar.ncols else 80
        fixed = len(self.bar.desc) + len(" 100%||  [00:00, ]") + len(f"{self.bar.total:.0f}") * 2 + 7 + MIN_BAR
        left = self._remaining(wall)
        for text in (
            f"left {left}, step {self.step}, train {fmt(self.train, exponent=True)}, test {fmt(self.test, exponent=True)}",
            f"left {left}, train {fmt(self.train, 2, exponent=True)}, test {fmt(self.test, 2, exponent=True)}",
            f"left {left}, test {fmt(self.test, 2, exponent=True)}",
            f"left {left}",
        ):
            if fixed + len(text) <= width:
                break
        self.bar.set_postfix_str(text, refresh=False)

    def _move(self, step: int, wall: float) -> None:
        self.step = step
        if self.bar is not None:
            n = step if self.by_updates else wall
            self.bar.n = min(n, self.bar.total) if self.bar.total else n
            self._postfix(wall)

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
            self.step = step
            losses = f"train {fmt(train_loss, exponent=True)}  test {fmt(test_loss, exponent=True)}"
            text = f"{self.label}{self.name} step {step:7d}  t {wall:8.2f}s  {losses}"
            done = self._fraction(step, wall)
            if done is None or done >= self._next_line:
                _line(text)
                self._unprinted = None
                if done is not None:
                    self._next_line = (int(done * PIPE_LINES + 1e-9) + 1) / PIPE_LINES
            else:
                self._unprinted = text

    def _fraction(self, step: int, wall: float) -> float | None:
        """How much of the budget is used (None: no budget, every evaluation prints)."""
        if self.by_updates:
            return step / self.max_updates
        return wall / self.budget_s if self.budget_s else None

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        elif self._unprinted is not None:  # piped: the last evaluation always shows
            _line(self._unprinted)
            self._unprinted = None


def _span(seconds: float) -> str:
    """A coarse duration for a forecast: '40 s', '3 min', '2.5 h'."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 90 * 60:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def count_text(label: str, done: int, total: int, noun: str = "runs", seconds_left: float | None = None, failed: int = 0) -> str:
    """The one wording of work counted in pieces (figure runs, sweep jobs, league runs):
    ``[figures] 7 of 24 runs done (1 failed), about 3 min left``."""
    text = f"[{label}] {done} of {total} {noun} done"
    if failed:
        text += f" ({failed} failed)"
    if seconds_left is not None and done < total:
        text += f", about {_span(seconds_left)} left"
    return text


class CountProgress:
    """Progress of work counted in pieces, in one style across the tool (``count_text``).

    On a terminal one line redrawn in place; piped (a log, CI), a line at the start, about one
    per tenth of the pieces (``PIPE_LINES``) and one at the end; nothing when disabled (the
    ``progress=false`` of the runs it launches). ``seconds_left`` is the caller's forecast
    (the budgets still to train), never a rate guess."""

    def __init__(self, enabled: bool, label: str, total: int, noun: str = "runs"):
        self.enabled, self.label, self.total, self.noun = enabled and total > 0, label, total, noun
        self.tty = self.enabled and sys.stderr.isatty()
        self._next_line = 0.0
        self.last = ""

    def update(self, done: int, seconds_left: float | None = None, failed: int = 0) -> None:
        if not self.enabled:
            return
        self.last = count_text(self.label, done, self.total, self.noun, seconds_left, failed)
        if self.tty:
            sys.stderr.write("\r\033[K" + self.last)
            sys.stderr.flush()
            return
        fraction = done / self.total
        if fraction >= self._next_line or done >= self.total:
            _line(self.last)
            self._next_line = (int(fraction * PIPE_LINES + 1e-9) + 1) / PIPE_LINES

    def close(self) -> None:
        if self.tty and self.last:
            sys.stderr.write("\n")
            sys.stderr.flush()
