"""Reading run files back: metadata, curves, per-update timings, logs and weights.

Files are opened with ``locking=False``: a run that is still going (or whose writer was
killed) can be read up to its last flush; its ``status`` is then ``running``.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import yaml


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
