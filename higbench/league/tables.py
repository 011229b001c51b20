"""The league's tables: what a root carries to another machine, and what the scorer reads.

    export(root)                      # ROOT/tables/runs.csv.gz and ROOT/tables/curves.csv.gz
    runs, curves = read([root_a, root_b])
    league.league_frames(runs, curves, spaces)   # as from load_runs(root, curves=True)

The contract with the scorer (``higbench.results.league``). ``runs.csv.gz``: one row per league
run and role (a run that served two roles has two rows), the columns of
``higbench.results.index.load_runs`` named in ``RUN_COLUMNS`` with their meanings there,
``path`` replaced by ``run`` (the run file's path relative to the root), and the league's own:
``identity`` (the job identity, ``config_id``), ``league_role`` (tune, confirm, paper or
default: the problem's shipped settings where it has none of the paper's; target-tune and
target: the target setting's reference trials and reruns),
``league_job`` (``tune/toy/adam/0/3``: role, problem, optimizer, study, trial; confirmation
jobs name their variant), ``study`` and ``trial`` (tuning runs), ``task``, ``hardware``
(``tables.hardware``) and ``env.load_1min``; ``env.hostname``, ``env.boot_time`` and
``env.cpu_model`` say which machine of that class (``MACHINE_COLUMNS``: tables written before
runs recorded them lack them, and read them as empty). ``curves.csv.gz``: one row per (run,
evaluation): ``run``, ``step``, ``wall_time``, ``train_loss``, ``val_loss`` (where the run file
has it) and ``test_loss``. Floats at full precision; gzip.

``read`` gives back the frames ``load_runs`` gives (a ``path`` per run, ``ROOT/run``, the join
key with the curves), with ``root`` per row, so roots trained on different machines merge into
one score and each row keeps its hardware. Export is cumulative: rows of runs whose files are
gone (a root brought back without them) stay in the tables.
"""

from __future__ import annotations

import io
import json
import math
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path

import pandas as pd

from higbench.league.files import ROOT_FILE_ERRORS, read_bytes, read_json_files, safe_dir, write_bytes
from higbench.results.league import ROLES

TABLES_DIR = "tables"
RUNS_TABLE = "runs.csv.gz"
CURVES_TABLE = "curves.csv.gz"
RUN_COLUMNS = (
    "run", "identity", "league_role", "league_job", "study", "trial", "seed", "problem.name", "task", "optimizer.name",
    "overrides", "setting_config", "config_id", "status", "final_val_loss", "final_test_loss", "steps", "train_time_s",
    "hardware", "env.cpu_share", "env.load_1min", "env.device", "env.device_name", "env.cpu_count", "env.torch_threads",
    "env.git_revision", "started", "finished", "problem.targets", "env.hostname", "env.boot_time", "env.cpu_model",
)  # fmt: skip
# which machine trained a run: tables written before runs recorded it lack these columns (read as empty)
MACHINE_COLUMNS = ("env.hostname", "env.boot_time", "env.cpu_model")
CURVE_COLUMNS = ("run", "step", "wall_time", "train_loss", "val_loss", "test_loss")


def hardware(runs: pd.DataFrame) -> pd.Series:
    """Per run, what it trained on: the GPU's name, else 'CPU, N cores' (the machine's count)."""
    gpu = runs.get("env.device_name", pd.Series("", index=runs.index)).fillna("").astype(str)
    cores = pd.to_numeric(runs.get("env.cpu_count"), errors="coerce").fillna(0).astype(int)
    on_gpu = runs.get("env.device", pd.Series("cpu", index=runs.index)).fillna("cpu").astype(str).str.startswith("cuda")
    return gpu.where(on_gpu, "CPU, " + cores.astype(str) + " cores")


