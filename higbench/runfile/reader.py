"""Reading run files back: metadata, curves, per-update timings, logs and weights.

This package (``higbench.runfile``) is the only one that opens an HDF5 file: the run
index, the figures, resume and ``init_from`` read run files through these functions.

Files are opened with ``locking=False`` unless said otherwise: a run that is still going
(or whose writer was killed) can be read up to its last flush; its ``status`` is then
``running``. With ``locking=True`` a file held by a live writer raises ``RunFileLocked``.
"""

from __future__ import annotations

import errno
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import yaml

RUN_FILE = "run.h5"  # the file name of a run inside its output directory
RUN_FILE_GLOB = "*.h5"  # what an index looks for: run files, also renamed copies; never checkpoints (run.h5.ckpt)


def run_file_path(path: str | Path) -> Path:
    """A run's file from a run directory or a file path (``outputs/x`` -> ``outputs/x/run.h5``)."""
    p = Path(path)
    return p / RUN_FILE if p.is_dir() or p.suffix != ".h5" else p


class UnreadableRunFile(OSError):
    """Not a run file: missing, not HDF5, truncated, a FIFO, or without a recorded config.

    ``kind``: the name of the underlying error; ``detail``: its full text (for the index)."""

    def __init__(self, message: str, kind: str = "", detail: str = ""):
        super().__init__(message)
        self.kind, self.detail = kind, detail or message


class RunFileLocked(UnreadableRunFile):
    """Opened with locking and held by a live writer (a run still going on this host)."""


class RunFileOpenForWrite(UnreadableRunFile):
    """HDF5's 'open for write' flag is set: the writer runs elsewhere, or died without closing
    the file (``h5clear -s <file>`` makes a dead run's file readable)."""


def _unreadable(p: Path, exc: Exception) -> UnreadableRunFile:
    """The exception to raise for a failed open/read of run file ``p``."""
    kind, detail = type(exc).__name__, f"{type(exc).__name__}: {exc}"
    if isinstance(exc, BlockingIOError) and exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EACCES):
        return RunFileLocked(f"{p}: open in another process (file locked by its writer)", kind, detail)
    if "already open for write" in str(exc):
        why = "open-for-write flag set: writer still running elsewhere, or killed (h5clear -s recovers)"
        return RunFileOpenForWrite(f"{p}: {why}", kind, why)
    return UnreadableRunFile(f"{p}: not a readable run file ({kind})", kind, detail)


@dataclass(frozen=True)
class RunHead:
    """What a run file says about itself, without its curves: enough to index, resume or
    initialise from it. ``attrs`` holds every root attribute (decoded, numeric ones as numbers)."""

    path: Path
    status: str
    config_yaml: str
    run_id: str | None
    problem: str
    steps: int | None
    has_weights: bool
    attrs: dict = field(default_factory=dict, repr=False)
    rows: dict = field(default_factory=dict, repr=False)  # {table: {column: rows}} (what checkpoints record)

    @property
    def n_updates(self) -> int:
        """Updates recorded in the per-update table."""
        return int(self.rows.get("updates", {}).get("step", 0))


def read_head(path: str | Path, locking: bool = False) -> RunHead:
    """The root attributes of a run file; raises ``UnreadableRunFile`` (with the reason),
    ``RunFileLocked`` with ``locking=True`` when a live writer holds the file."""
    p = run_file_path(path)
    if not p.is_file():  # a FIFO or device named *.h5 would block the open forever
        raise UnreadableRunFile(f"{p}: no such run file")
    try:
        with h5py.File(p, "r", locking=locking) as f:
            attrs = {k: _attr(v) for k, v in f.attrs.items()}
            has_weights = "weights" in f and len(f["weights"]) > 0
            rows = _row_counts(f)
    except Exception as exc:  # noqa: BLE001 - not HDF5, truncated, ...
        raise _unreadable(p, exc) from None
    steps = attrs.get("steps")
    try:
        steps = None if steps is None else int(float(steps))
    except (TypeError, ValueError):
        steps = None
    return RunHead(
        path=p,
        status=str(attrs.get("status", "running")),
        config_yaml=str(attrs.get("config", "")),
        run_id=attrs.get("run_id"),
        problem=str(attrs.get("problem", "")),
        steps=steps,
        has_weights=has_weights,
        attrs=attrs,
        rows=rows,
    )


def _row_counts(f: h5py.File) -> dict[str, dict[str, int]]:
    out: dict[str, dict[str, int]] = {}
    for group in ("curves", "updates", "logs"):
        if group in f and isinstance(f[group], h5py.Group):
            out[group] = {name: int(ds.shape[0]) for name, ds in f[group].items() if isinstance(ds, h5py.Dataset) and ds.ndim}
    return out


@dataclass
class RunTables:
    """A run file's root attributes, chosen 1-D numeric columns of its tables (as stored: a
    killed writer may leave them of different lengths) and its ``memory``/``env`` attributes."""

    attrs: dict
    tables: dict[str, dict[str, np.ndarray]]
    memory: dict
    env: dict


