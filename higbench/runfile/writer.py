"""One HDF5 file per run, appended and flushed as the run goes.

Layout (documented in the README, read by ``higbench.results``):

    /                 attrs: format_version, status, status_reason, status_step, config (YAML),
                             overrides (JSON list), problem, optimizer, started, finished
    /env              attrs: versions, git revision, hostname, threads, device, ...
    /curves/<column>  (n_evals,)          one row per evaluation (step, epoch, wall_time, ...)
    /logs/<name>      (n_evals, ...)      per-evaluation arrays (neuron saturation, probe output)
    /updates/<column> (n_updates,)        per-update timings and batch loss
    /memory           attrs: peak_rss_mb, baseline_rss_mb, cuda_peak_mb
    /weights/<name>   final parameters (state_dict names), attrs: step
    /checkpoint/...   reserved for resumable state

Datasets are created resizable on first append; ``flush()`` after every evaluation keeps
the file readable up to that point if the process dies.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Mapping

import h5py
import numpy as np

FORMAT_VERSION = 1
STATUSES = ("running", "completed", "diverged", "interrupted", "failed")


class RunFileExists(FileExistsError):
    pass


class RunFileWriter:
    def __init__(self, path: str | Path, config_yaml: str, overrides: list[str], env: Mapping, meta: Mapping):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            # "w-": never overwrite an existing run's file.
            self.f = h5py.File(self.path, "w-", libver="latest")
        except (FileExistsError, OSError) as exc:
            if self.path.exists():
                raise RunFileExists(f"run file {self.path} already exists; refusing to overwrite it") from exc
            raise
        self.f.attrs["format_version"] = FORMAT_VERSION
        self.f.attrs["config"] = config_yaml
        self.f.attrs["overrides"] = json.dumps(list(overrides))
        self.f.attrs["started"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        for k, v in meta.items():
            self.f.attrs[k] = v
        env_group = self.f.create_group("env")
        for k, v in env.items():
            env_group.attrs[k] = "" if v is None else v
        for group in ("curves", "logs", "updates", "memory"):
            self.f.create_group(group)
        self.set_status("running")
        self.flush()

    # -- status --
    def set_status(self, status: str, reason: str = "", step: int = -1) -> None:
        if status not in STATUSES:
            raise ValueError(f"status={status!r}: expected one of {STATUSES}")
        self.f.attrs["status"] = status
        self.f.attrs["status_reason"] = reason
        self.f.attrs["status_step"] = step

    # -- appends --
    def _append(self, group: str, name: str, values: np.ndarray) -> None:
        values = np.asarray(values)
        g = self.f[group]
        if name not in g:
            g.create_dataset(name, data=values, maxshape=(None, *values.shape[1:]), chunks=True)
            return
        ds = g[name]
        if ds.shape[1:] != values.shape[1:]:
            raise ValueError(f"{group}/{name}: row shape {values.shape[1:]} != {ds.shape[1:]}")
        n = ds.shape[0]
        ds.resize(n + values.shape[0], axis=0)
        ds[n:] = values

    def append_row(self, group: str, row: Mapping[str, float | np.ndarray]) -> None:
        """Append one row (a value or array per column) to /group."""
        for name, value in row.items():
            self._append(group, name, np.asarray(value, dtype=np.float64)[None, ...])

    def append_rows(self, group: str, columns: Mapping[str, list | np.ndarray]) -> None:
        """Append many rows at once (columns of equal length)."""
        for name, values in columns.items():
            if len(values):
                self._append(group, name, np.asarray(values, dtype=np.float64))

    # -- end of run --
    def set_attrs(self, group: str, attrs: Mapping) -> None:
        for k, v in attrs.items():
            self.f[group].attrs[k] = v

    def write_weights(self, state: Mapping[str, np.ndarray], step: int) -> None:
        if "weights" in self.f:
            del self.f["weights"]
        g = self.f.create_group("weights")
        g.attrs["step"] = step
        for name, value in state.items():
            g.create_dataset(name, data=np.asarray(value))

    def flush(self) -> None:
        self.f.flush()

    def close(self, status: str | None = None, reason: str = "", step: int = -1) -> None:
        if not self.f.id.valid:
            return
        if status is not None:
            self.set_status(status, reason, step)
        self.f.attrs["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        self.f.close()
