"""The HDF5 run file: one per run, the single source of truth for figures and tables."""

from higbench.runfile.reader import (
    RUN_FILE,
    RUN_FILE_GLOB,
    RunFileLocked,
    RunFileOpenForWrite,
    RunHead,
    RunTables,
    UnreadableRunFile,
    load_logs,
    load_run,
    load_updates,
    load_weights,
    read_head,
    read_tables,
    run_file_path,
)
from higbench.runfile.writer import FORMAT_VERSION, H5PY_VERSION, STATUSES, RunFileExists, RunFileWriter

__all__ = [
    "RUN_FILE",
    "RUN_FILE_GLOB",
    "RunHead",
    "UnreadableRunFile",
    "RunFileLocked",
    "RunFileOpenForWrite",
    "RunTables",
    "read_head",
    "read_tables",
    "run_file_path",
    "RunFileWriter",
    "RunFileExists",
    "FORMAT_VERSION",
    "H5PY_VERSION",
    "STATUSES",
    "load_run",
    "load_updates",
    "load_logs",
    "load_weights",
]
