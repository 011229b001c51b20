"""The run directory: every question about an existing one, answered here and nowhere else.

Before anything is written (the plan asks; each answer a one-line ``ConfigError`` naming the
key the user gave for the directory, ``hydra.run.dir`` or ``resume``):

* can a run be created there: writable, room for a run file, names the file system takes
  (``check_output_dir``, also for a sweep's directory);
* is anything higbench writes there a link (``check_links``; ``check_tensorboard_dir``);
* what its run file holds (``look``, one read of its head): nothing worth keeping
  (``recorded_nothing``: killed while being created, or stopped before its first update),
  a sweep job stopped before its first checkpoint (``stopped_without_checkpoint``), or a run
  to continue (``inspect``), and its stored config (``stored_config``);
* what that means for the plan, one call per kind of run: ``fresh_start`` (new, restart,
  keep, or the refusal to overwrite) and ``resumption`` (resume, restart, or a sweep job that
  starts now), each a ``Found``;
* another run's directory: the final weights ``init_from`` starts from (``final_weights``).

Once the job holds the directory, ``make_room`` moves a dead run file and a checkpoint
without its run (the stray checkpoint) aside: renamed beside them, never deleted.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import time
from pathlib import Path
from typing import Any

from higbench.errors import ConfigError
from higbench.runfile.reader import RUN_FILE, RunFileLocked, RunHead, UnreadableRunFile, read_head, run_file_path
from higbench.runfile.writer import RESERVE_BYTES, free_bytes
from higbench.runner.checkpoint import checkpoint_path

MIN_FREE_BYTES = 2 * RESERVE_BYTES  # Hydra's files, the run file's first rows, the reserve for closing
EMPTY_FILE_BYTES = 64 * 1024  # an unopenable file this small was killed while being created
RESUMABLE_STATUSES = ("running", "interrupted", "failed")
# Everything higbench (and Hydra for it) writes in a run directory: none may be a link.
WRITTEN_NAMES = (".hydra", *(f".hydra/{n}.yaml" for n in ("config", "hydra", "overrides")), "higbench.log")
WRITTEN_NAMES += (RUN_FILE, f"{RUN_FILE}.ckpt")
_UNSEEN = object()  # recorded_nothing: the run file not looked at yet
LINK = "is a symbolic link (to {}); higbench never writes through links"


def check_output_dir(out: str | Path, key: str) -> None:
    """Refuse a directory that cannot take a run (or a sweep): its names, room, permissions."""
    path = Path(os.path.abspath(os.path.expanduser(str(out))))
    existing = path
    while not os.path.lexists(existing):
        existing = existing.parent
    probe = existing if existing.is_dir() else existing.parent
    name_max, path_max = _limit(probe, "PC_NAME_MAX", 255), _limit(probe, "PC_PATH_MAX", 4096)
    for part in path.parts:
        if len(os.fsencode(part)) > name_max:
            why = f"a name in this path is {len(os.fsencode(part))} bytes, longer than the file system allows ({name_max})"
            raise ConfigError(key, str(out), why)
    if len(os.fsencode(str(path))) + 16 >= path_max:
        raise ConfigError(key, str(out), f"path too long for the file system ({path_max} bytes at most)")
    if not existing.is_dir():
        what = "a dangling symbolic link" if existing.is_symlink() and not existing.exists() else "not a directory"
        raise ConfigError(key, str(out), f"{existing} is {what}")
    with contextlib.suppress(OSError):
        if os.statvfs(existing).f_flag & os.ST_RDONLY:
            raise ConfigError(key, str(out), f"{existing} is on a read-only file system")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ConfigError(key, str(out), f"{existing} is not writable")
    free = free_bytes(existing)
    if free < MIN_FREE_BYTES:
        why = f"only {free // 1024} KiB free on its file system; a run needs at least {MIN_FREE_BYTES // 1024} KiB"
        raise ConfigError(key, str(out), why)


def _limit(path: Path, name: str, default: int) -> int:
    try:
        return int(os.pathconf(path, name))
    except (OSError, ValueError):
        return default


def run_file_of(resume: Any, run_dir: str | Path | None) -> Path:
    """The run file that ``resume=<value>`` designates (``true``: the one in ``run_dir``)."""
    if resume is True:
        if run_dir is None:
            raise ConfigError("resume", True, "needs hydra.run.dir=<run dir>, or give the run: resume=<run dir or run file>")
        return Path(run_dir) / RUN_FILE
    return run_file_path(Path(str(resume)).expanduser())


def final_weights(path: str | None, problem_name: str) -> dict | None:
    """``init_from``: the final weights of another run, existing, readable, finished, of the same
    problem (ConfigError otherwise; None where ``path`` is none). Their shapes are checked against
    the network in ``runner.train`` once it is built, still before anything is written."""
    import numpy as np

    if not path:
        return None
    p = run_file_path(path)
    if not p.is_file():
        raise ConfigError("init_from", path, "no such run file")
    try:
        head = read_head(p, with_weights=True)
    except UnreadableRunFile as exc:
        raise ConfigError("init_from", path, str(exc).split(": ", 1)[-1]) from None
    if not head.has_weights:
        raise ConfigError("init_from", path, "run file holds no final weights (run still going, or killed)")
    if head.problem and head.problem != problem_name:
        raise ConfigError("init_from", path, f"run is of problem {head.problem}, not {problem_name}")
    if head.status == "diverged":  # its weights, finite or not, are where it failed
        raise ConfigError("init_from", path, "run diverged; a diverged run cannot start another")
    bad = sorted(k for k, v in head.weights.items() if not np.isfinite(v).all())
    if bad:
        why = f"final weights hold NaN or inf ({', '.join(bad)}); a diverged run cannot start another"
        raise ConfigError("init_from", path, why)
    return head.weights


def move_aside(path: Path, label: str) -> Path:
    """Rename ``path`` to ``<name>.<label>-<time>`` beside it (never deleted: nothing is lost)."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    target, n = path.with_name(f"{path.name}.{label}-{stamp}"), 1
    while target.exists():
        target, n = path.with_name(f"{path.name}.{label}-{stamp}-{n}"), n + 1
    os.replace(path, target)
    return target


