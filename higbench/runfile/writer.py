"""One HDF5 file per run, appended and flushed as the run goes.

Layout (documented in docs/run-file.md, read by ``higbench.results``):

    /                 attrs: format_version, status, status_reason, status_step, config (YAML),
                             overrides (JSON list), problem, optimizer, started, finished
    /env              attrs: versions, git revision, hostname, threads, device, ...
    /curves/<column>  (n_evals,)          one row per evaluation (step, epoch, wall_time, ...)
    /logs/<name>      (n_evals, ...)      per-evaluation arrays (neuron saturation, probe output)
    /updates/<column> (n_updates,)        per-update timings and batch loss
    /memory           attrs: peak_rss_mb, baseline_rss_mb, cuda_peak_mb
    /weights/<name>   final parameters (state_dict names), attrs: step
    /                 attrs (resumed runs): resumes (JSON list: when, from which step, overrides),
                             config_original (the config before resume changed a budget)

Crash safety. Datasets are created resizable on first append; the runner writes only at
evaluations and checkpoints, each time followed by ``flush()``, so a writer killed with
SIGKILL leaves a file that is readable up to its last flush, with ``status`` still
``running`` (which is how an index tells it from a completed run). The file is written
with HDF5's default format bounds (low bound "earliest") on purpose: with a low bound of
v110 or later (``libver="latest"``) HDF5 writes superblock v3, whose "open for write"
flag makes a killed writer's file unopenable until ``h5clear -s`` (measured with HDF5 2.0:
10 of 10 writers killed mid-append left unreadable files with "latest", 0 of 40 with the
default). Readers open with ``locking=False`` so they can read a file that is still being
written (up to its last flush).

What this does not guarantee: HDF5 without SWMR has no atomic flush. A kill that lands
inside a flush which allocates new file space (a new chunk of a table) can leave that
newest chunk unreadable ("addr overflow ... eoa"); measured with HDF5 2.0, 1 of 150 kills
of a writer that does nothing but append and flush, 0 of 150 with SWMR. The runner writes
only at evaluations (a few ms per evaluation), so the exposure per kill is far smaller.
SWMR would close it but is not used: a SWMR file killed mid-run cannot be reopened for
writing (resume) without ``h5clear``, holds no lock a reader could test for liveness, and
needs ``swmr=True`` in every reader.

Faults of the file system (see ``RunFileFault``). HDF5 cannot recover from a failed write:
after one, its caches are inconsistent, further calls fail ("Slist already enabled?") or
crash the process, and what reaches the disk references space that was never written
("addr overflow"). So the writer never lets a write fail for lack of space: before every
write it checks the free space of the file's file system and the process's file-size
limit (RLIMIT_FSIZE) against what is not yet flushed plus a reserve for closing
(``RESERVE_BYTES``); short of it, it raises ``DiskFull`` before touching the file, and the
runner closes the file as ``failed`` inside the reserve. The file then holds every row
up to its last flush. (What remains: another process filling the disk between the check
and the write.) Likewise it checks that the file can still be written (no immutable or
append-only flag, no read-only mount; ``RunFileReadOnly``): such a file cannot even take
its status, so it is left open and untouched (closing would write) and the CLI exits 1.
A run file or directory that cannot be created (no space, no free inode, a quota) is a
``DiskFull``/``RunFileFault`` too. At every flush the writer also checks that the path still names the file
it writes (``RunFileLost``: deleted or replaced under a live run).

Identity: every run file carries a random ``run_id`` (root attribute); its checkpoints
carry the same id, and resume refuses a checkpoint whose id differs.

Never overwriting: a new run file is created with mode ``"w-"`` (fails if the file
exists). The only writer that opens an existing file is ``RunFileWriter.reopen``, used by
``resume=...``: it truncates every table to the rows recorded by the checkpoint it resumes
from and appends from there.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import resource
import sys
import time
import uuid
from collections.abc import Mapping
from pathlib import Path

import h5py
import numpy as np

from higbench.runfile.reader import SUMMARY_COLUMNS, RunTables, check_contained, tables_of

FORMAT_VERSION = 1
H5PY_VERSION = h5py.__version__  # recorded in each run's environment
STATUSES = ("running", "completed", "diverged", "interrupted", "failed")
# Room kept free for closing a run (pending rows, status, weights' metadata, HDF5's caches).
RESERVE_BYTES = 1 << 20


class RunFileExists(FileExistsError):
    pass


class RunFileBusy(OSError):
    """Another process holds the run file open (a live writer)."""


class RunFileShared(RunFileBusy):
    """The opened file is not the run directory's own: reached through a link, or with a
    second hard link (a snapshot made with ``cp -al``), which a write in place would change."""


def check_own_file(f: h5py.File, path: Path) -> None:
    """Raise RunFileShared unless the open ``f`` is the file at ``path`` itself, with one link
    (checked on the opened descriptor, after the open: nothing planted meanwhile is written)."""
    try:
        opened = os.fstat(f.id.get_vfd_handle())
        named = os.lstat(path)
    except (OSError, ValueError, TypeError):  # a driver without a descriptor: the path checks stand
        return
    if (opened.st_dev, opened.st_ino) != (named.st_dev, named.st_ino):
        raise RunFileShared(f"run file {path} was replaced by a link or another file; refusing to write through it")
    if opened.st_nlink > 1:
        why = f"has {opened.st_nlink} hard links (a snapshot shares it); refusing to write it in place"
        raise RunFileShared(f"run file {path} {why}")


class RunFileFault(OSError):
    """The file system cannot take the run's writes (full, gone, failing): the run stops (exit 1)."""


