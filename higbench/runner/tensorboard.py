"""A TensorBoard sink (``tensorboard=true``): curves and per-update phase times as event files.

Writes to ``<run dir>/tensorboard`` (``tensorboard --logdir outputs/`` shows every run):
the evaluation curves under ``eval/`` against the update count, and each update's batch
loss, phase times (``jacobian_s``, ``inversion_s``, ``apply_s``, ``update_s``) and, for
GN/HIG/LM, the spectrum columns under ``update/``. The run file stays the record; this is
a view. Needs the ``tensorboard`` extra (``pip install -e ".[tensorboard]"``).
"""

from __future__ import annotations

import math
from pathlib import Path

from higbench.errors import ConfigError
from higbench.runner.sinks import Sink


def summary_writer_class() -> type:
    """torch's SummaryWriter, or ConfigError (one clear line) when the extra is not installed."""
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:
        raise ConfigError("tensorboard", True, 'needs the tensorboard package: pip install -e ".[tensorboard]"') from None
    return SummaryWriter


class TensorBoardSink(Sink):
    """Update rows are kept and written at each flush (evaluations, checkpoints: the training
    clock is paused then), since writing them costs ~0.3 ms a row, 10% of a toy update."""

    def __init__(self, log_dir: Path):
        self.writer = summary_writer_class()(log_dir=str(log_dir))
        self.pending: list[dict[str, float]] = []

    def on_update(self, row: dict[str, float]) -> None:
        self.pending.append(row)

    def _write_updates(self) -> None:
        rows, self.pending = self.pending, []
        for row in rows:
            step = int(row["step"])
            for key, value in row.items():
                if key not in ("step", "wall_time") and math.isfinite(value):
                    self.writer.add_scalar(f"update/{key}", value, step)

    def on_eval(self, row: dict[str, float]) -> None:
        step = int(row["step"])
        for key, value in row.items():
            if key != "step" and math.isfinite(value):
                self.writer.add_scalar(f"eval/{key}", value, step)

    def flush(self) -> None:
        self._write_updates()
        self.writer.flush()

    def close(self, status: str, reason: str = "", step: int = -1) -> None:
        self._write_updates()
        self.writer.add_text("status", f"{status} at step {step}" + (f": {reason}" if reason else ""))
        self.writer.close()