@dataclasses.dataclass(frozen=True)
class Found:
    """What a run directory holds, as the plan needs it: what to do with it (``policy``: new,
    restart, resume or keep) and why; the stored config a resumed or restarted run starts from
    (``stored_yaml``; None: the command line's); the head of the run to continue (``resume``);
    ``fresh``: a sweep job that starts now from its own config, whatever its run file said."""

    policy: str
    why: str = ""
    stored_yaml: str | None = None
    head: RunHead | None = None
    fresh: bool = False


@dataclasses.dataclass(frozen=True)
class RunDir:
    """A run's directory and its run file; ``key``: what a refusal about it names."""

    run_file: Path
    key: str = "hydra.run.dir"

    @property
    def path(self) -> Path:
        return self.run_file.parent

    def refuse(self, why: str, value: Any = None) -> ConfigError:
        return ConfigError(self.key, str(self.path) if value is None else value, why)

    def check(self) -> None:
        """A run can be written here: the directory takes one, and nothing higbench writes is a link."""
        check_output_dir(self.path, self.key)
        run_file = self.run_file
        if self.key == "resume":  # its run file: ``inspect``
            return self.check_links()
        if run_file.is_symlink():
            dangling = "a dangling " if not run_file.exists() else "a "
            why = f"{run_file} is {dangling}symbolic link (to {os.readlink(run_file)}); run files are never written through links"
            raise self.refuse(why)
        if os.path.lexists(run_file) and not run_file.is_file():
            raise self.refuse(f"{run_file} exists and is not a regular file")
        self.check_links()

    def check_links(self) -> None:
        for name in WRITTEN_NAMES:
            if (self.path / name).is_symlink():
                raise self.refuse(f"{self.path / name} {LINK.format(os.readlink(self.path / name))}")

    def check_tensorboard_dir(self, tensorboard: bool) -> None:
        """TensorBoard asked for (``tensorboard``: the run's side sinks name it): its directory here
        is absent or a real directory (a link would take the event files elsewhere; a file or a
        dangling link would fail mid-run)."""
        from higbench.runner.tensorboard import TENSORBOARD_DIR

        path = self.path / TENSORBOARD_DIR
        if not tensorboard or not os.path.lexists(path):
            return
        if path.is_symlink():
            raise self.refuse(f"{path} {LINK.format(os.readlink(path))}")
        if not path.is_dir():
            raise self.refuse(f"{path} exists and is not a directory; tensorboard=true writes its event files there")

    # -- what it means for the plan: one call per kind of run ----------------------------------

    def fresh_start(self, multirun: bool, tensorboard: bool) -> Found:
        """A run that does not resume: ``new`` where no run file is there, ``restart`` where the
        one there recorded nothing, ``keep`` for a sweep job whose directory holds a run; else
        the refusal to overwrite it (after the checks that a run can be written here)."""
        self.check()
        self.check_tensorboard_dir(tensorboard)
        if not os.path.lexists(self.run_file):
            return Found("new")
        empty = self.recorded_nothing(self.look())
        if empty:
            return Found("restart", empty)
        if multirun:  # a sweep run again into its directory: its runs stay as they are
            return Found("keep", "already holds a run (resume=true completes interrupted and failed jobs)")
        raise self.refuse(
            f"already holds a run file ({RUN_FILE}); refusing to overwrite it "
            f"(resume={self.path} continues it, or pick a new hydra.run.dir)"
        )

    def resumption(self, resume_value: Any, multirun: bool) -> Found:
        """``resume=``: the run continues from its checkpoint (``resume``, its head inspected), or
        starts again from its stored config where it recorded nothing (``restart``); a sweep job
        that never started (``new``), or stopped before its first checkpoint (``restart``),
        starts now from its own config (``fresh``). One look at its run file."""
        self.check()
        seen = self.look()
        stopped = self.stopped_without_checkpoint(seen) if multirun else None
        if multirun and (stopped or not self.run_file.exists()):
            return Found("restart" if stopped else "new", stopped or "", fresh=True)
        why = self.recorded_nothing(seen)
        if not why:
            head = self.inspect(resume_value)
            return Found("resume", head=head, stored_yaml=head.config_yaml)
        # a sweep job's stored config is its own composed one (None: the plan takes that)
        return Found("restart", why, stored_yaml=None if multirun else self.stored_config(seen, resume_value))

    # -- what its run file holds ---------------------------------------------------------------

    def look(self) -> RunHead | str | None:
        """The head of a run file no live writer holds and no checkpoint continues (one read);
        why it is dead when it cannot be opened and is a few KiB at most; None otherwise."""
        if not self.run_file.is_file() or checkpoint_path(self.run_file).exists():
            return None
        try:
            return read_head(self.run_file, locking=True)  # a live writer on this host holds the lock
        except RunFileLocked:
            return None
        except UnreadableRunFile:
            try:  # readable without locking (a file system without locks): kept, as a run
                read_head(self.run_file, locking=False)
            except UnreadableRunFile:  # not HDF5, truncated header
                size = self.run_file.stat().st_size
                return f"unreadable {size}-byte file, killed while it was being created" if size <= EMPTY_FILE_BYTES else None
        return None

    def recorded_nothing(self, seen: RunHead | str | None | object = _UNSEEN) -> str | None:
        """Why the run file (``seen``: ``look()``, read now if not given) holds nothing worth
        keeping, or None: a file killed while being created (unopenable, a few KiB at most), or
        a run that stopped before recording one update and left no checkpoint. It may start
        again, its file moved aside."""
        seen = self.look() if seen is _UNSEEN else seen
        if isinstance(seen, str):
            return seen
        if isinstance(seen, RunHead) and _stopped(seen) and seen.n_updates == 0:
            return f"status {_stopped(seen)}, no update recorded, no checkpoint"
        return None

    def stopped_without_checkpoint(self, seen: RunHead | str | None) -> str | None:
        """Why a sweep job's run must run again from the start, or None: it stopped before its
        first checkpoint (a sweep's Ctrl-C hard-kills the parallel workers not yet writing one),
        so nothing can continue it; the sweep's resume command reruns it."""
        if isinstance(seen, RunHead) and _stopped(seen):
            return f"stopped ({_stopped(seen)}) after {seen.n_updates} updates, before its first checkpoint"
        return None

    def inspect(self, resume_value: Any) -> RunHead:
        """The head of a run to resume (status, stored config, rows); ConfigError if it cannot be."""
        run_file = self.run_file

        def refuse(why: str) -> ConfigError:
            return ConfigError("resume", resume_value, why)

        if run_file.is_symlink():  # the run would go on elsewhere while its checkpoint and logs stay here
            raise refuse(f"{run_file} is a symbolic link (to {os.readlink(run_file)}); resume runs in their own directory")
        if not run_file.is_file():
            raise refuse(f"no run file {run_file}")
        links = run_file.stat().st_nlink
        if links > 1:  # resume writes it in place: a snapshot sharing its inode (cp -al) would change too
            raise refuse(
                f"{run_file} has {links} hard links (a snapshot shares it); resume writes in place: copy it (cp, not cp -l) first"
            )
        try:  # with file locking: a live writer holds the file, and we must not write into it
            head = read_head(run_file, locking=True)
        except RunFileLocked:
            raise refuse(f"{run_file} is open in another process (that run is still going)") from None
        except UnreadableRunFile as exc:
            why = exc.detail.split(": ", 1)[-1] if exc.kind == "refused" else exc.kind
            raise refuse(f"{run_file} is not a readable run file ({why})") from None
        status = str(head.attrs.get("status", ""))
        if status not in RESUMABLE_STATUSES:
            raise refuse(f"run is {status}, nothing to resume (resumable: {', '.join(RESUMABLE_STATUSES)})")
        if not checkpoint_path(run_file).is_file():
            every = _checkpoint_every(head.config_yaml)
            why = "set checkpoint_every to make runs resumable"
            if every is not None:
                why = f"it stopped before its first checkpoint, due after {every} s of training clock"
            raise refuse(f"no checkpoint next to {run_file} ({why})")
        if not head.config_yaml:
            raise refuse(f"{run_file} holds no config")
        return head

    def stored_config(self, seen: RunHead | str | None, resume_value: Any) -> str:
        """The config YAML of a run that recorded nothing: its run file's, else (a file killed at
        creation) Hydra's copy beside it."""
        if isinstance(seen, RunHead) and seen.config_yaml:
            return seen.config_yaml
        saved = self.path / ".hydra" / "config.yaml"
        if saved.is_file() and not saved.is_symlink():
            return saved.read_text()
        why = f"{self.run_file} recorded nothing and its config is unknown (no .hydra/config.yaml)"
        raise ConfigError("resume", resume_value, why)

    # -- once the job holds it -----------------------------------------------------------------

    def make_room(self, policy: str, why: str, where: Path) -> list[str]:
        """Before the run writes into ``where`` (the job's directory): a run file made since the
        plan refuses a new run; a dead one (``restart``) and a checkpoint without its run are
        moved aside. Returns what to say of it."""
        said = []
        if policy == "new" and os.path.lexists(self.run_file):
            raise self.refuse(f"already holds a run file ({RUN_FILE}); refusing to overwrite it", str(where))
        if policy == "restart":
            stopped = why.startswith("stopped")  # stopped_without_checkpoint
            what = why if stopped else f"recorded nothing ({why})"
            aside = move_aside(self.run_file, "stopped" if stopped else "empty")
            said.append(f"{self.run_file} {what}; moved to {aside.name}, starting the run again")
        stray = checkpoint_path(self.run_file)
        if policy != "resume" and stray.exists():  # never adopt another run's checkpoint
            said.append(f"a checkpoint without its run was in {where}; moved to {move_aside(stray, 'stray').name}")
        return said


def _stopped(head: RunHead) -> str:
    """Its status if it is one a run stops with (no live writer: ``look`` took the lock), else ''."""
    status = str(head.attrs.get("status", ""))
    return status if status in RESUMABLE_STATUSES else ""


def _checkpoint_every(config_yaml: str):
    import yaml

    try:
        return (yaml.safe_load(config_yaml) or {}).get("checkpoint_every")
    except Exception:  # noqa: BLE001
        return None