def read_tables(path: str | Path, columns: dict[str, Sequence[str] | None], locking: bool = True) -> RunTables:
    """Root attributes and the 1-D numeric ``columns`` of each table (``None``: all of them).

    The fast path of the run index (thousands of files): h5py's low-level calls, about half
    the cost of ``group[name][()]`` per small dataset. Raises ``RunFileLocked`` (``locking``
    and a live writer holds the file), ``RunFileOpenForWrite``, or ``UnreadableRunFile``.
    """
    p = Path(path)
    if not p.is_file():
        raise UnreadableRunFile(f"{p}: no such run file")
    try:
        with h5py.File(p, "r", locking=locking) as f:
            attrs = {k: _attr(v) for k, v in f.attrs.items()}
            tables = {group: _columns(f, group, names) for group, names in columns.items()}
            memory = {k: _attr(v) for k, v in f["memory"].attrs.items()} if "memory" in f else {}
            env = {k: _attr(v) for k, v in f["env"].attrs.items()} if "env" in f else {}
    except Exception as exc:  # noqa: BLE001 - truncated, garbage, not HDF5, half-written
        raise _unreadable(p, exc) from None
    return RunTables(attrs, tables, memory, env)


def _columns(f: h5py.File, group: str, names: Sequence[str] | None) -> dict[str, np.ndarray]:
    try:
        gid = h5py.h5g.open(f.id, group.encode())
    except KeyError:
        return {}
    if names is None:
        names = [gid.get_objname_by_idx(i).decode() for i in range(gid.get_num_objs())]
    cols = {}
    for name in names:
        try:
            ds = h5py.h5d.open(gid, name.encode())
        except KeyError:
            continue
        if len(ds.shape) != 1 or ds.dtype.kind not in "fiub":
            continue
        values = np.empty(ds.shape, dtype=ds.dtype)
        if values.size:
            ds.read(h5py.h5s.ALL, h5py.h5s.ALL, values)
        cols[name] = values
    return cols


def _attr(value):
    return value.decode() if isinstance(value, bytes) else (value.item() if isinstance(value, np.generic) else value)


def _open(path: str | Path) -> h5py.File:
    return h5py.File(path, "r", locking=False)


_NUMERIC_ATTRS = {"steps": int, "status_step": int, "format_version": int, "wall_time": float}


def read_meta(f: h5py.File) -> dict:
    meta = {k: _attr(v) for k, v in f.attrs.items()}
    for key, kind in _NUMERIC_ATTRS.items():  # older files may hold these as text
        if isinstance(meta.get(key), str):
            try:
                meta[key] = kind(float(meta[key])) if kind is int else kind(meta[key])
            except ValueError:
                pass
    meta["config"] = yaml.safe_load(meta.get("config", "{}")) or {}
    meta["overrides"] = json.loads(meta.get("overrides", "[]"))
    meta["resumes"] = json.loads(meta.get("resumes", "[]"))
    meta["env"] = {k: _attr(v) for k, v in f["env"].attrs.items()} if "env" in f else {}
    meta["memory"] = {k: _attr(v) for k, v in f["memory"].attrs.items()} if "memory" in f else {}
    return meta


def _table(f: h5py.File, group: str) -> pd.DataFrame:
    if group not in f:
        return pd.DataFrame()
    cols = {name: ds[()] for name, ds in f[group].items() if ds.ndim == 1}
    if not cols:
        return pd.DataFrame()
    n = min(len(v) for v in cols.values())  # a killed writer may leave columns one row apart
    df = pd.DataFrame({k: v[:n] for k, v in cols.items()})
    for col in ("step", "epoch"):
        if col in df:
            df[col] = df[col].astype("int64")
    return df


def load_run(path: str | Path) -> tuple[dict, pd.DataFrame]:
    """(meta, curves) of one run file.

    meta: dict with ``status``, ``config`` (resolved, as a dict), ``overrides``, ``env``,
    ``memory`` and the other root attributes. curves: one row per evaluation with at least
    ``step``, ``epoch``, ``wall_time``, ``train_loss``, ``test_loss`` (+ extra metrics).
    """
    with _open(path) as f:
        return read_meta(f), _table(f, "curves")


UPDATE_COLUMNS = ("step", "wall_time", "loss", "jacobian_s", "inversion_s", "apply_s", "update_s")


def load_updates(path: str | Path) -> pd.DataFrame:
    """Per-update table: step, wall_time, loss, jacobian_s, inversion_s, apply_s, update_s.

    A run stopped before its first update gives an empty table with these columns.
    """
    with _open(path) as f:
        df = _table(f, "updates")
    if df.empty and "step" not in df:
        df = pd.DataFrame({c: pd.Series(dtype="int64" if c == "step" else "float64") for c in UPDATE_COLUMNS})
    return df


def load_logs(path: str | Path) -> dict[str, np.ndarray]:
    """Per-evaluation arrays, e.g. neuron_mean (n_evals, hidden), probe_output (n_evals, 2)."""
    with _open(path) as f:
        return {name: ds[()] for name, ds in f["logs"].items()} if "logs" in f else {}


def load_weights(path: str | Path) -> dict[str, np.ndarray]:
    """Final weights as {state_dict name: array}."""
    with _open(path) as f:
        if "weights" not in f:
            raise KeyError(f"{path}: no final weights stored (status {_attr(f.attrs.get('status', '?'))})")
        return {name: ds[()] for name, ds in f["weights"].items()}
