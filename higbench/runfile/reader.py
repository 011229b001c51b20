"""Reading run files back: metadata, curves, per-update timings, logs and weights.

This package (``higbench.runfile``) is the only one that opens an HDF5 file: the run
index, the figures, resume and ``init_from`` read run files through these functions.

Files are opened with ``locking=False`` unless said otherwise: a run that is still going
(or whose writer was killed) can be read up to its last flush; its ``status`` is then
``running``. With ``locking=True`` a file held by a live writer raises ``RunFileLocked``.

Files other people wrote (``init_from=``, ``resume=``, a shared runs tree) are not trusted.
Every reader here first checks that the file is self-contained (``check_contained``): only
hard links (no soft, external or user-defined links), no dataset with external storage
(``external=``: its bytes would come from another file) or a virtual layout (mapped onto
other files), no filter but HDF5's built-in ones (no plugin is loaded), and no dataset that
declares more bytes than its file could hold (an unallocated 200000 x 200000 dataset reads
as 320 GB of fill values). The stored config is parsed with bounds (``parse_config``): at
most ``MAX_CONFIG_BYTES`` of text and ``MAX_CONFIG_NODES`` nodes once YAML aliases are
expanded (a 640-byte alias bomb expands to billions). Such a file is an ``UnreadableRunFile``
(kind ``refused``): one line for the CLI, a ``corrupt`` row in the index.
"""

from __future__ import annotations

import errno
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import yaml

RUN_FILE = "run.h5"  # the file name of a run inside its output directory
UPDATE_SPECTRUM_COLUMNS = ("sv_max", "sv_min_kept", "sv_dropped")
# What a run's summary row reads of its tables (``results.index.read_run_summary``); its writer
# keeps them as it closes the file (``RunFileWriter.final_tables``), so the summary of the run
# just ended does not open it again.
SUMMARY_COLUMNS = {
    "curves": ("step", "wall_time", "train_loss", "test_loss", "val_loss"),
    "updates": ("update_s", "jacobian_s", "inversion_s", *UPDATE_SPECTRUM_COLUMNS),
    "final": ("test_losses", "fresh_test_losses"),
}
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


class RefusedRunFile(UnreadableRunFile):
    """A file with content no run file has: links or storage outside it, a config too large."""

    def __init__(self, message: str):
        super().__init__(message, "refused", message)


def _unreadable(p: Path, exc: Exception) -> UnreadableRunFile:
    """The exception to raise for a failed open/read of run file ``p``."""
    if isinstance(exc, RefusedRunFile):
        return RefusedRunFile(f"{p}: {exc}")
    kind, detail = type(exc).__name__, f"{type(exc).__name__}: {exc}"
    if isinstance(exc, BlockingIOError) and exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EACCES):
        return RunFileLocked(f"{p}: open in another process (file locked by its writer)", kind, detail)
    if "already open for write" in str(exc):
        why = "open-for-write flag set: writer still running elsewhere, or killed (h5clear -s recovers)"
        return RunFileOpenForWrite(f"{p}: {why}", kind, why)
    return UnreadableRunFile(f"{p}: not a readable run file ({kind})", kind, detail)


# -- what a file from somebody else may hold ---------------------------------------------------

_BUILTIN_FILTERS = frozenset(
    getattr(h5py.h5z, name)
    for name in ("FILTER_DEFLATE", "FILTER_SHUFFLE", "FILTER_FLETCHER32", "FILTER_SZIP", "FILTER_NBIT", "FILTER_SCALEOFFSET")
) | {32000}  # lzf, built into h5py
_COMPRESSION_RATIO = 1100  # deflate expands at most ~1032x; an uncompressed dataset holds its bytes
_SLACK_BYTES = 1 << 20  # a killed writer's resized table may lack its last chunk (read as fill)


MAX_DEPTH = 16  # a run file nests 2 levels; HDF5's own recursive visit crashes near 10,000
MAX_OBJECTS = 20_000  # links in one file (a run file holds a few hundred)
_TOTAL_RATIO = 16  # all datasets of a file together declare at most this multiple of its size


