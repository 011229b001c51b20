"""The runs root as the ledger of its jobs: who runs a job now, and how its last attempt ended.

Two files per job identity (``higbench.results.index.config_id``), in ``<root>/ledger/``:

* ``<identity>.claim``: the job is being run. Created by the worker about to run it, atomically
  (``O_CREAT|O_EXCL|O_NOFOLLOW``: of two workers exactly one creates it, and a link planted under
  its name is never followed); it says the host, the pid and that process's start time. While the
  job runs, the worker touches it every ``HEARTBEAT_S`` seconds (its mtime is the heartbeat);
  at the end it removes it.
* ``<identity>.json``: how the last attempt ended (the run file's status, or ``refused`` when
  the run was refused for memory before it wrote anything), where its run file is, and how many
  attempts in a row failed.

A job is done when its run file says so (the results index decides, as it always did); the
ledger only decides who may run it and whether to run it again:

* A claim whose worker is dead is broken and the job runs again (resuming from its checkpoint
  where the run left one): on this host, when its pid is gone (or is another process: the start
  time differs); on another host, when its heartbeat is older than ``STALE_S``.
* A live claim means another worker (another driver's, or one left running by a killed driver)
  runs the job: nobody else starts it; a driver waits for it.
* A job refused for memory, or failed ``MAX_FAILURES`` times in a row, is final: no driver
  launches it again until its record is removed (``rm <root>/ledger/<identity>.json``).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import socket
import stat
import threading
import time
from dataclasses import dataclass
from pathlib import Path

LEDGER_DIR = "ledger"
HEARTBEAT_S = 30.0  # a worker touches its claim this often
STALE_S = 600.0  # another host's claim not touched for this long is a dead worker's
MAX_FAILURES = 2  # attempts in a row that failed before a job is left alone
MAX_RECORD_BYTES = 1 << 16
IDENTITY = re.compile(r"[0-9a-f]{8,64}")  # config_id: hex digits (a file name, never a path)
FINAL_STATUSES = ("refused",)


@dataclass(frozen=True)
class Claim:
    """Who holds a job: its host, pid and that process's start time; ``heartbeat``: the claim
    file's mtime; ``inode``: which claim file (a broken and re-made claim is another one)."""

    identity: str
    host: str
    pid: int
    pid_started: float
    started: float
    heartbeat: float
    run: str = ""
    inode: int = 0

    def describe(self) -> str:
        return f"pid {self.pid} on {self.host}, heartbeat {max(0.0, time.time() - self.heartbeat):.0f} s ago"


def this_host() -> str:
    return socket.gethostname()


def process_started(pid: int) -> float | None:
    """The start time of process ``pid`` (psutil), None if there is none."""
    import psutil

    try:
        return psutil.Process(pid).create_time()
    except (psutil.NoSuchProcess, psutil.AccessDenied, ValueError):
        return None


def is_live(claim: Claim, now: float | None = None) -> bool:
    """Whether the claim's worker still runs: on this host its pid is the same process; on
    another host its heartbeat is younger than ``STALE_S``."""
    if claim.host == this_host():
        started = process_started(claim.pid)
        return started is not None and abs(started - claim.pid_started) < 1.0
    return (time.time() if now is None else now) - claim.heartbeat < STALE_S