class DiskFull(RunFileFault):
    def __init__(self, message: str):
        super().__init__(errno.ENOSPC, message)

    def __str__(self) -> str:
        return self.strerror


class RunFileReadOnly(RunFileFault):
    """The file can no longer be written (immutable or append-only flag, read-only mount)."""

    def __str__(self) -> str:
        return self.args[1] if len(self.args) > 1 else "run file read-only"


class RunFileLost(RunFileFault):
    def __str__(self) -> str:
        return self.args[0] if self.args else "run file lost"


def free_bytes(path: str | Path, file_size: int = 0) -> int:
    """Bytes that can still be written into ``path`` (a file, or a directory to create one in).

    The smaller of the free space of its file system (what an unprivileged user may use)
    and what the process's file-size limit leaves to a file of ``file_size`` bytes.
    """
    path = Path(path)
    probe = path if path.exists() else path.parent
    st = os.statvfs(probe)
    free = st.f_bavail * st.f_frsize
    soft, _hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    if soft != resource.RLIM_INFINITY:
        free = min(free, max(0, soft - file_size))
    return int(free)


def new_run_id() -> str:
    return uuid.uuid4().hex


TABLES = ("curves", "logs", "updates")

# (units, description) written as attributes of each table dataset, so a file explains itself
# (h5dump, HDFView). Extra metrics (curves/test_<metric>) get a generic entry.
DATASET_INFO: dict[tuple[str, str], tuple[str, str]] = {
    ("curves", "step"): ("updates", "update count at this evaluation (0: the initial network)"),
    ("curves", "epoch"): ("epochs", "completed passes over the training set at this evaluation"),
    ("curves", "wall_time"): ("s", "training clock at this evaluation (evaluations excluded; start-up included)"),
    ("curves", "train_loss"): ("loss", "mean mini-batch loss since the previous evaluation (NaN at step 0)"),
    ("curves", "test_loss"): ("loss", "mean loss over the test set"),
    ("curves", "val_loss"): ("loss", "mean loss over the validation set (problem.val_size; what tuning reads)"),
    ("curves", "rss_mb"): ("MB", "resident memory of the process at this evaluation"),
    ("logs", "neuron_mean"): ("activation", "per hidden neuron: mean activation over the validation inputs"),
    ("logs", "neuron_std"): ("activation", "per hidden neuron: standard deviation of the activation over the validation inputs"),
    ("logs", "probe_output"): ("output", "network output for the probe input problem.probe_x"),
    ("logs", "probe_target"): ("output", "target for the probe input problem.probe_x"),
    ("updates", "step"): ("updates", "update count after this update"),
    ("updates", "wall_time"): ("s", "training clock after this update"),
    ("updates", "loss"): ("loss", "mean loss of this update's mini-batch"),
    ("updates", "jacobian_s"): ("s", "time of the derivatives (forward pass, gradient or Jacobian factors)"),
    ("updates", "inversion_s"): ("s", "time of the inversion (GN/HIG: Gram/SVD; first-order: 0)"),
    ("updates", "apply_s"): ("s", "time to apply the update to the weights"),
    ("updates", "update_s"): ("s", "whole update: jacobian_s + inversion_s + apply_s"),
    ("updates", "sv_max"): ("singular value", "GN/HIG/LM: largest singular value of this update's Jacobian"),
    ("updates", "sv_min_kept"): ("singular value", "GN/HIG/LM: smallest singular value kept by the truncation tau"),
    ("updates", "sv_dropped"): ("count", "GN/HIG/LM: singular values the truncation tau dropped"),
    ("updates", "step_error"): ("relative", "GN/HIG solver=krylov: estimated relative error of the step (NaN: exact route)"),
    ("logs", "sv_quantiles"): ("singular value", "GN/HIG/LM: 11 quantiles (0, 0.1, ..., 1) of the last update's singular values"),
}


