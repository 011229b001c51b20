"""Reading run files back: metadata, curves, per-update timings, logs and weights.

Files are opened with ``locking=False``: a run that is still going (or whose writer was
killed) can be read up to its last flush; its ``status`` is then ``running``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import yaml

RUN_FILE = "run.h5"  # the file name of a run inside its output directory


def run_file_path(path: str | Path) -> Path:
    """A run's file from a run directory or a file path (``outputs/x`` -> ``outputs/x/run.h5``)."""
    p = Path(path)
    return p / RUN_FILE if p.is_dir() or p.suffix != ".h5" else p


class UnreadableRunFile(OSError):
    """Not a run file: missing, not HDF5, truncated, a FIFO, or without a recorded config."""


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


def read_head(path: str | Path, locking: bool = False) -> RunHead:
    """The root attributes of a run file; raises ``UnreadableRunFile`` (with the reason)."""
    p = run_file_path(path)
    if not p.is_file():  # a FIFO or device named *.h5 would block the open forever
        raise UnreadableRunFile(f"{p}: no such run file")
    try:
        with h5py.File(p, "r", locking=locking) as f:
            attrs = {k: _attr(v) for k, v in f.attrs.items()}
            has_weights = "weights" in f and len(f["weights"]) > 0
    except Exception as exc:  # noqa: BLE001 - not HDF5, truncated, ...
        raise UnreadableRunFile(f"{p}: not a readable run file ({type(exc).__name__})") from None
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
    )


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