def check_contained(f: h5py.File, datasets: bool = True) -> None:
    """Raise ``RefusedRunFile`` unless every object of ``f`` lives in ``f`` (see module doc),
    within ``MAX_DEPTH`` levels and ``MAX_OBJECTS`` links.

    Walked here, one group at a time and never deeper than the bound (HDF5's recursive
    ``H5Lvisit`` overflows the C stack on a file of 10,000 nested groups: a crash, not an
    error). ``datasets=False``: links only (a caller that checks each dataset it reads itself,
    with ``check_dataset``: the run index, which reads a few of them per file).
    """
    size = f.id.get_filesize()
    budget = ReadBudget(size)
    seen: set[int] = set()
    queue: list[tuple[h5py.h5g.GroupID, bytes, int]] = [(f.id, b"", 0)]
    count = 0
    while queue:
        gid, prefix, depth = queue.pop()
        entries = _links(gid, MAX_OBJECTS - count)
        count += len(entries)
        if count > MAX_OBJECTS:
            raise RefusedRunFile(f"holds more than {MAX_OBJECTS:,} objects (a run file holds a few hundred)")
        for name, kind in entries:
            path = prefix + name
            if kind != h5py.h5l.TYPE_HARD:
                why = _LINK_KINDS.get(kind, "a user-defined link")
                raise RefusedRunFile(f"{path.decode(errors='replace')} is {why}; run files hold hard links only")
            info = h5py.h5o.get_info(gid, name)  # without opening it
            if info.addr in seen:  # a second hard link to an object already checked
                continue
            seen.add(info.addr)
            if info.type == h5py.h5o.TYPE_GROUP:
                if depth + 1 >= MAX_DEPTH:
                    raise RefusedRunFile(f"nests groups more than {MAX_DEPTH} levels deep (a run file: 2)")
                queue.append((h5py.h5g.open(gid, name), path + b"/", depth + 1))
            elif datasets and info.type == h5py.h5o.TYPE_DATASET:
                check_dataset(path.decode(errors="replace"), h5py.h5d.open(gid, name), size, budget)


def _links(gid: h5py.h5g.GroupID, limit: int) -> list[tuple[bytes, int]]:
    """(name, link type) of a group's links, at most ``limit`` + 1 of them (the iteration stops)."""
    entries: list[tuple[bytes, int]] = []

    def take(name: bytes, info):
        entries.append((name, info.type))
        return True if len(entries) > limit else None  # a value other than None stops HDF5's iteration

    gid.links.iterate(take, info=True)
    return entries


class ReadBudget:
    """Bytes the datasets of one file may declare together (``_TOTAL_RATIO`` x its size): a
    crafted file can point many datasets at the same stored bytes."""

    def __init__(self, file_size: int):
        self.left = _TOTAL_RATIO * file_size + _SLACK_BYTES

    def take(self, name: str, declared: int) -> None:
        self.left -= declared
        if self.left < 0:
            raise RefusedRunFile(f"its datasets declare more than {_TOTAL_RATIO}x the file's size together (at {name})")


_LINK_KINDS = {h5py.h5l.TYPE_SOFT: "a soft link", h5py.h5l.TYPE_EXTERNAL: "an external link (to another file)"}


def check_dataset(name: str, ds: h5py.h5d.DatasetID, file_size: int, budget: ReadBudget | None = None) -> None:
    """Refuse a dataset whose bytes would come from elsewhere, or more bytes than its file holds."""
    plist = ds.get_create_plist()
    if plist.get_layout() == h5py.h5d.VIRTUAL:
        raise RefusedRunFile(f"{name} is a virtual dataset (mapped onto other files)")
    if plist.get_external_count():
        raise RefusedRunFile(f"{name} has external storage (its bytes live in another file)")
    filters = [plist.get_filter(i)[0] for i in range(plist.get_nfilters())]
    unknown = [code for code in filters if code not in _BUILTIN_FILTERS]
    if unknown:
        raise RefusedRunFile(f"{name} needs filter {unknown[0]} (not built into HDF5; no plugin is loaded)")
    declared = ds.dtype.itemsize * math.prod(ds.shape or ())
    bound = file_size * (_COMPRESSION_RATIO if filters else 1) + _SLACK_BYTES
    if declared > bound:
        raise RefusedRunFile(f"{name} declares {declared:,} bytes in a {file_size:,}-byte file")
    if budget is not None:
        budget.take(name, declared)


