"""The results index: every run file under a root as one pandas table.

    runs = load_runs("outputs")                       # one row per run file
    runs, curves = load_runs("outputs", curves=True)  # + one row per (run, evaluation)
    best_runs(runs, by="optimizer.name")              # table-2 selection, per problem

``runs`` has the flattened config (``problem.name``, ``optimizer.lr``, ``batch_size``, ...),
``path``, ``source``, ``status``, ``overrides``, ``steps``, ``train_time_s`` (the training
clock at the end: evaluations excluded), ``final_test_loss``,
``best_test_loss``, ``time_to_<target>`` (training clock at the first evaluation whose
test loss is at or below the target: ``targets.reach_index``; by default each run's own
problem's targets, ``targets.for_problem``), ``mean_update_s``, ``peak_rss_mb``, ``env.*``,
``cond_kept_median``, ``cond_kept_max``, ``sv_dropped_mean`` (GN/HIG/LM: the steps'
conditioning, ``higbench.results.spectrum``; NaN for other runs),
``config_id`` (the run's identity: resolved config without ``COSMETIC_KEYS``),
``setting_config`` (what makes its optimizer setting: ``setting_config``; seeds of one
setting share it).

This is the one run index: ``make figures`` finds its runs here too (``one_per_config``,
``DONE_STATUSES``). Files are read through ``higbench.runfile.read_tables``.

A file that cannot be read never stops the index; it becomes a row with a ``status`` of
``running`` (another process holds it open for writing, or the writer died with the file
open; see ``error``) or ``corrupt`` (truncated, not an HDF5 run file), and ``error`` says why.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from higbench.cards import without_card  # how an optimizer is shown is no part of a run
from higbench.config import COSMETIC_KEYS  # identity=False in the schema: not part of config_id
from higbench.display import BUSY_SHARE
from higbench.problems.base import ProblemConfig
from higbench.results.spectrum import CONDITIONING_COLUMNS, UPDATE_SPECTRUM_COLUMNS, conditioning
from higbench.results.targets import for_problem, reach_index
from higbench.runfile.reader import (
    RUN_FILE_GLOB,
    SUMMARY_COLUMNS,
    RunFileLocked,
    RunFileOpenForWrite,
    RunTables,
    UnreadableRunFile,
    load_run,
    read_tables,
    run_file_path,
)
from higbench.schema import keys_where

PROBLEM_COSMETIC_KEYS = keys_where(ProblemConfig, "identity", False)  # problem.* keys outside config_id
# The one status rule. A done run ended by its own rule and is a result: never run again
# (a diverged run is a result too). Only completed runs compete in ``best_runs`` (a diverged
# run's last finite loss is not what it reached). Anything else (running, interrupted,
# failed, corrupt) is not a result: the figures run it again.
DONE_STATUSES = ("completed", "diverged")
RUN_STATUSES_DONE = ("completed",)  # the statuses ``best_runs`` selects from

# Columns the index computes; a config key of the same name is stored as "config.<key>".
_OWN_COLUMNS = {
    "path", "status", "status_reason", "status_step", "error", "problem", "optimizer", "overrides",
    "started", "finished", "steps", "wall_time", "n_evals", "final_step", "final_train_loss", "final_val_loss", "best_val_loss",
    "best_test_loss", "best_step", "mean_update_s", "median_update_s", "mean_jacobian_s",
    "mean_inversion_s", "peak_rss_mb", "baseline_rss_mb", "cuda_peak_mb", "format_version", "resumes",
    "config_id", "parallel_jobs", "setting_config", *CONDITIONING_COLUMNS,
}  # fmt: skip

# Config keys that never make a different optimizer setting: the seed is what a comparison's
# median runs over, the budget and the evaluation schedule are what settings are compared
# within, and the schema's cosmetic keys (threads, progress, tensorboard, checkpoints, ...:
# identity=False, and the problem's: PROBLEM_COSMETIC_KEYS) change no result. Everything else
# does (problem.gamma, dtype, amsgrad, ...).
NOT_SETTING_KEYS = ("seed", "budget", "eval_every", "eval_unit", *COSMETIC_KEYS)


def config_id(config: dict, parent_id: str | None = None) -> str:
    """The identity of a run: a hash of its resolved config without ``COSMETIC_KEYS`` and its
    optimizer's card (``higbench.cards``: how it is shown, the same before cards existed).

    ``init_from`` (a path) is replaced by ``parent_id``, the identity of the run it starts
    from, so a continued run keeps its identity wherever its parent's file lies.
    """
    c = {k: v for k, v in without_card(config).items() if k not in COSMETIC_KEYS}
    if isinstance(c.get("problem"), dict):  # the problem's own such keys (validation size, targets, ...)
        c["problem"] = {k: v for k, v in c["problem"].items() if k not in PROBLEM_COSMETIC_KEYS}
    if c.get("init_from"):
        c["init_from"] = {"run": parent_id or f"path:{c['init_from']}"}
    text = json.dumps(c, sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def setting_config(config: dict, device: str | None = None) -> str:
    """A run's setting: its flattened config without ``NOT_SETTING_KEYS``, as sorted JSON.

    ``device`` is the device the run used (the environment's), which replaces the config's
    (``auto`` resolves to ``cpu`` on a CPU-only machine: the same setting as ``device=cpu``).
    Runs with equal strings are seeds of one setting (``profile.setting_labels``).
    """
    kept = {k: v for k, v in without_card(config).items() if k not in NOT_SETTING_KEYS}
    if isinstance(kept.get("problem"), dict):  # the problem's own such keys (targets, validation size, ...)
        kept["problem"] = {k: v for k, v in kept["problem"].items() if k not in PROBLEM_COSMETIC_KEYS}
    if device:
        kept["device"] = device.split(":")[0]
    return json.dumps(_flatten(kept), sort_keys=True, default=str)


TIME_TO_PREFIX = "time_to_"  # the time-to-target columns: TIME_TO_PREFIX + the target


def threshold_column(threshold: float) -> str:
    """Column name of a threshold: 1e-2 -> 'time_to_1e-2', 3e-4 -> 'time_to_3e-4'."""
    mantissa, exponent = f"{threshold:e}".split("e")
    mantissa = mantissa.rstrip("0").rstrip(".")
    return f"{TIME_TO_PREFIX}{mantissa}e{int(exponent)}"


def find_run_files(root: str | Path | Iterable[str | Path], pattern: str = RUN_FILE_GLOB) -> list[Path]:
    """Run files under ``root`` (a directory, a file, or several of them), sorted."""
    roots = [root] if isinstance(root, (str, os.PathLike)) else list(root)
    found: set[Path] = set()
    for r in roots:
        r = Path(r)
        if r.is_file():
            found.add(r)
        elif r.is_dir():
            inside = r.resolve()  # a link to a file outside the tree given is never followed
            found.update(p for p in r.rglob(pattern) if p.is_file() and (not p.is_symlink() or inside in p.resolve().parents))
        else:
            raise FileNotFoundError(f"{r}: no such file or directory")
    return sorted(found)


def unreadable_dirs(root: str | Path | Iterable[str | Path]) -> list[tuple[Path, str]]:
    """Directories under ``root`` that cannot be listed (runs in them would be missed
    silently): (directory, why), each a ``corrupt`` row of the index, as an unreadable file is."""
    roots = [root] if isinstance(root, (str, os.PathLike)) else list(root)
    bad: list[tuple[Path, str]] = []

    def note(exc: OSError) -> None:
        bad.append((Path(exc.filename), f"directory cannot be read ({exc.strerror}); run files in it are not indexed"))

    for r in roots:
        if Path(r).is_dir():
            for _ in os.walk(r, onerror=note):
                pass
    return sorted(bad)


# -- reading one file ------------------------------------------------------------------------


def _flatten(d: dict, prefix: str = "", out: dict | None = None) -> dict:
    out = {} if out is None else out
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            if v:
                _flatten(v, key + ".", out)
            else:
                out[key] = None
        elif isinstance(v, list):
            out[key] = tuple(v)
        else:
            out[key] = v
    return out


def _cut(cols: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    """Columns cut to a common length (a killed writer may leave them ragged) and, if they
    were ragged, {column: length} of the longer ones plus ``kept``."""
    if not cols:
        return cols, {}
    n = min(len(v) for v in cols.values())
    ragged = {k: len(v) for k, v in cols.items() if len(v) != n}
    return {k: v[:n] for k, v in cols.items()}, (ragged | {"kept": n} if ragged else {})


def _mean(values: np.ndarray | None) -> float:
    if values is None or len(values) == 0:
        return math.nan
    return float(np.mean(values))


def final_test_spread(per_sample: np.ndarray | None, fresh: np.ndarray | None = None) -> dict[str, float]:
    """The final evaluation's test losses sample by sample (/final/test_losses) as a median
    and a 95th percentile, and the mean over the problem's large fresh draw
    (/final/fresh_test_losses, ``problem.fresh_test_size``): a mean carried by a few samples (the
    oscillator's heavy tail) is then seen for what it is. NaN for runs that recorded none
    (interrupted, older files, problems without a fresh draw)."""
    row = {"final_test_median": math.nan, "final_test_p95": math.nan, "final_fresh_mean": math.nan}
    with np.errstate(invalid="ignore"):  # a diverged run's inf losses: inf or NaN, without a warning
        if per_sample is not None and len(per_sample):
            row["final_test_median"] = float(np.median(per_sample))
            row["final_test_p95"] = float(np.percentile(per_sample, 95))
        if fresh is not None and len(fresh):
            row["final_fresh_mean"] = float(np.mean(fresh))
    return row


def _summarise(
    run: RunTables, thresholds: Sequence[float] | None, want_curves: bool
) -> tuple[dict, dict[str, np.ndarray] | None]:
    attrs = dict(run.attrs)
    if "format_version" not in attrs or "config" not in attrs:
        raise ValueError("not a higbench run file (no format_version/config attributes)")
    attrs.pop("config")
    config = run.config  # parsed by the reader, with bounds (an alias bomb is refused there)
    if thresholds is None:  # the run's own problem's targets (stored, else shipped)
        thresholds = for_problem(config if isinstance(config, dict) else attrs.get("problem", ""))
    row = _record_columns(config, attrs)
    curves, ragged = _cut(run.tables.get("curves", {}))
    if ragged:  # a writer stopped between columns: the last full row is the final one
        kept = ragged.pop("kept")
        longer = ", ".join(f"{k} ({v})" for k, v in sorted(ragged.items()))
        row["curves_note"] = f"curve columns differ in length: {longer}; final values taken at row {kept} of each"
    row.update(_curve_columns(curves, thresholds, row))
    final = run.tables.get("final", {})
    row.update(final_test_spread(final.get("test_losses"), final.get("fresh_test_losses")))
    row.update(_update_columns(run.tables.get("updates", {})))
    row.update(run.memory)
    if isinstance(config, dict):
        row["setting_config"] = setting_config(config, run.env.get("device"))
    for key, value in run.env.items():
        row[f"env.{key}"] = value
    # Runs of a sweep that shared the machine (a joblib launcher's parallel jobs): their
    # wall-clock budgets bought less compute each. NaN for files that predate the record.
    row["parallel_jobs"] = float(run.env.get("parallel_jobs", math.nan))
    return row, (curves if want_curves else None)


_RECORD_ATTRS = ("status", "status_reason", "status_step", "problem", "optimizer", "started", "finished", "steps",
                 "wall_time", "format_version")  # fmt: skip


def _record_columns(config, attrs: dict) -> dict:
    """The run's identity and record: its config (flattened), overrides, resumes and status."""
    row: dict = {"config_id": config_id(config) if isinstance(config, dict) else None}
    if isinstance(config, dict) and config.get("init_from"):
        row["_config"] = config  # config_id is set again once its parent is known (load_runs)
    for key, value in _flatten(config).items():
        row[f"config.{key}" if key in _OWN_COLUMNS else key] = value
    try:
        overrides = json.loads(attrs.pop("overrides", "[]"))
    except ValueError:
        overrides = []
    row["overrides"] = " ".join(overrides)
    try:
        row["resumes"] = len(json.loads(attrs.pop("resumes", "[]")))  # times the run was resumed
    except ValueError:
        row["resumes"] = 0
    row.update({key: attrs[key] for key in _RECORD_ATTRS if key in attrs})
    return row


def _curve_columns(curves: dict[str, np.ndarray], thresholds: Sequence[float], record: dict) -> dict:
    """Final and best losses, and the wall clock to each threshold, from the evaluation curves
    (``record``: the columns so far; the curves stand in for a wall time or steps it lacks)."""
    test = curves.get("test_loss")
    row: dict = {"n_evals": 0 if test is None else len(test)}
    if not row["n_evals"]:
        return row | {threshold_column(t): math.nan for t in thresholds}
    wall, steps = curves.get("wall_time"), curves.get("step")
    row["final_test_loss"] = float(test[-1])
    finite = np.isfinite(test)
    if finite.any():
        i = int(np.argmin(np.where(finite, test, np.inf)))
        row["best_test_loss"] = float(test[i])
        row["best_step"] = int(steps[i]) if steps is not None else i
    if steps is not None:
        row["final_step"] = int(steps[-1])
    if "train_loss" in curves:
        row["final_train_loss"] = float(curves["train_loss"][-1])
    if "val_loss" in curves:  # the validation split (what tuning reads): final and best
        val = curves["val_loss"]
        row["final_val_loss"] = float(val[-1])
        row["best_val_loss"] = float(np.nanmin(val)) if np.isfinite(val).any() else math.nan
    for name, values in curves.items():  # extra metrics: final_test_<metric>
        if name.startswith("test_") and name != "test_loss":
            row[f"final_{name}"] = float(values[-1])
    if "wall_time" not in record and wall is not None:
        row["wall_time"] = float(wall[-1])
    if "steps" not in record and steps is not None:
        row["steps"] = int(steps[-1])
    for t in thresholds:
        i = reach_index(test, t)
        row[threshold_column(t)] = float(wall[i]) if (i is not None and wall is not None) else math.nan
    return row


def _update_columns(raw: dict[str, np.ndarray]) -> dict:
    """Mean and median update times, and the conditioning, from the per-update table."""
    # Spectrum columns cut apart: they may be shorter than the timings (a file from before they
    # were recorded, resumed by a version that records them), which must not shorten those.
    updates, _ = _cut({k: v for k, v in raw.items() if k not in UPDATE_SPECTRUM_COLUMNS})
    update_s = updates.get("update_s")
    row = {
        "mean_update_s": _mean(update_s),
        "median_update_s": float(np.median(update_s)) if update_s is not None and len(update_s) else math.nan,
        "mean_jacobian_s": _mean(updates.get("jacobian_s")),
        "mean_inversion_s": _mean(updates.get("inversion_s")),
    }
    return row | conditioning(_cut({k: raw[k] for k in UPDATE_SPECTRUM_COLUMNS if k in raw})[0])  # else NaN


def read_run_summary(
    path: str | Path, thresholds: Sequence[float] | None = None, curves: bool = False, tables: RunTables | None = None
) -> tuple[dict, dict | None]:
    """(row, curve columns or None) of one run file; never raises for an unreadable file.
    thresholds: the ``time_to_<t>`` levels (None: the run's problem's targets). tables: its
    ``SUMMARY_COLUMNS`` as its writer kept them closing it (the file is then not read)."""
    path = Path(path)
    row: dict = {"path": str(path), "error": ""}
    wanted = {**SUMMARY_COLUMNS, "curves": None} if curves else SUMMARY_COLUMNS
    try:
        read = tables if tables is not None and not curves else read_tables(path, wanted)
        summary, columns = _summarise(read, thresholds, curves)
        note = summary.pop("curves_note", "")
        row.update(summary)
        if row.get("status") == "running":
            if os.environ.get("HDF5_USE_FILE_LOCKING", "").upper() in ("FALSE", "0"):
                row["error"] = "status is running (HDF5 file locking is off: a live writer and a killed one look alike)"
            else:  # we could take the file lock, so no process on this host is writing it
                row["error"] = "status is running but no writer holds the file: still running on another host, or killed"
        row["error"] = "; ".join(x for x in (row["error"], note) if x)
        return row, columns
    except RunFileLocked:
        # Locked by a live writer. Files written without SWMR can still be read unlocked up to
        # the last flush (HDF5 refuses when the file carries the 'open for write' flag).
        try:
            summary, columns = _summarise(read_tables(path, wanted, locking=False), thresholds, curves)
            row.update(summary)
            row["status"] = "running"
            row["error"] = "being written (file locked by another process); read up to its last flush"
            return row, columns
        except Exception:  # noqa: BLE001 - anything from a half-written file
            row.update(status="running", error="being written (file locked by another process)")
            return row, None
    except RunFileOpenForWrite as exc:  # the writer is alive elsewhere, or died without closing the file
        row.update(status="running", error=exc.detail)
        return row, None
    except UnreadableRunFile as exc:  # truncated, garbage, not HDF5, half-written
        row.update(status="corrupt", error=exc.detail)
        return row, None
    except Exception as exc:  # noqa: BLE001 - an HDF5 file that is not a run file
        row.update(status="corrupt", error=f"{type(exc).__name__}: {exc}")
        return row, None


# -- the index -------------------------------------------------------------------------------


_ALWAYS = (
    "path",
    "status",
    "error",
    "overrides",
    "problem.name",
    "optimizer.name",
    "steps",
    "wall_time",
    "final_test_loss",
    "best_test_loss",
    "config_id",
)
_NUMERIC = ("steps", "wall_time", "final_test_loss", "best_test_loss")


# Renamed for the table: the run file's root attribute `wall_time` is the training clock.
_RENAMED = {"wall_time": "train_time_s"}
# Kept in the row dict (read_run_summary) but not in the table: duplicates of other columns
# (`problem.name`, `optimizer.name`; `final_step` is `steps` except for a run stopped between
# evaluations, where `status_step` and the curves tell).
_DROPPED = ("problem", "optimizer", "final_step")
FIGURE_RUNS_DIR = "figures-runs"  # where `make figures` puts its runs (higbench/jobs.py)


def _number(text: str) -> int | float:
    try:
        return int(text)
    except ValueError:
        try:
            return float(text)
        except ValueError:
            return math.nan


def _integer_columns(rows: list[dict]) -> set[str]:
    """Columns whose values are all ints (bools aside): kept as integers despite missing values."""
    seen: dict[str, bool] = {}
    for row in rows:
        for k, v in row.items():
            if v is None or (isinstance(v, float) and math.isnan(v)):
                continue
            seen[k] = seen.get(k, True) and isinstance(v, int | np.integer) and not isinstance(v, bool | np.bool_)
    return {k for k, ok in seen.items() if ok}


def _frame(rows: list[dict]) -> pd.DataFrame:
    for row in rows:  # runs whose config lacks the name (old files): take it from the root attribute
        for key in ("problem", "optimizer"):
            if row.get(f"{key}.name") is None and row.get(key) is not None:
                row[f"{key}.name"] = row[key]
    for row in rows:  # files written before numbers were stored as numbers held them as text
        for key in _NUMERIC:
            if isinstance(row.get(key), str):
                row[key] = _number(row[key])
    integers = _integer_columns(rows)
    df = pd.DataFrame.from_records(rows)
    df = df.drop(columns=[c for c in _DROPPED if c in df.columns])
    for col in integers & set(df.columns):
        if df[col].dtype.kind == "f":  # ints with a missing value: pandas' nullable integers
            df[col] = df[col].astype("Int64")
    for col in _ALWAYS:  # present even when no file could be read
        if col not in df.columns:
            df[col] = pd.Series(
                np.nan if col in _NUMERIC else None, index=df.index, dtype="float64" if col in _NUMERIC else "object"
            )
    first = [c for c in ("path", "status", "problem.name", "optimizer.name", "overrides") if c in df.columns]
    return df[first + [c for c in df.columns if c not in first]].rename(columns=_RENAMED)


def _curves_frame(parts: list[tuple[str, dict[str, np.ndarray]]]) -> pd.DataFrame:
    names: list[str] = []
    for _, cols in parts:
        names.extend(c for c in cols if c not in names)
    lengths = [len(next(iter(cols.values()))) if cols else 0 for _, cols in parts]
    total = sum(lengths)
    data: dict[str, np.ndarray | pd.Categorical] = {}
    paths = [p for p, _ in parts]
    codes = np.repeat(np.arange(len(parts)), lengths)
    data["path"] = pd.Categorical.from_codes(codes, categories=pd.Index(paths)) if paths else pd.Categorical([])
    for name in names:
        chunks = [cols[name] if name in cols else np.full(n, np.nan) for (_, cols), n in zip(parts, lengths)]
        data[name] = np.concatenate(chunks) if chunks else np.empty(0)
    df = pd.DataFrame(data, index=pd.RangeIndex(total))
    for col in ("step", "epoch"):
        if col in df and np.isfinite(df[col].to_numpy(dtype=float)).all():
            df[col] = df[col].astype("int64")
    return df


def _read_chunk(paths: list[Path], thresholds: Sequence[float] | None, curves: bool) -> list[tuple[dict, dict | None]]:
    return [read_run_summary(p, thresholds, curves) for p in paths]


def load_runs(
    root: str | Path | Iterable[str | Path],
    curves: bool = False,
    thresholds: Sequence[float] | None = None,
    pattern: str = RUN_FILE_GLOB,
    jobs: int = 1,
    figure_runs: bool = False,
) -> pd.DataFrame | tuple[pd.DataFrame, pd.DataFrame]:
    """One row per run file under ``root``; with ``curves=True`` also the long curves table.

    thresholds: test-loss levels for the ``time_to_<t>`` columns (training-clock seconds at
    the first evaluation at or below ``t``; NaN if never reached); None (default): each run's
    own problem's targets (``targets.for_problem``), so a row has its problem's columns.
    jobs: processes reading files (reading is HDF5-bound, a few ms per file; worth it for
    thousands of files on several cores).
    figure_runs: also index the runs `make figures` made (under a ``figures-runs`` folder
    below a root; often smoke-preset budgets). Off by default, so a table of your runs is
    not mixed with them; a root that is itself inside ``figures-runs`` is always indexed.
    The ``source`` column says ``figures`` or ``runs``.
    Returns ``runs`` or ``(runs, curves)``; ``curves`` has one row per (run, evaluation):
    ``path`` (join key with ``runs``), ``step``, ``epoch``, ``wall_time``, ``train_loss``,
    ``test_loss``, ``rss_mb`` and any extra ``test_<metric>``.
    """
    paths = find_run_files(root, pattern)
    roots = [Path(root)] if isinstance(root, str | Path) else [Path(r) for r in root]
    if not figure_runs:
        paths = [p for p in paths if not under_figure_runs(p, roots)]
    if jobs > 1 and len(paths) > 2 * jobs:
        from concurrent.futures import ProcessPoolExecutor

        size = -(-len(paths) // (4 * jobs))
        chunks = [paths[i : i + size] for i in range(0, len(paths), size)]
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            results = [
                r for part in pool.map(_read_chunk, chunks, [thresholds] * len(chunks), [curves] * len(chunks)) for r in part
            ]
    else:
        results = _read_chunk(paths, thresholds, curves)
    results += [({"path": str(d), "status": "corrupt", "error": why}, None) for d, why in unreadable_dirs(root)]
    for row, _ in results:
        row["source"] = "figures" if FIGURE_RUNS_DIR in Path(row["path"]).parts else "runs"
    _chain_ids([row for row, _ in results])
    runs = _frame([row for row, _ in results])
    if not curves:
        return runs
    return runs, _curves_frame([(row["path"], cols) for row, cols in results if cols])


def _chain_ids(rows: list[dict]) -> None:
    """``config_id`` of runs started from another run (``init_from``): with their parent's
    identity when the parent is among ``rows`` (followed up the chain)."""
    by_path = {Path(r["path"]).resolve(): r for r in rows}

    def ident(row: dict, seen: frozenset) -> str | None:
        config = row.pop("_config", None)
        if config is None:
            return row.get("config_id")
        parent = by_path.get(run_file_path(str(config["init_from"])).resolve())
        parent_id = ident(parent, seen | {id(row)}) if parent is not None and id(parent) not in seen else None
        row["config_id"] = config_id(config, parent_id)
        return row["config_id"]

    for row in rows:
        ident(row, frozenset())


def one_per_config(runs: pd.DataFrame) -> pd.DataFrame:
    """One run per ``config_id`` (the rule for duplicates of the same config): the newest done
    run (``DONE_STATUSES``; newest by ``finished``), else the run furthest along (most training
    clock, ``train_time_s``: the one worth resuming), then the newest (by ``started``). Rows without
    a ``config_id`` (unreadable files) are left out."""
    if runs.empty:
        return runs
    df = runs[runs["config_id"].notna()]

    def when(col: str) -> pd.Series:
        if col not in df:
            return pd.Series(pd.NaT, index=df.index, dtype="datetime64[ns, UTC]")
        return pd.to_datetime(df[col], utc=True, errors="coerce", format="%Y-%m-%dT%H:%M:%S%z")

    done = df["status"].isin(DONE_STATUSES)
    clock = pd.to_numeric(df.get("train_time_s", pd.Series(float("nan"), index=df.index)), errors="coerce")
    order = df.assign(_done=done, _along=clock.where(~done), _when=when("finished").fillna(when("started"))).sort_values(
        ["config_id", "_done", "_along", "_when", "path"], ascending=[True, False, False, False, False], na_position="last"
    )
    return order.groupby("config_id", sort=False).head(1).drop(columns=["_done", "_along", "_when"])


def under_figure_runs(path: Path, roots: list[Path]) -> bool:
    """Whether ``path`` lies in a figures-runs folder below the root it was found under."""
    for r in roots:
        try:
            rel = path.relative_to(r)
        except ValueError:
            continue
        return FIGURE_RUNS_DIR in rel.parts[:-1]
    return False


def load_curves(root: str | Path | Iterable[str | Path], pattern: str = RUN_FILE_GLOB) -> pd.DataFrame:
    """The long curves table alone (see ``load_runs``)."""
    return load_runs(root, curves=True, pattern=pattern)[1]


def best_runs(
    df: pd.DataFrame, by: str | Sequence[str] = "optimizer.name", metric: str = "final_test_loss", per_problem: bool = True
) -> pd.DataFrame:
    """The best completed run per group (lowest ``metric``): the table-2 selection.

    Only runs with status ``completed`` and a finite ``metric`` compete, so diverged,
    interrupted, failed, running and corrupt runs are never selected. Losses of different
    problems do not compare: with ``per_problem`` (default) the groups are also split by
    ``problem.name`` (and ``problem.model``, where runs have it).
    """
    keys = [by] if isinstance(by, str) else list(by)
    if per_problem:
        keys = [k for k in ("problem.name", "problem.model") if k in df.columns and k not in keys] + keys
    missing = [k for k in [*keys, metric, "status"] if k not in df.columns]
    if missing:
        raise KeyError(f"best_runs: no column(s) {missing} in the runs table")
    values = pd.to_numeric(df[metric], errors="coerce")
    ok = df["status"].isin(RUN_STATUSES_DONE) & np.isfinite(values.to_numpy(dtype=float, na_value=np.nan))
    candidates = df[ok].assign(_metric=values[ok])
    if candidates.empty:
        return df.iloc[0:0]
    best = candidates.sort_values([*keys, "_metric", "path"]).groupby(keys, sort=True, dropna=False).head(1)
    return best.drop(columns="_metric").sort_values(keys).reset_index(drop=True)


def best_settings(
    df: pd.DataFrame,
    by: str | Sequence[str] = "optimizer.name",
    metric: str = "final_test_loss",
    per_problem: bool = True,
    setting: str = "setting",
) -> pd.DataFrame:
    """The best setting per group, judged by its seeds: one row per group.

    A setting is the runs that share the ``setting`` column (their seeds). Its completed runs
    with a ``metric``, and its diverged runs (counted as inf: the worst), are its seeds: their
    median (``<metric>_median``), count (``seeds``), least and greatest (``<metric>_min``,
    ``<metric>_max``), and ``diverged_seeds``; its other runs (interrupted, failed, ...) are
    counted in ``runs_not_completed``. The setting with the
    lowest median wins its group (ties: more seeds, then the label). Groups as in
    ``best_runs``. Other numeric columns (steps, times, conditioning) are medians over the
    seeds; ``busy_seeds`` counts seeds that had under ``display.BUSY_SHARE`` of their cores.
    """
    keys = [by] if isinstance(by, str) else list(by)
    if per_problem:
        keys = [k for k in ("problem.name", "problem.model") if k in df.columns and k not in keys] + keys
    missing = [k for k in [*keys, metric, "status", setting] if k not in df.columns]
    if missing:
        raise KeyError(f"best_settings: no column(s) {missing} in the runs table")
    values = pd.to_numeric(df[metric], errors="coerce")
    # A diverged seed is a seed that ended worst, not one to leave out: otherwise a setting whose
    # seeds mostly diverge would win on its one survivor.
    values = values.where(df["status"] != "diverged", math.inf)
    ok = df["status"].isin(DONE_STATUSES) & ~np.isnan(values.to_numpy(dtype=float, na_value=np.nan))
    seeds = df[ok].assign(_metric=values[ok])
    if seeds.empty:
        return df.iloc[0:0]
    group = [*dict.fromkeys([*keys, setting])]
    grouped = seeds.groupby(group, sort=True, dropna=False)
    rows = grouped["_metric"].agg(["median", "count", "min", "max"])
    rows.columns = [f"{metric}_median", "seeds", f"{metric}_min", f"{metric}_max"]
    firsts = [c for c in ("optimizer.name", "optimizer.lr", "batch_size", "budget") if c in seeds and c not in group]
    rows = rows.join(grouped[firsts].first()) if firsts else rows
    medians = [c for c in ("steps", "train_time_s", *_time_and_conditioning(seeds)) if c in seeds and c != metric]
    if medians:
        rows = rows.join(grouped[medians].agg(_median_over_seeds))
    if "env.cpu_share" in seeds:
        share = pd.to_numeric(seeds["env.cpu_share"], errors="coerce")
        rows = rows.join((share < BUSY_SHARE).groupby([seeds[k] for k in group], dropna=False).sum().rename("busy_seeds"))
    rows = rows.join(
        (seeds["status"] == "diverged").groupby([seeds[k] for k in group], dropna=False).sum().rename("diverged_seeds")
    )
    all_runs = df.groupby(group, sort=True, dropna=False).size().rename("_runs")
    rows = rows.join(all_runs)
    rows["runs_not_completed"] = rows.pop("_runs") - rows["seeds"]
    rows = rows.reset_index()
    rows["_label"] = rows[setting].astype(str)
    rows = rows.sort_values([*keys, f"{metric}_median", "seeds", "_label"], ascending=[*[True] * len(keys), True, False, True])
    best = rows.groupby(keys, sort=True, dropna=False).head(1).drop(columns="_label")
    return best.sort_values(keys).reset_index(drop=True)


def _median_over_seeds(values: pd.Series) -> float:
    """The median of one column over a setting's seeds; a time_to_<t> that a seed never
    reached counts as never (so 2 of 3 seeds never reaching it make the median never: NaN)."""
    numbers = pd.to_numeric(values, errors="coerce")
    if str(values.name).startswith("time_to_"):
        numbers = numbers.fillna(math.inf)
    median = float(numbers.median())
    return median if math.isfinite(median) else math.nan


def _time_and_conditioning(df: pd.DataFrame) -> list[str]:
    return [c for c in df.columns if c.startswith("time_to_") or c in CONDITIONING_COLUMNS]


def cpu_uses(paths: Iterable[str | Path]) -> list[tuple[float, str]]:
    """(CPU share, load at the end) of each readable run file that records them (env/cpu_share):
    what the closing lines of sweeps and figure builds judge the machine's load from."""
    uses = []
    for path in paths:
        try:
            env = load_run(path)[0]["env"]
        except Exception:  # noqa: BLE001 - a failed job's missing or half-written file: nothing to say
            continue
        if "cpu_share" in env:
            uses.append((float(env["cpu_share"]), str(env.get("load_at_finish", ""))))
    return uses
