"""Files under a league's root, read and written without following links.

A root gathers what other machines and people bring back; a link planted in it must neither
bring a file from elsewhere into the published report nor carry a write out of the root, and a
FIFO must never hang the league. So every file is opened with ``O_NOFOLLOW | O_NONBLOCK`` and
checked on the open descriptor to be a regular file; every directory the league writes into
is refused when it is a link; writes go to a new file beside the target (``O_EXCL``), renamed
over it (a rename replaces a link, never writes through it).
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import stat
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any


class RootFileError(Exception):
    """A file or directory under a league root that the league will not read or write (one line)."""


ROOT_FILE_ERRORS = (RootFileError,)
MAX_JSON_BYTES = 64 << 20  # a manifest of a hundred thousand runs is a few MB


def read_bytes(path: Path, limit: int = MAX_JSON_BYTES * 16) -> bytes:
    """The bytes of a regular file, never through a link and never blocking on a FIFO;
    FileNotFoundError when absent, RootFileError (one line naming it) when it is not a file."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except FileNotFoundError:
        raise
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise RootFileError(f"{path}: a symbolic link; the league reads no file through a link") from None
        raise RootFileError(f"{path}: cannot be read ({exc.strerror})") from None
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise RootFileError(f"{path}: not a regular file")
        if st.st_size > limit:
            raise RootFileError(f"{path}: {st.st_size} bytes, more than a league file holds")
        return f.read(limit + 1)


def read_json(path: Path) -> Any:
    """A JSON file under a root (``read_bytes``); RootFileError when it is not JSON (deeply
    nested JSON included: Python's parser recurses)."""
    data = read_bytes(path, MAX_JSON_BYTES)
    try:
        return json.loads(data)
    except (ValueError, RecursionError) as exc:
        why = "nested too deeply" if isinstance(exc, RecursionError) else "not JSON"
        raise RootFileError(f"{path}: {why}") from None


def read_json_files(paths: Iterable[Path]) -> Iterator[tuple[Path, Any]]:
    """(path, content) of each JSON file that can be read; one warning line for each that cannot."""
    for path in paths:
        try:
            yield path, read_json(path)
        except FileNotFoundError:
            continue
        except RootFileError as exc:
            print(f"[league] skipped {exc}", file=sys.stderr)


def safe_dir(path: Path, create: bool = False) -> Path | None:
    """``path`` when it is a directory of its own (not a link); with ``create`` made (parents
    too) and RootFileError when it is a link or not a directory; without, None for those."""
    path = Path(path)
    if create and not os.path.lexists(path):
        path.mkdir(parents=True, exist_ok=True)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        if create:
            raise
        return None
    if stat.S_ISDIR(st.st_mode):
        return path
    if not create:
        return None
    what = "a symbolic link" if stat.S_ISLNK(st.st_mode) else "not a directory"
    raise RootFileError(f"{path}: {what}; the league writes only into directories of its own")


def write_bytes(path: Path, data: bytes) -> None:
    """Write ``path`` whole: a new file beside it (``O_EXCL | O_NOFOLLOW``), renamed over it. A
    link or FIFO at ``path`` is replaced, never written through or waited on; a directory there
    is refused."""
    path = Path(path)
    safe_dir(path.parent, create=True)
    if os.path.isdir(path) and not os.path.islink(path):
        raise RootFileError(f"{path}: a directory; the league writes a file there")
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)
    except OSError as exc:
        raise RootFileError(f"{tmp}: cannot be created ({exc.strerror})") from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_text(path: Path, text: str) -> None:
    write_bytes(path, text.encode("utf-8"))
