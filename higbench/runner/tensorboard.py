"""A TensorBoard sink (``sink=tensorboard``, or ``tensorboard=true``): curves and per-update phase times as event files.

Writes to ``<run dir>/tensorboard`` (``tensorboard --logdir outputs/`` shows every run):
the evaluation curves under ``eval/`` against the update count, and each update's batch
loss, phase times (``jacobian_s``, ``inversion_s``, ``apply_s``, ``update_s``) and, for
GN/HIG/LM, the spectrum columns under ``update/``. The run file stays the record; this is
a view. Needs the ``tensorboard`` extra (``pip install -e ".[tensorboard]"``).
"""

from __future__ import annotations

import contextlib
import math
import os
import secrets
import stat
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


TENSORBOARD_DIR = "tensorboard"  # in the run directory


def open_log_dir(run_dir: Path) -> int:
    """A descriptor of ``<run dir>/tensorboard``, made if absent, never reached through a link."""
    parent = os.open(run_dir, os.O_RDONLY | os.O_DIRECTORY)
    try:
        with contextlib.suppress(FileExistsError):
            os.mkdir(TENSORBOARD_DIR, 0o777, dir_fd=parent)
        return os.open(TENSORBOARD_DIR, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW, dir_fd=parent)
    finally:
        os.close(parent)


def _hold_event_file(writer, dir_fd: int) -> None:
    """Make the SummaryWriter append to a descriptor higbench holds, not to a path.

    TensorBoard's file writer reopens its event file by name at every flush, so a link put in
    its place mid-run would be followed; here the record writer gets the file opened once
    (``O_NOFOLLOW``, relative to the directory's descriptor, one link) and keeps it.
    """
    events = writer._get_file_writer().event_writer  # tensorboard's EventFileWriter
    records = events._async_writer._writer  # its RecordWriter: write/flush/close on a file object
    name = os.path.basename(events._file_name)
    fd = os.open(name, os.O_WRONLY | os.O_APPEND | os.O_NOFOLLOW, dir_fd=dir_fd)
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode) or st.st_nlink != 1:
        os.close(fd)
        raise OSError(f"{name} is not this run's own event file")
    records._writer = os.fdopen(fd, "ab")


class TensorBoardSink(Sink):
    """Update rows are kept and written at each flush (evaluations, checkpoints: the training
    clock is paused then), since writing them costs ~0.3 ms a row, 10% of a toy update.

    Written through descriptors only: the directory is opened once (``open_log_dir``) and
    the writer addresses it as ``/proc/self/fd/<n>`` (Linux), the event file gets a random
    suffix and is then held open (``_hold_event_file``). A failure here turns the sink off
    (``sinks.Sinks``), never the run."""

    name = "tensorboard"

    def __init__(self, run_dir: Path):
        writer_class = summary_writer_class()  # without the extra: refused before anything is made
        self.dir_fd = open_log_dir(run_dir)
        via_fd = f"/proc/self/fd/{self.dir_fd}"
        log_dir = via_fd if os.path.isdir(via_fd) else str(Path(run_dir) / TENSORBOARD_DIR)
        suffix = f".{secrets.token_hex(8)}"  # an unpredictable name: nothing can be planted under it
        self.writer = writer_class(log_dir=log_dir, filename_suffix=suffix)
        _hold_event_file(self.writer, self.dir_fd)
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
        try:
            self.writer.add_text("status", f"{status} at step {step}" + (f": {reason}" if reason else ""))
            self.writer.close()
        finally:
            os.close(self.dir_fd)
