"""Where a run's rows go: the run file, the progress display, optionally TensorBoard.

The training loop only calls the four methods of ``Sink``; each sink decides what to keep.
``on_update`` rows: step, wall_time, loss, the phase times and, for GN/HIG/LM, the spectrum
columns. ``on_eval`` rows: one per evaluation (the curves). ``on_log``: per-evaluation
arrays (neuron statistics, probe outputs, spectrum quantiles).
"""

from __future__ import annotations

import contextlib
import math
import sys

import numpy as np

from higbench.runfile.writer import RunFileFault, RunFileWriter
from higbench.runner.progress import Progress


class Sink:
    """The interface: every method may be a no-op."""

    def on_update(self, row: dict[str, float]) -> None: ...

    def on_eval(self, row: dict[str, float]) -> None: ...

    def on_log(self, name: str, value) -> None: ...

    def flush(self) -> None:
        """Make everything received so far durable (before a checkpoint, at evaluations)."""

    def close(self, status: str, reason: str = "", step: int = -1) -> None: ...


class RunFileSink(Sink):
    """The HDF5 run file: per-update rows are buffered and written at each flush."""

    def __init__(self, writer: RunFileWriter):
        self.writer = writer
        self.pending: dict[str, list[float]] = {}

    def on_update(self, row: dict[str, float]) -> None:
        for k, v in row.items():
            self.pending.setdefault(k, []).append(v)

    def on_eval(self, row: dict[str, float]) -> None:
        self.writer.append_row("curves", row)

    def on_log(self, name: str, value) -> None:
        self.writer.append_row("logs", {name: value})

    def write_pending(self) -> None:
        rows, self.pending = self.pending, {}  # cleared first: a stop mid-write never writes them twice
        self.writer.append_rows("updates", rows)

    def flush(self) -> None:
        self.write_pending()
        self.writer.flush()

    def close(self, status: str, reason: str = "", step: int = -1) -> None:
        self.writer.close(status, reason, step)

    def close_failed(self, exc: BaseException, step: int, write_pending: bool = True) -> None:
        """Close as ``failed``, whatever else goes wrong on the way.

        Pending rows are written if the file can still take them (not after a file-system
        fault: the file then keeps what its last flush holds).
        """
        if write_pending and not isinstance(exc, RunFileFault):
            try:
                self.write_pending()
            except Exception:  # noqa: BLE001 - the original error is the one to report
                pass
        try:
            self.writer.close("failed", f"{type(exc).__name__}: {exc}", step)
        except Exception:  # noqa: BLE001
            pass


class ProgressSink(Sink):
    """The bar (terminal) or lines (pipe) of ``Progress``."""

    def __init__(self, progress: Progress):
        self.progress = progress

    def on_update(self, row: dict[str, float]) -> None:
        self.progress.tick(int(row["step"]), row["wall_time"])

    def on_eval(self, row: dict[str, float]) -> None:
        self.progress.update(int(row["step"]), row["wall_time"], row["train_loss"], row["test_loss"])

    def close(self, status: str, reason: str = "", step: int = -1) -> None:
        self.progress.close()


class Sinks(Sink):
    """Several sinks in order; the run file first, so it holds a row before any display shows it.

    The run file is the record: its faults stop the run. A side sink (TensorBoard) that
    fails is turned off with one line on stderr, and the run goes on without it.
    """

    def __init__(self, *sinks: Sink):
        self.sinks = list(sinks)

    def _each(self, method: str, *args) -> None:
        for s in list(self.sinks):
            if isinstance(s, (RunFileSink, ProgressSink)):
                getattr(s, method)(*args)
                continue
            try:
                getattr(s, method)(*args)
            except Exception as exc:  # noqa: BLE001 - a view of the run, never worth the run itself
                self.turn_off(s, exc)

    def turn_off(self, sink: Sink, exc: BaseException) -> None:
        if sink in self.sinks:
            self.sinks.remove(sink)
        name = getattr(sink, "name", type(sink).__name__)
        why = " ".join(f"{type(exc).__name__}: {exc}".split())[:300]
        print(f"higbench: {name} turned off ({why}); the run goes on, its run file is the record", file=sys.stderr, flush=True)
        with contextlib.suppress(Exception):
            sink.close("failed", why)

    def on_update(self, row):
        self._each("on_update", row)

    def on_eval(self, row):
        self._each("on_eval", row)

    def on_log(self, name, value):
        self._each("on_log", name, value)

    def flush(self):
        self._each("flush")

    def close(self, status, reason="", step=-1):
        self._each("close", status, reason, step)


SPECTRUM_QUANTILES = np.linspace(0.0, 1.0, 11)


SPECTRUM_COLUMNS = ("sv_max", "sv_min_kept", "sv_dropped", "step_error")


def spectrum_columns(spectrum: dict) -> dict[str, float]:
    """Per-update columns of a GN/HIG/LM spectrum (NaN when the update recorded none).

    ``step_error``: the estimated relative error of the step on the approximate (krylov)
    route; NaN on the exact routes.
    """
    return {k: float(spectrum.get(k, math.nan)) for k in SPECTRUM_COLUMNS}


def spectrum_quantiles(spectrum: dict) -> np.ndarray:
    """Quantiles 0, 0.1, .., 1 of all singular values of an update (NaN when none)."""
    s = spectrum.get("singular_values")
    if s is None or len(s) == 0:
        return np.full(len(SPECTRUM_QUANTILES), math.nan)
    return np.quantile(np.asarray(s, dtype=np.float64), SPECTRUM_QUANTILES)