def _read_regular(path: Path) -> tuple[bytes, os.stat_result] | None:
    """A small regular file's bytes and stat, never following a link; None if it is absent."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except FileNotFoundError:
        return None
    except OSError as exc:  # a link (ELOOP) or worse: not ours to read
        raise LedgerError(f"{path}: not a regular file ({exc.strerror})") from None
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_size > MAX_RECORD_BYTES:
            raise LedgerError(f"{path}: not a ledger file (not regular, or over {MAX_RECORD_BYTES} bytes)")
        return f.read(MAX_RECORD_BYTES), st


class LedgerError(OSError):
    """A file in the ledger that is not one the ledger writes (a link, a FIFO, a huge file)."""


class Ledger:
    """The ledger of a runs root (``<root>/ledger``)."""

    def __init__(self, root: str | Path):
        self.dir = Path(root) / LEDGER_DIR

    def _path(self, identity: str, suffix: str) -> Path:
        if not IDENTITY.fullmatch(identity):
            raise ValueError(f"{identity!r}: not a job identity")
        return self.dir / f"{identity}{suffix}"

    def ensure_dir(self) -> None:
        self.dir.parent.mkdir(parents=True, exist_ok=True)
        with contextlib.suppress(FileExistsError):
            os.mkdir(self.dir)
        if self.dir.is_symlink() or not self.dir.is_dir():
            raise LedgerError(f"{self.dir}: not a directory (a link is not followed)")

    # -- claims -------------------------------------------------------------------------------
    def holder(self, identity: str) -> Claim | None:
        """The claim on a job, None if nobody claims it (or its file is not a readable claim)."""
        got = _read_regular(self._path(identity, ".claim"))
        if got is None:
            return None
        data, st = got
        try:
            d = json.loads(data)
            return Claim(identity, str(d["host"]), int(d["pid"]), float(d["pid_started"]), float(d["started"]),
                         st.st_mtime, str(d.get("run", "")), st.st_ino)  # fmt: skip
        except (ValueError, KeyError, TypeError):  # a claim being written, or a torn one: its age decides
            return Claim(identity, "?", -1, 0.0, st.st_mtime, st.st_mtime, "", st.st_ino)

    def live_holder(self, identity: str) -> Claim | None:
        claim = self.holder(identity)
        if claim is None:
            return None
        if claim.pid < 0:  # unreadable: treated as another host's (alive while fresh)
            return claim if time.time() - claim.heartbeat < STALE_S else None
        return claim if is_live(claim) else None

    def try_claim(self, identity: str, run: str | Path = "") -> tuple[int, Claim] | None:
        """Claim a job for this process: (the open claim file, the claim), or None when a live
        worker holds it. A dead worker's claim is broken first."""
        self.ensure_dir()
        path = self._path(identity, ".claim")
        for _ in range(3):  # a claim broken by someone else meanwhile: try again
            held = self.holder(identity)
            if held is not None:
                if self.live_holder(identity) is not None:
                    return None
                self._break(path, held)
            try:
                fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)
            except FileExistsError:
                continue
            pid = os.getpid()
            started = process_started(pid) or 0.0
            me = {"host": this_host(), "pid": pid, "pid_started": started, "started": time.time(), "run": str(run)}
            os.write(fd, json.dumps(me).encode())
            os.fsync(fd)
            st = os.fstat(fd)
            return fd, Claim(identity, me["host"], pid, me["pid_started"], me["started"], st.st_mtime, str(run), st.st_ino)
        return None

    def _break(self, path: Path, dead: Claim) -> None:
        """Remove a dead worker's claim, and only that one: it is renamed aside first, and put
        back if the file renamed turns out to be a newer claim (another worker re-made it)."""
        aside = path.with_name(f"{path.name}.dead-{os.getpid()}-{time.monotonic_ns()}")
        try:
            os.rename(path, aside)
        except FileNotFoundError:
            return  # someone else broke it
        if os.lstat(aside).st_ino != dead.inode:
            with contextlib.suppress(FileExistsError):
                os.link(aside, path, follow_symlinks=False)
        os.unlink(aside)

    def release(self, fd: int, claim: Claim) -> None:
        """Remove our claim (only if the claim file is still ours)."""
        path = self._path(claim.identity, ".claim")
        with contextlib.suppress(FileNotFoundError):
            if os.lstat(path).st_ino == claim.inode:
                os.unlink(path)
        os.close(fd)

    @contextlib.contextmanager
    def held(self, identity: str, run: str | Path = ""):
        """Hold the claim on a job while the block runs (heartbeat every ``HEARTBEAT_S``);
        yields the claim, or None when a live worker holds it (the block must not run the job)."""
        got = self.try_claim(identity, run)
        if got is None:
            yield None
            return
        fd, claim = got
        stop = threading.Event()

        def beat():
            while not stop.wait(HEARTBEAT_S):
                with contextlib.suppress(OSError):
                    os.utime(fd)

        thread = threading.Thread(target=beat, name=f"ledger-heartbeat-{identity[:8]}", daemon=True)
        thread.start()
        try:
            yield claim
        finally:
            stop.set()
            thread.join()
            self.release(fd, claim)

    # -- records ------------------------------------------------------------------------------
    def record(self, identity: str) -> dict:
        """How the last attempt at a job ended ({} if none, or the record is unreadable)."""
        try:
            got = _read_regular(self._path(identity, ".json"))
            d = json.loads(got[0]) if got else {}
        except (LedgerError, ValueError):
            return {}
        return d if isinstance(d, dict) else {}

    def write_record(self, identity: str, status: str, run: str | Path | None, reason: str = "") -> dict:
        """Record an attempt's end (atomically: a new file renamed over the old one)."""
        self.ensure_dir()
        before = self.record(identity)
        failures = int(before.get("failures", 0)) + 1 if status == "failed" else 0
        rec = {"status": status, "reason": reason[:2000], "run": str(run or ""), "failures": failures,
               "host": this_host(), "pid": os.getpid(), "finished": time.time()}  # fmt: skip
        path = self._path(identity, ".json")
        tmp = path.with_name(f"{path.name}.tmp-{os.getpid()}-{time.monotonic_ns()}")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)
        with os.fdopen(fd, "w") as f:
            json.dump(rec, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)  # replaces a link planted there, never its target
        return rec

    def final(self, identity: str) -> dict | None:
        """The record of a job not to be launched again (refused for memory, or failed
        ``MAX_FAILURES`` times in a row), else None."""
        rec = self.record(identity)
        if rec.get("status") in FINAL_STATUSES or int(rec.get("failures", 0) or 0) >= MAX_FAILURES:
            return rec
        return None


def is_memory_refusal(exc: BaseException | None) -> bool:
    """Whether a job's failure is a refusal for memory (``errors.MemoryRefusal``: the memory
    guard, the network-size check), anywhere in its chain. The same config is refused again on
    the same machine, so it is a result, not a retry."""
    from higbench.errors import MemoryRefusal

    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, MemoryRefusal):
            return True
        exc = exc.__cause__ or exc.__context__
    return False