MAX_CONFIG_BYTES = 256 * 1024  # a run's resolved config is a few KB
MAX_CONFIG_NODES = 50_000  # YAML nodes once aliases are expanded


def parse_config(text: str) -> dict:
    """A stored config (YAML) as a dict, with bounds; ``RefusedRunFile`` beyond them.

    Aliases are counted as often as they are used, so an alias bomb is refused after
    composing its few nodes, before anything is built from it.
    """
    if len(text) > MAX_CONFIG_BYTES:
        raise RefusedRunFile(f"config attribute is {len(text):,} bytes (at most {MAX_CONFIG_BYTES:,})")
    loader = _YamlLoader(text)
    try:
        node = loader.get_single_node()
        if node is not None:
            _count_nodes(node)
        data = loader.construct_document(node) if node is not None else {}
    except yaml.YAMLError as exc:
        raise RefusedRunFile(f"config attribute is not YAML ({' '.join(str(exc).split())[:120]})") from None
    finally:
        loader.dispose()
    if not isinstance(data, dict):
        raise RefusedRunFile(f"config attribute is a {type(data).__name__}, not a mapping")
    return data


def _count_nodes(root) -> None:
    """Expanded size of a composed YAML graph (shared nodes counted per use), memoised."""
    sizes: dict[int, int] = {}

    def size(node, depth: int) -> int:
        if id(node) in sizes:
            return sizes[id(node)]
        if depth > 100:
            raise RefusedRunFile("config attribute nests more than 100 levels")
        sizes[id(node)] = MAX_CONFIG_NODES + 1  # a node reached again through itself (a cycle): too big
        if isinstance(node, yaml.MappingNode):
            n = 1 + sum(size(k, depth + 1) + size(v, depth + 1) for k, v in node.value)
        elif isinstance(node, yaml.SequenceNode):
            n = 1 + sum(size(v, depth + 1) for v in node.value)
        else:
            n = 1
        sizes[id(node)] = n = min(n, MAX_CONFIG_NODES + 1)
        return n

    if size(root, 0) > MAX_CONFIG_NODES:
        raise RefusedRunFile(f"config attribute expands to more than {MAX_CONFIG_NODES:,} YAML nodes (aliases)")


try:  # libyaml's parser when present
    _YamlLoader = yaml.CSafeLoader
except AttributeError:  # pragma: no cover
    _YamlLoader = yaml.SafeLoader


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
    config: dict = field(default_factory=dict, repr=False)  # config_yaml parsed (``parse_config``)
    weights: dict | None = field(default=None, repr=False)  # final weights, read only when asked (``with_weights``)

    @property
    def n_updates(self) -> int:
        """Updates recorded in the per-update table."""
        return int(self.rows.get("updates", {}).get("step", 0))


def read_head(path: str | Path, locking: bool = False, with_weights: bool = False) -> RunHead:
    """The root attributes of a run file; raises ``UnreadableRunFile`` (with the reason),
    ``RunFileLocked`` with ``locking=True`` when a live writer holds the file.

    with_weights: also its final weights (``init_from``: the file is opened once)."""
    p = run_file_path(path)
    if not p.is_file():  # a FIFO or device named *.h5 would block the open forever
        raise UnreadableRunFile(f"{p}: no such run file")
    try:
        with h5py.File(p, "r", locking=locking) as f:
            check_contained(f)
            attrs = {k: _attr(v) for k, v in f.attrs.items()}
            has_weights = _check_weights(f)
            rows = _row_counts(f)
            weights = _weights(f) if with_weights and has_weights else None
        config = parse_config(str(attrs.get("config", "")))
    except Exception as exc:  # noqa: BLE001 - not HDF5, truncated, refused, ...
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
        config=config,
        weights=weights,
    )


def _check_weights(f: h5py.File) -> bool:
    """Whether ``f`` holds final weights; ``RefusedRunFile`` if they are not real numbers."""
    if "weights" not in f:
        return False
    group = f["weights"]
    if not isinstance(group, h5py.Group):
        raise RefusedRunFile("weights is not a group of datasets")
    for name, obj in group.items():
        if not isinstance(obj, h5py.Dataset):
            raise RefusedRunFile(f"weights/{name} is a group, not an array of weights")
        kind = obj.dtype.kind
        if kind not in "fiu":
            what = {"c": "complex numbers", "S": "strings", "U": "strings", "O": "objects or strings", "b": "booleans"}
            raise RefusedRunFile(f"weights/{name} holds {what.get(kind, f'dtype {obj.dtype}')}, not real numbers")
    return len(group) > 0


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
    config: dict = field(default_factory=dict)  # attrs["config"] parsed (``parse_config``)


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
            return tables_of(f, columns)
    except Exception as exc:  # noqa: BLE001 - truncated, garbage, not HDF5, half-written, refused
        raise _unreadable(p, exc) from None