def dataset_info(group: str, name: str) -> tuple[str, str] | None:
    if (group, name) in DATASET_INFO:
        return DATASET_INFO[group, name]
    if group == "curves" and name.startswith("test_"):
        return "loss", f"{name[5:].replace('_', ' ')} over the test set"
    return None


class RunFileWriter:
    final_tables: RunTables | None = None  # its SUMMARY_COLUMNS, kept as it closed the file

    def __init__(self, path: str | Path, config_yaml: str, overrides: list[str], env: Mapping, meta: Mapping):
        self.path = Path(path)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise _creation_fault(self.path.parent, exc) from None
        self._unflushed = 0
        self._inode = None
        self.check_space()
        try:
            # "w-": never overwrite an existing run's file.
            # libver low bound "earliest" (HDF5's default): a low bound of v110 or later writes
            # superblock v3, whose "open for write" flag makes a killed writer's file unopenable.
            self.f = h5py.File(self.path, "w-", libver=("earliest", "latest"))
        except (FileExistsError, OSError) as exc:
            if os.path.lexists(self.path):
                raise RunFileExists(f"run file {self.path} already exists; refusing to overwrite it") from exc
            raise _creation_fault(self.path, exc) from None
        self._inode = self._stat_key()
        self.run_id = new_run_id()
        self.f.attrs["format_version"] = FORMAT_VERSION
        self.f.attrs["run_id"] = self.run_id
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

    @classmethod
    def reopen(
        cls,
        path: str | Path,
        rows: Mapping[str, Mapping[str, int]],
        resume_info: Mapping | None = None,
        config_yaml: str | None = None,
    ) -> RunFileWriter:
        """Open an existing run file to continue it (``resume``): the one exception to "w-".

        ``rows``: {group: {dataset: length}} as recorded by the checkpoint; every table is
        cut back to those lengths (rows written after the checkpoint, or by a writer killed
        mid-append, go) and tables created after it are removed, so the resumed run appends
        without duplicates. Final weights and the end-of-run attributes are removed too.
        """
        self = cls.__new__(cls)
        self.path = Path(path)
        self._unflushed = 0
        self._inode = None
        if self.path.is_symlink():  # resume writes a run in its own directory only
            raise RunFileFault(errno.ELOOP, f"run file {self.path} is a symbolic link; refusing to write through it")
        self.check_writable()
        self.check_space()
        try:
            self.f = h5py.File(self.path, "r+")
        except BlockingIOError as exc:
            raise RunFileBusy(f"run file {self.path} is open in another process (is that run still going?)") from exc
        try:
            check_contained(self.f)  # nothing it writes may land in another file
            check_own_file(self.f, self.path)
        except BaseException:
            self.f.close()
            raise
        self._inode = self._stat_key()
        self.run_id = run_id_of(self.f)
        for group, names in rows.items():  # check everything before changing anything
            for name, n in names.items():
                have = self.f[group][name].shape[0] if group in self.f and name in self.f[group] else 0
                if have < n:
                    self.f.close()
                    raise ValueError(f"{self.path}: {group}/{name} has {have} rows, its checkpoint recorded {n}; cannot resume")
        for group in TABLES:
            if group not in self.f:
                self.f.create_group(group)
                continue
            keep = rows.get(group, {})
            g = self.f[group]
            for name in list(g.keys()):
                if name not in keep:
                    del g[name]
                elif g[name].shape[0] > keep[name]:
                    g[name].resize(keep[name], axis=0)
        if "weights" in self.f:
            del self.f["weights"]
        for key in ("finished", "steps", "wall_time"):
            if key in self.f.attrs:
                del self.f.attrs[key]
        if config_yaml is not None:
            if "config_original" not in self.f.attrs:
                self.f.attrs["config_original"] = self.f.attrs["config"]
            self.f.attrs["config"] = config_yaml
        if resume_info is not None:
            history = json.loads(self.f.attrs.get("resumes", "[]"))
            history.append(dict(resume_info))
            self.f.attrs["resumes"] = json.dumps(history)
        self.set_status("running")
        self.flush()
        return self

    # -- faults of the file system --
    def _stat_key(self) -> tuple[int, int] | None:
        try:
            st = os.stat(self.path)
        except OSError:
            return None
        return (st.st_dev, st.st_ino)

    def check_space(self, extra: int = 0) -> None:
        """Raise DiskFull unless the unflushed data, ``extra`` bytes and the reserve fit."""
        if self._inode is not None:
            self.check_file()  # a file that is gone has no disk to fill
            self.check_writable()
        need = 2 * (self._unflushed + extra) + RESERVE_BYTES
        try:
            size = self.path.stat().st_size if self.path.exists() else 0
            free = free_bytes(self.path, size)
        except FileNotFoundError:  # its directory went between the checks above and here
            if self._inode is not None:
                self.check_file()
            raise
        if free < need:
            raise DiskFull(
                f"no space left for {self.path} ({free // 1024} KiB free, the next write needs about {need // 1024} KiB "
                "with the reserve for closing the file); run stopped before writing"
            )

    def check_writable(self) -> None:
        """Raise RunFileReadOnly if a write would fail: HDF5 cannot survive a failed write
        (it crashes the process), so this is checked before every write, like the disk space."""
        why = read_only_reason(self.path, getattr(self, "f", None))
        if why:
            self._read_only = True
            raise RunFileReadOnly(
                errno.EPERM,
                f"run file {self.path} became read-only while the run was writing it ({why}); run stopped. "
                "It keeps every row up to its last flush; its status cannot be written",
            )

    def check_file(self) -> None:
        """Raise RunFileLost if the path no longer names the file this writer writes."""
        if self._stat_key() != self._inode:
            what = "deleted" if not os.path.lexists(self.path) else "replaced by another file"
            raise RunFileLost(f"run file {self.path} was {what} while the run was writing it; run stopped")

    def row_counts(self) -> dict[str, dict[str, int]]:
        """{group: {dataset: rows}} of the tables now (recorded by checkpoints)."""
        return {group: {name: int(ds.shape[0]) for name, ds in self.f[group].items()} for group in TABLES if group in self.f}

    def last_value(self, group: str, name: str) -> float:
        """The last row of ``/group/name`` (NaN if there is none): a resumed run's last evaluation."""
        if group in self.f and name in self.f[group] and self.f[group][name].shape[0]:
            return float(self.f[group][name][-1])
        return float("nan")

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
        self.check_space(values.nbytes + 4096)
        self._unflushed += values.nbytes + 4096
        g = self.f[group]
        if name not in g:
            ds = g.create_dataset(name, data=values, maxshape=(None, *values.shape[1:]), chunks=True)
            info = dataset_info(group, name)
            if info is not None:
                ds.attrs["units"], ds.attrs["description"] = info
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
        """``/weights``: the network's final weights, at ``step``."""
        self._write_group("weights", state, step)

    def write_final(self, arrays: Mapping[str, np.ndarray], step: int) -> None:
        """``/final``: arrays of the final evaluation (the per-sample test losses), at ``step``."""
        self._write_group("final", arrays, step)

    def _write_group(self, group: str, arrays: Mapping[str, np.ndarray], step: int) -> None:
        """``group`` replaced by ``arrays`` (one dataset each), its attr ``step``; space checked first."""
        self.check_space(sum(np.asarray(v).nbytes + 4096 for v in arrays.values()))
        if group in self.f:
            del self.f[group]
        g = self.f.create_group(group)
        g.attrs["step"] = step
        for name, value in arrays.items():
            g.create_dataset(name, data=np.asarray(value))

    def flush(self) -> None:
        self.check_file()
        self.check_space()
        self.f.flush()
        self._unflushed = 0

    def close(self, status: str | None = None, reason: str = "", step: int = -1) -> None:
        """Write the final status and close; the file is closed whatever happens."""
        if not self.f.id.valid:
            return
        if getattr(self, "_read_only", False) or read_only_reason(self.path, self.f):
            # Nothing can be written, and closing writes (HDF5 then fails, and may crash the
            # process): the file is left open, untouched, until the process exits.
            _ABANDONED.append(self.f)
            return
        try:
            if status is not None:
                self.set_status(status, reason, step)
            self.f.attrs["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
            with contextlib.suppress(Exception):  # else the summary reads the closed file
                self.final_tables = tables_of(self.f, SUMMARY_COLUMNS)
        finally:
            self.f.close()


_ABANDONED: list[h5py.File] = []  # read-only run files never closed (see RunFileWriter.close)
_FS_IOC_GETFLAGS = 0x80086601  # Linux: the inode's attribute flags (chattr)
_FS_IMMUTABLE_FL, _FS_APPEND_FL = 0x10, 0x20


def read_only_reason(path: Path, f: h5py.File | None = None) -> str:
    """Why ``path`` cannot be written into now ("" if it can, or if that cannot be told)."""
    try:
        if os.statvfs(path.parent).f_flag & os.ST_RDONLY:
            return "its file system is mounted read-only"
    except OSError:
        return ""
    try:
        import fcntl

        fd = f.id.get_vfd_handle() if f is not None and f.id.valid else None
        own = fd is None
        if own:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
        try:
            flags = int.from_bytes(fcntl.ioctl(fd, _FS_IOC_GETFLAGS, b"\0" * 8)[:4], sys.byteorder)
        finally:
            if own:
                os.close(fd)
    except (OSError, ImportError, TypeError, ValueError):  # no such ioctl here (tmpfs of old kernels, NFS, macOS)
        return ""
    if flags & _FS_IMMUTABLE_FL:
        return "immutable flag set (chattr +i)"
    if flags & _FS_APPEND_FL:
        return "append-only flag set (chattr +a)"
    return ""


_NO_ROOM = (errno.ENOSPC, errno.EDQUOT)


def _creation_fault(path: Path, exc: OSError) -> RunFileFault:
    """One line for a run file (or its directory) that cannot be created: a full disk, no
    free inodes, a quota (``DiskFull``: nothing was written), anything else (``RunFileFault``)."""
    code = exc.errno
    if code is None:  # h5py puts the errno in its message only
        code = next((c for c in (*_NO_ROOM, errno.EACCES, errno.EROFS) if f"errno = {c}," in str(exc)), None)
    why = os.strerror(code) if code else " ".join(str(exc).split())[:200]
    if code in _NO_ROOM:
        return DiskFull(f"cannot create {path}: {why} (no space, no free inodes or over quota); nothing was written")
    return RunFileFault(code or errno.EIO, f"cannot create {path}: {why}; nothing was written")


def run_id_of(f: h5py.File) -> str:
    """The ``run_id`` attribute of an open run file ("" for files written before it existed)."""
    v = f.attrs.get("run_id", "")
    return v.decode() if isinstance(v, bytes) else str(v)
