"""Checks of an output location before anything is written there (``higbench.preflight``).

A run or sweep directory must be creatable and writable, on a file system with room for a
run file (``MIN_FREE_BYTES``), with names the file system accepts; a ``run.h5`` that is a
symbolic link (dangling or not) is refused, since the writer would follow it. Each problem
is one ``ConfigError`` naming the key, so the CLI prints one line and exits 2.
"""

from __future__ import annotations

import os
from pathlib import Path

from higbench.errors import ConfigError
from higbench.runfile.writer import RESERVE_BYTES, free_bytes

MIN_FREE_BYTES = 2 * RESERVE_BYTES  # Hydra's files, the run file's first rows, the reserve for closing


def _limit(path: Path, name: str, default: int) -> int:
    try:
        return int(os.pathconf(path, name))
    except (OSError, ValueError):
        return default


def check_output_dir(out: str | Path, key: str, run_file_name: str | None = None) -> None:
    """Refuse (ConfigError) an output directory that cannot take a run."""
    path = Path(os.path.abspath(os.path.expanduser(str(out))))
    existing = path
    while not os.path.lexists(existing):
        existing = existing.parent
    probe = existing if existing.is_dir() else existing.parent
    name_max = _limit(probe, "PC_NAME_MAX", 255)
    for part in path.parts:
        if len(os.fsencode(part)) > name_max:
            raise ConfigError(
                key,
                str(out),
                f"a name in this path is {len(os.fsencode(part))} bytes, longer than the file system allows ({name_max})",
            )
    path_max = _limit(probe, "PC_PATH_MAX", 4096)
    if len(os.fsencode(str(path))) + 16 >= path_max:
        raise ConfigError(key, str(out), f"path too long for the file system ({path_max} bytes at most)")
    if not existing.is_dir():
        what = "a dangling symbolic link" if existing.is_symlink() and not existing.exists() else "not a directory"
        raise ConfigError(key, str(out), f"{existing} is {what}")
    try:
        read_only = bool(os.statvfs(existing).f_flag & os.ST_RDONLY)
    except OSError:
        read_only = False
    if read_only:
        raise ConfigError(key, str(out), f"{existing} is on a read-only file system")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ConfigError(key, str(out), f"{existing} is not writable")
    free = free_bytes(existing)
    if free < MIN_FREE_BYTES:
        raise ConfigError(
            key, str(out), f"only {free // 1024} KiB free on its file system; a run needs at least {MIN_FREE_BYTES // 1024} KiB"
        )
    if run_file_name is not None:
        run_file = path / run_file_name
        if run_file.is_symlink():
            target = os.readlink(run_file)
            dangling = "a dangling " if not run_file.exists() else "a "
            raise ConfigError(
                key, str(out), f"{run_file} is {dangling}symbolic link (to {target}); run files are never written through links"
            )
        if os.path.lexists(run_file) and not run_file.is_file():
            raise ConfigError(key, str(out), f"{run_file} exists and is not a regular file")