def tables_of(f: h5py.File, columns: dict[str, Sequence[str] | None]) -> RunTables:
    """``read_tables`` of a file already open (its writer's, as it closes it)."""
    check_contained(f, datasets=False)  # _columns checks the datasets it reads
    attrs = {k: _attr(v) for k, v in f.attrs.items()}
    budget = ReadBudget(f.id.get_filesize())
    tables = {group: _columns(f, group, names, budget) for group, names in columns.items()}
    memory = {k: _attr(v) for k, v in f["memory"].attrs.items()} if "memory" in f else {}
    env = {k: _attr(v) for k, v in f["env"].attrs.items()} if "env" in f else {}
    return RunTables(attrs, tables, memory, env, parse_config(str(attrs.get("config") or "{}")))


def _columns(f: h5py.File, group: str, names: Sequence[str] | None, budget: ReadBudget) -> dict[str, np.ndarray]:
    if group not in f:  # an optional group (``final``: completed runs only)
        return {}
    gid = h5py.h5g.open(f.id, group.encode())
    if names is None:
        names = [gid.get_objname_by_idx(i).decode() for i in range(gid.get_num_objs())]
    size = f.id.get_filesize()
    cols = {}
    for name in names:
        try:
            ds = h5py.h5d.open(gid, name.encode())
        except KeyError:
            continue
        if len(ds.shape) != 1 or ds.dtype.kind not in "fiub":
            continue
        check_dataset(f"{group}/{name}", ds, size, budget)
        values = np.empty(ds.shape, dtype=ds.dtype)
        if values.size:
            ds.read(h5py.h5s.ALL, h5py.h5s.ALL, values)
        cols[name] = values
    return cols


def _attr(value):
    return value.decode() if isinstance(value, bytes) else (value.item() if isinstance(value, np.generic) else value)


def _open(path: str | Path) -> h5py.File:
    """Open a run file to read, refusing content that leaves it (``check_contained``)."""
    f = h5py.File(path, "r", locking=False)
    try:
        check_contained(f)
    except BaseException:
        f.close()
        raise
    return f


_NUMERIC_ATTRS = {"steps": int, "status_step": int, "format_version": int, "wall_time": float}


def read_meta(f: h5py.File) -> dict:
    meta = {k: _attr(v) for k, v in f.attrs.items()}
    for key, kind in _NUMERIC_ATTRS.items():  # older files may hold these as text
        if isinstance(meta.get(key), str):
            try:
                meta[key] = kind(float(meta[key])) if kind is int else kind(meta[key])
            except ValueError:
                pass
    meta["config"] = parse_config(str(meta.get("config") or "{}"))
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


def load_final(path: str | Path) -> dict[str, np.ndarray]:
    """Arrays of the final evaluation, e.g. ``test_losses`` (one per test sample); {} when the
    run recorded none (it was interrupted, failed, or is older than this record)."""
    with _open(path) as f:
        return {name: _native(ds[()]) for name, ds in f["final"].items()} if "final" in f else {}


def load_weights(path: str | Path) -> dict[str, np.ndarray]:
    """Final weights as {state_dict name: array}; ``RefusedRunFile`` if they are not arrays of
    real numbers (complex ones would lose their imaginary part in a real network)."""
    with _open(path) as f:
        if not _check_weights(f):
            raise KeyError(f"{path}: no final weights stored (status {_attr(f.attrs.get('status', '?'))})")
        return _weights(f)


def _weights(f: h5py.File) -> dict[str, np.ndarray]:
    return {name: _native(ds[()]) for name, ds in f["weights"].items()}


def _native(values: np.ndarray) -> np.ndarray:
    """An array in this machine's byte order (torch takes no big-endian weights)."""
    values = np.asarray(values)
    return values if values.dtype.isnative else values.astype(values.dtype.newbyteorder("="))