def load_1min(value) -> float:
    """The 1-minute load of a run's ``env.load_at_finish`` ('11.87 11.99 10.86' -> 11.87); NaN for
    anything else (a file from elsewhere may hold a number or nothing there)."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    if not isinstance(value, str) or not value.split():
        return math.nan
    try:
        return float(value.split()[0])
    except ValueError:
        return math.nan


def _warn(text: str) -> None:
    print(f"[league] {text}", file=sys.stderr)


def _roles(root: Path, jobs: Mapping[str, Mapping] | None) -> dict[str, dict[str, dict]]:
    """identity -> role -> {league_role, league_job, study, trial}: from the manifests every league
    invocation left under ``ROOT/manifests/`` (oldest first), then ``jobs`` (this invocation's).
    One run can serve two roles (a reference's tuning trial is a league tuning trial too when
    the league's budget is the target setting's): it gets a row for each."""
    found: dict[str, dict[str, dict]] = {}
    manifests = sorted((root / "manifests").glob("*.json")) if safe_dir(root / "manifests") else []
    for _, manifest in read_json_files(manifests):
        entries = manifest.get("runs") if isinstance(manifest, dict) else None
        for entry in entries if isinstance(entries, list) else []:
            if isinstance(entry, dict) and isinstance(entry.get("identity"), str) and entry.get("role") in ROLES:
                found.setdefault(entry["identity"], {})[entry["role"]] = _role_of(entry)
    for identity, entry in (jobs or {}).items():
        found.setdefault(identity, {})[entry.get("role")] = _role_of(entry)
    return found


def _role_of(entry: Mapping) -> dict:
    def number(key):
        value = entry.get(key)
        return value if isinstance(value, int) and not isinstance(value, bool) else None

    return {"league_role": entry.get("role"), "league_job": entry.get("job"), "study": number("study"), "trial": number("trial")}


def runs_table(root: Path, runs: pd.DataFrame, roles: Mapping[str, dict]) -> pd.DataFrame:
    """The exported rows of the league runs of ``runs`` (``load_runs``'s frame of ``root``)."""
    from higbench.results import league

    runs = runs[runs["config_id"].isin(roles)] if len(runs) else runs
    runs = runs[[_readable(row) for _, row in runs.iterrows()]] if len(runs) else runs
    if runs.empty:
        return pd.DataFrame(columns=list(RUN_COLUMNS))
    base = Path(root).resolve()
    table = runs.assign(
        run=runs["path"].map(lambda p: Path(p).resolve().relative_to(base).as_posix()),
        identity=runs["config_id"],
        hardware=hardware(runs),
        **{"env.load_1min": runs.get("env.load_at_finish", pd.Series(None, index=runs.index)).map(load_1min)},
    )
    table = table.assign(role=table["identity"].map(lambda i: list(roles[i].values()))).explode("role")  # a row per role
    for key in ("league_role", "league_job", "study", "trial"):
        table[key] = table["role"].map(lambda r, key=key: r[key])
    table = table.reset_index(drop=True)
    table["task"] = table.apply(league.task_label, axis=1)  # the job names its variant
    for key in ("study", "trial"):  # whole numbers, empty for confirmation runs (not 0.0)
        table[key] = pd.to_numeric(table[key], errors="coerce").astype("Int64")
    for column in RUN_COLUMNS:
        if column not in table:
            table[column] = None
    table = table[list(RUN_COLUMNS)].copy()
    table["problem.targets"] = table["problem.targets"].map(_targets_text)
    return table


def _readable(row: pd.Series) -> bool:
    """Whether a run's row can be scored (a file from elsewhere may hold anything); one line naming
    the run file for one that cannot."""
    seed, status = row.get("seed"), row.get("status")
    if isinstance(seed, bool) or not isinstance(seed, int | float) or seed != seed or int(seed) != seed:
        _warn(f"{row['path']}: skipped, seed {seed!r} is not an integer")
        return False
    if not isinstance(status, str):
        _warn(f"{row['path']}: skipped, status {status!r} is not a status")
        return False
    return True


def _targets_text(value) -> str | None:
    try:
        levels = [float(v) for v in value] if value is not None and not isinstance(value, str | float) else None
    except (TypeError, ValueError):
        return None
    return json.dumps(levels) if levels is not None else None


def curves_table(root: Path, curves: pd.DataFrame, runs: pd.DataFrame) -> pd.DataFrame:
    """The exported evaluations of the runs of ``runs`` (a ``runs_table``)."""
    base = Path(root).resolve()
    if curves.empty or runs.empty:
        return pd.DataFrame(columns=list(CURVE_COLUMNS))
    run = curves["path"].astype(str).map(lambda p: Path(p).resolve().relative_to(base).as_posix())
    table = curves.assign(run=run)
    table = table[table["run"].isin(set(runs["run"]))]
    for column in CURVE_COLUMNS:
        if column not in table:
            table[column] = math.nan
    return table[list(CURVE_COLUMNS)].reset_index(drop=True)


def export(root: Path, jobs: Mapping[str, Mapping] | None = None) -> tuple[Path, Path]:
    """Write ``ROOT/tables/runs.csv.gz`` and ``curves.csv.gz`` from the league runs under ``root``
    (runs the manifests or ``jobs``, identity -> manifest entry, name). Rows already exported for
    runs whose files are no longer there are kept; a run read now replaces its old row, and the
    row of another run of its identity (one moved out and trained again)."""
    from higbench.results.index import load_runs

    root = Path(root)
    runs, curves = load_runs(root, curves=True, figure_runs=True)
    runs = runs[runs["path"].map(lambda p: Path(p).is_file())] if len(runs) else runs  # corrupt dirs have no run id
    runs_now = runs_table(root, runs, _roles(root, jobs))
    curves_now = curves_table(root, curves, runs_now)
    old_runs, old_curves = read_root(root, missing_ok=True)
    if len(old_runs):
        # a run read now replaces its old row, and a run moved out of the root and trained again
        # (the same identity, another directory) replaces the row of the one moved out
        stale = old_runs["run"].isin(set(runs_now["run"])) | old_runs["identity"].isin(set(runs_now["identity"]))
        old_runs = old_runs[~stale].drop(columns=["root", "path"], errors="ignore")
        old_curves = old_curves[old_curves["run"].isin(set(old_runs["run"]))].drop(columns=["root", "path"], errors="ignore")
        old_runs["problem.targets"] = old_runs["problem.targets"].map(_targets_text)
        runs_now = pd.concat([old_runs, runs_now], ignore_index=True) if len(runs_now) else old_runs
        curves_now = pd.concat([old_curves, curves_now], ignore_index=True) if len(curves_now) else old_curves
    return _write_tables(root, runs_now, curves_now)


def write_merged(out: Path, roots: Iterable[Path]) -> tuple[Path, Path]:
    """The tables of ``roots`` merged into ``OUT/tables/`` (one row per run and role; its ``run`` as in its
    own root): ``out`` is then a root itself, which a later league reads as its earlier runs and
    ``--report-only --root OUT`` scores alone."""
    runs, curves = read(roots)
    runs = one_row_per_identity_and_role(runs)
    # each kept run's evaluations once: from the root its row came from (a run in two roots, a
    # league's own root and the published one, was counted once per root, and again per merge)
    curves = curves[curves["path"].isin(set(runs["path"]))].drop(columns=["path"], errors="ignore").drop_duplicates()
    runs = runs.drop(columns=["root", "path"], errors="ignore")
    runs["problem.targets"] = runs["problem.targets"].map(_targets_text)
    return _write_tables(Path(out), runs[list(RUN_COLUMNS)], curves[list(CURVE_COLUMNS)])


def one_row_per_identity_and_role(runs: pd.DataFrame) -> pd.DataFrame:
    """The first row of each (identity, role), a finished one (completed or diverged) before any
    other: a run killed without closing its file (status ``running``) or interrupted, and trained
    again under another directory, leaves two files of one identity, and the old one comes first."""
    from higbench.results.index import DONE_STATUSES

    unfinished = ~runs["status"].isin(DONE_STATUSES)
    order = unfinished.sort_values(kind="stable").index  # finished first, each group in its old order
    return runs.loc[order].drop_duplicates(["identity", "league_role"], keep="first").sort_index()


def _write_tables(root: Path, runs: pd.DataFrame, curves: pd.DataFrame) -> tuple[Path, Path]:
    directory = safe_dir(root / TABLES_DIR, create=True)
    paths = directory / RUNS_TABLE, directory / CURVES_TABLE
    for path, table in zip(paths, (runs, curves), strict=True):
        buffer = io.BytesIO()
        table.to_csv(buffer, index=False, compression={"method": "gzip", "mtime": 0})
        write_bytes(path, buffer.getvalue())
    return paths


def _read_table(path: Path, columns: Iterable[str]) -> pd.DataFrame | None:
    """One exported table (never through a link, never a FIFO); None with one warning line when it
    is not one."""
    try:
        data = read_bytes(path)
        table = pd.read_csv(io.BytesIO(data), compression="gzip", dtype={"run": str, "overrides": str})
    except FileNotFoundError:
        return None
    except (*ROOT_FILE_ERRORS, ValueError, EOFError, OSError) as exc:
        _warn(f"{path}: skipped, not a league table ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})")
        return None
    missing = [c for c in columns if c not in table]
    if missing:
        _warn(f"{path}: skipped, not a league table (no column {missing[0]})")
        return None
    return table


def read_root(root: Path, missing_ok: bool = False) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The tables of one root as ``load_runs`` frames (``path`` = ROOT/run); empty when absent."""
    root = Path(root)
    required = [c for c in RUN_COLUMNS if c not in MACHINE_COLUMNS]
    runs = _read_table(root / TABLES_DIR / RUNS_TABLE, required) if safe_dir(root / TABLES_DIR) else None
    curves = _read_table(root / TABLES_DIR / CURVES_TABLE, CURVE_COLUMNS) if runs is not None else None
    if runs is None or curves is None:
        if not missing_ok:
            raise FileNotFoundError(f"{root}: no league tables ({TABLES_DIR}/{RUNS_TABLE}); export them with a league run first")
        return pd.DataFrame(columns=[*RUN_COLUMNS, "path", "root"]), pd.DataFrame(columns=[*CURVE_COLUMNS, "path"])
    for column in MACHINE_COLUMNS:
        if column not in runs:
            runs[column] = None
    prefix = str(root)
    runs["path"] = prefix + "/" + runs["run"].astype(str)
    runs["root"] = prefix
    runs["problem.targets"] = runs["problem.targets"].map(_targets_value)
    for column in ("seed", "steps", "study", "trial", "env.cpu_count", "env.torch_threads"):
        runs[column] = pd.to_numeric(runs[column], errors="coerce").astype("Int64")
    curves = curves[curves["run"].isin(set(runs["run"]))].copy()
    curves["path"] = prefix + "/" + curves["run"].astype(str)
    return runs, curves


def _targets_value(text) -> tuple[float, ...] | None:
    try:
        levels = json.loads(text) if isinstance(text, str) else None
        return tuple(float(v) for v in levels) if isinstance(levels, list) else None
    except (ValueError, TypeError, RecursionError):
        return None


def read(roots: Path | Iterable[Path]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(runs, curves) of one or several roots' tables, merged: the frames the scorer
    (``league.league_frames``) reads as it reads ``load_runs(root, curves=True)``'s."""
    roots = [Path(roots)] if isinstance(roots, str | Path) else [Path(r) for r in roots]
    parts = [read_root(r) for r in roots]
    runs = pd.concat([p[0] for p in parts], ignore_index=True)
    curves = pd.concat([p[1] for p in parts], ignore_index=True)
    curves["path"] = pd.Categorical(curves["path"])
    for column in ("step",):
        if len(curves) and curves[column].notna().all():
            curves[column] = curves[column].astype("int64")
    return runs, curves
