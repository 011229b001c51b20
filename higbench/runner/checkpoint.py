"""Checkpoints and resume: continue an interrupted run exactly where its last checkpoint was.

A checkpoint is a sidecar file next to the run file, ``run.h5.ckpt`` (so an index that
globs ``*.h5`` never mistakes it for a run), written atomically: ``torch.save`` to a
temporary file in the same directory, ``fsync``, ``os.replace``. It holds everything the
loop needs to continue as if never stopped:

* model weights and the optimizer's ``state_dict`` (Adam's moments, ...; JacobianPower
  has no state beyond its hyper-parameters),
* step, epoch, position in the epoch, the shuffle generator's state at the start of the
  epoch (the epoch's batches are replayed up to the position, so the data order is the
  original one), the global torch RNG state, the next evaluation time, the training-loss
  accumulator, the training clock,
* the number of rows of every table of the run file at that moment: resume cuts the
  tables back to them, so nothing written after the checkpoint is duplicated,
* the ``run_id`` of its run file: ``resume=`` refuses a checkpoint of another run (a
  stray ``run.h5.ckpt`` copied or left in the directory), and a new run never adopts one.

The checkpoint is serialised in memory first and written only if it fits on the disk
beside the run file's reserve (``writer.DiskFull`` otherwise; the previous one stays).
The temporary file (``run.h5.ckpt.tmp<random>``) is created exclusively, so nothing planted
under its name (a link to another file) is followed; those of a writer killed mid-save are
unlinked by the next save (which removes a link, never its target).

Checkpoints may come from somebody else (a shared run dir), so loading one runs no code:
it holds only tensors and plain containers, and is read with torch's restricted unpickler
(``weights_only=True``) after refusing links, non-zip files and compressed records; its
``run_id`` is compared with the run file's before anything in it is used (``check_owner``,
right after ``load``).

The runner writes one every ``checkpoint_every`` seconds of training clock (null: off)
and one when it stops on SIGINT/SIGTERM. A run killed with SIGKILL resumes from the last
periodic one. Resuming: ``higbench resume=<run dir or run file>`` (or ``resume=true`` with
``hydra.run.dir=<run dir>``); the run's own stored config is used, and only the keys in
``RESUMABLE_KEYS`` (budgets, evaluation and checkpoint intervals, threads, progress,
device, memory cap) may be changed on the command line.
"""

from __future__ import annotations

import contextlib
import copy
import io
import math
import os
import stat
import tempfile
import time
import zipfile
from pathlib import Path
from typing import Any

from higbench.config import RESUMABLE_KEYS  # the schema marks them (resumable=True)
from higbench.errors import ABSENT, ConfigError, dotted_get, dotted_set, show
from higbench.runfile.reader import RUN_FILE, RunFileLocked, RunHead, UnreadableRunFile, read_head, run_file_path
from higbench.runfile.writer import RESERVE_BYTES, DiskFull, RunFileFault, free_bytes

RUN_FILE_NAME = RUN_FILE  # kept as a name for the callers
SUFFIX = ".ckpt"
FORMAT = 1  # every format-1 checkpoint holds only tensors and plain containers
READABLE_FORMATS = (1,)
TMP_MARK = ".tmp"  # temporaries: run.h5.ckpt.tmp<random>
RESUMABLE_STATUSES = ("running", "interrupted", "failed")


def checkpoint_path(run_path: str | Path) -> Path:
    run_path = Path(run_path)
    return run_path.with_name(run_path.name + SUFFIX)


def save(run_path: str | Path, state: dict[str, Any]) -> Path:
    """Write the checkpoint of ``run_path`` atomically (temp file, fsync, rename).

    The temporary file is created exclusively (``mkstemp``: ``O_CREAT|O_EXCL``), so a link
    or file planted under its name is never followed or overwritten.
    """
    import torch

    final = checkpoint_path(run_path)
    remove_stale_temporaries(run_path)
    state = {"format": FORMAT, "saved": time.strftime("%Y-%m-%dT%H:%M:%S%z"), **state}
    buffer = io.BytesIO()
    torch.save(state, buffer)
    data = buffer.getbuffer()
    free = free_bytes(final.parent)
    if free < len(data) + RESERVE_BYTES:
        raise DiskFull(
            f"no space left for checkpoint {final} ({free // 1024} KiB free, it needs {len(data) // 1024} KiB "
            "plus the reserve for closing the run file); run stopped before writing"
        )
    tmp = None
    try:
        fd, name = tempfile.mkstemp(prefix=f"{final.name}{TMP_MARK}", dir=final.parent)
        tmp = Path(name)
        with os.fdopen(fd, "wb") as f:
            os.fchmod(f.fileno(), 0o666 & ~_umask())  # as an ordinary file would be (mkstemp: 0600)
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, final)  # rename replaces a link at ``final`` itself, never its target
    except OSError as exc:
        if tmp is not None:
            tmp.unlink(missing_ok=True)  # the previous checkpoint stays as it was
        raise RunFileFault(exc.errno, f"cannot write checkpoint {final} ({exc.strerror or exc}); run stopped") from None
    except BaseException:
        if tmp is not None:
            tmp.unlink(missing_ok=True)
        raise
    try:  # make the rename itself durable
        fd = os.open(final.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError:
        pass
    return final


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def load(run_path: str | Path, resume_value: Any = None) -> dict[str, Any]:
    """The checkpoint of run file ``run_path``: checked, then deserialised without running code.

    Refused (``ConfigError`` on ``resume``): a missing checkpoint, a link, anything but a
    torch zip archive of uncompressed records (a plain pickle is never unpickled), an archive
    holding any object but tensors and plain containers (``weights_only=True``: torch's
    restricted unpickler constructs nothing else and calls no function), another format, a
    checkpoint of another run (``check_owner``, next, compares its ``run_id``).
    """
    path = checkpoint_path(run_path)
    value = str(run_path) if resume_value is None else resume_value

    def refuse(why: str) -> ConfigError:
        return ConfigError("resume", value, f"checkpoint {path.name} {why}")

    if not os.path.lexists(path):
        raise ConfigError(
            "resume", value, f"no checkpoint {path.name} next to the run file (was checkpoint_every null and the run killed?)"
        )
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        why = (
            "is a symbolic link; checkpoints are never read through links"
            if os.path.islink(path)
            else f"cannot be opened ({exc.strerror})"
        )
        raise refuse(why) from None
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(f.fileno())
        if not stat.S_ISREG(st.st_mode):
            raise refuse("is not a regular file")
        state = _deserialise(f, st.st_size, refuse)
    if not isinstance(state, dict):
        raise refuse(f"holds a {type(state).__name__}, not a checkpoint")
    if state.get("format") not in READABLE_FORMATS:
        raise refuse(f"has format {show(state.get('format'))}; this version reads {', '.join(map(str, READABLE_FORMATS))}")
    check_fields(state, refuse)
    return state


def _deserialise(f, size: int, refuse) -> Any:
    """A torch zip archive read with the restricted unpickler; ``refuse(why)`` otherwise."""
    import pickle

    import torch

    try:
        with zipfile.ZipFile(f) as archive:
            records = archive.infolist()
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        raise refuse(f"is unreadable: not a checkpoint archive ({exc}); other formats are never unpickled") from None
    if any(r.compress_type != zipfile.ZIP_STORED for r in records) or sum(r.file_size for r in records) > size:
        raise refuse("is unreadable: compressed or oversized records (torch never writes them)")
    foreign = _foreign_globals(f, records)
    if foreign:  # e.g. builtins.bytearray: torch allows it, and 133 bytes of pickle make 1.5 GB of it
        raise refuse(f"names {foreign}, which no checkpoint of higbench holds; refusing to load it")
    f.seek(0)
    try:
        return torch.load(f, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise refuse(f"holds objects other than tensors and plain containers; refusing to load it ({first})") from None
    except Exception as exc:  # noqa: BLE001 - truncated, damaged
        raise refuse(f"is unreadable ({type(exc).__name__}: {' '.join(str(exc).split())[:200]})") from None


def _allowed_global(module: str, name: str) -> bool:
    """What ``torch.save`` writes for a checkpoint of plain tensors and containers."""
    import torch

    if module == "collections":
        return name == "OrderedDict"
    if module == "torch._utils":
        return name == "_rebuild_tensor_v2"
    if module == "torch":
        return name.endswith("Storage") or isinstance(getattr(torch, name, None), torch.dtype)
    return False


def _foreign_globals(f, records) -> str:
    """The first global (module.name) the archive's pickle names that is not ``_allowed_global``,
    read from its opcodes without unpickling anything; '' when none."""
    import pickletools

    pickles = [r for r in records if r.filename.endswith("/data.pkl") or r.filename == "data.pkl"]
    f.seek(0)
    with zipfile.ZipFile(f) as archive:
        for record in pickles:
            strings: list[str] = []
            try:
                for op, arg, _pos in pickletools.genops(archive.read(record)):
                    if op.name in ("SHORT_BINUNICODE", "BINUNICODE", "UNICODE", "BINUNICODE8"):
                        strings.append(str(arg))
                    elif op.name == "GLOBAL":
                        module, _, name = str(arg).partition(" ")
                    elif op.name == "STACK_GLOBAL":
                        module, name = (strings[-2], strings[-1]) if len(strings) >= 2 else ("?", "?")
                    elif op.name in ("INST", "OBJ", "NEWOBJ_EX", "EXT1", "EXT2", "EXT4"):  # torch never writes these
                        return op.name
                    else:
                        continue
                    if op.name in ("GLOBAL", "STACK_GLOBAL") and not _allowed_global(module, name):
                        return f"{module}.{name}"
            except Exception as exc:  # noqa: BLE001 - a damaged pickle: torch.load says what is wrong
                return "" if isinstance(exc, ValueError) else f"an unreadable pickle ({type(exc).__name__})"
    return ""


# -- what a checkpoint must hold (checked before anything of the run is written) -------------

_INT = "an integer >= 0"


def _nonneg_int(v) -> bool:
    return type(v) is int and v >= 0


def _nonneg_number(v) -> bool:
    return type(v) in (int, float) and math.isfinite(v) and v >= 0


def _rng_state(v, like) -> bool:
    import torch

    return isinstance(v, torch.Tensor) and v.layout == torch.strided and v.dtype == torch.uint8 and v.shape == like.shape


def check_fields(state: dict, refuse) -> None:
    """Keys, types and ranges of a checkpoint's own fields (the network's are ``check_fits``);
    ``refuse(why)`` makes the error. Nothing of it is used before this passes."""
    import torch

    rules = {
        "step": (_nonneg_int, _INT),
        "epoch": (_nonneg_int, _INT),
        "position": (_nonneg_int, _INT),
        "wall_time": (_nonneg_number, "a finite number >= 0"),
        "next_eval": (_nonneg_number, "a finite number >= 0"),
        "last_eval_step": (lambda v: type(v) is int and v >= -1, "an integer >= -1"),
        "batch_losses": (lambda v: type(v) is list and all(type(x) in (int, float) for x in v), "a list of numbers"),
        "model": (lambda v: isinstance(v, dict) and all(isinstance(k, str) for k in v), "a mapping of weights"),
        "optimizer": (lambda v: isinstance(v, dict), "an optimizer state"),
        "shuffle_epoch_start": (lambda v: _rng_state(v, torch.Generator().get_state()), "a torch generator state"),
        "torch_rng": (lambda v: _rng_state(v, torch.get_rng_state()), "a torch generator state"),
        "rows": (_rows, "{group: {table: rows}} with integer counts"),
    }  # run_id: compared with the run file's next (none, or another: "belongs to another run")
    for key, (ok, what) in rules.items():
        if key not in state:
            raise refuse(f"has no {key}")
        if not ok(state[key]):
            raise refuse(f"has {key}={_brief(state[key])}, not {what}")
    cuda = state.get("cuda_rng")
    if not (cuda is None or (_rng_state(cuda, cuda) and cuda.dim() == 1 and cuda.numel() <= 1 << 16)):
        raise refuse(f"has cuda_rng={_brief(cuda)}, not a CUDA generator state")
    if "peak_rss_mb" in state and not _nonneg_number(state["peak_rss_mb"]):
        raise refuse(f"has peak_rss_mb={_brief(state['peak_rss_mb'])}, not a finite number >= 0")
    step = state["step"]
    for key, bound in (("epoch", step), ("position", step), ("last_eval_step", step)):
        if state[key] > bound:
            raise refuse(f"has {key}={state[key]}, beyond its step ({step})")
    if len(state["batch_losses"]) > step:
        raise refuse(f"holds {len(state['batch_losses'])} batch losses, more than its {step} updates")


def _rows(v) -> bool:
    return isinstance(v, dict) and all(
        isinstance(g, str) and isinstance(t, dict) and all(isinstance(n, str) and _nonneg_int(c) for n, c in t.items())
        for g, t in v.items()
    )


def _brief(v) -> str:
    """A value as an error line shows it: a tensor by its type and shape, anything else short."""
    import torch

    if isinstance(v, torch.Tensor):
        return f"<{v.layout} {v.dtype} tensor {tuple(v.shape)} on {v.device}>"
    text = show(v) if isinstance(v, (int, float, str, bool, type(None))) else f"<{type(v).__name__}>"
    return text if len(text) <= 60 else text[:57] + "..."


def check_fits(state: dict, model, optimizer, batches_per_epoch: int | None, resume_value: Any, path: Path) -> None:
    """The checkpoint's weights and optimizer state fit the network and optimizer built from
    the run's stored config: the same keys, dtypes and shapes, dense tensors, ranges. Run
    before the run file is reopened; ``ConfigError`` on ``resume`` otherwise."""

    def refuse(why: str) -> ConfigError:
        return ConfigError("resume", resume_value, f"checkpoint {path.name} {why}")

    ours = model.state_dict()
    theirs = state["model"]
    if set(theirs) != set(ours):
        missing, extra = sorted(set(ours) - set(theirs)), sorted(set(theirs) - set(ours))
        raise refuse(f"does not fit this run's network (missing {missing[:3]}, unknown {extra[:3]})")
    for key, mine in ours.items():
        t = theirs[key]
        if not _dense_like(t, mine.dtype, mine.shape):
            raise refuse(f"has {key}={_brief(t)}; the network has {mine.dtype} {tuple(mine.shape)}")
    if batches_per_epoch is not None and state["position"] > batches_per_epoch:
        raise refuse(f"has position={state['position']}, beyond the {batches_per_epoch} batches of an epoch")
    if _standard_layout(optimizer):
        _check_optimizer_state(state["optimizer"], optimizer, refuse)
    else:  # another layout (a split optimizer, Shampoo's preconditioners): plain values, bounded sizes
        params = [p for g in optimizer.param_groups for p in g["params"]]
        largest = max([p.numel() for p in params] + [d for p in params for d in p.shape] + [1])
        _check_plain_tree(state["optimizer"], 4 * max(sum(p.numel() for p in params), largest**2), refuse)


def _standard_layout(optimizer) -> bool:
    """torch.optim's classes and higbench's Jacobian-power family: torch's state_dict layout,
    per-parameter state shaped as the parameter (or scalars, or L-BFGS's flat histories)."""
    from higbench.optim.contract import uses_jacobian

    return type(optimizer).__module__.startswith("torch.optim") or uses_jacobian(optimizer)


def _check_plain_tree(node, max_numel: int, refuse, depth: int = 0, key: str = "optimizer") -> None:
    """Containers of plain values and dense real tensors of at most ``max_numel`` elements."""
    import torch

    if depth > 16:
        raise refuse(f"nests its {key} more than 16 levels")
    if isinstance(node, dict):
        items = node.items()
    elif isinstance(node, (list, tuple)):
        items = enumerate(node)
    elif isinstance(node, torch.Tensor):
        if node.layout != torch.strided or node.device.type == "meta" or node.is_complex() or node.numel() > max_numel:
            raise refuse(f"has {key}={_brief(node)}, not a dense real tensor of at most {max_numel:,} elements")
        return
    elif node is None or type(node) in (bool, int, float, str) or isinstance(node, torch.dtype):
        return
    else:
        raise refuse(f"has {key} of type {type(node).__name__}")
    if len(node) > 100_000:
        raise refuse(f"has {key} with {len(node):,} entries")
    for k, v in items:
        _check_plain_tree(v, max_numel, refuse, depth + 1, f"{key}.{k}")


def _dense_like(t, dtype, shape) -> bool:
    import torch

    return (
        isinstance(t, torch.Tensor)
        and t.layout == torch.strided
        and t.device.type != "meta"
        and t.dtype == dtype
        and t.shape == shape
    )


def _check_optimizer_state(saved: dict, optimizer, refuse) -> None:
    """Param groups as the fresh optimizer's (the same parameters, hyper-parameters of the same
    kinds), per-parameter state of real tensors shaped as their parameter (or scalars, or
    L-BFGS's flat vectors and bounded histories)."""
    import torch

    if not {"state", "param_groups"} <= set(saved):
        raise refuse("has an optimizer state without state or param_groups")
    fresh = optimizer.state_dict()
    groups = saved["param_groups"]
    if not isinstance(groups, list) or len(groups) != len(fresh["param_groups"]):
        raise refuse("has an optimizer state of another optimizer (its parameter groups differ)")
    params: dict[int, torch.Tensor] = {}
    for mine, theirs in zip(fresh["param_groups"], groups, strict=True):
        if not isinstance(theirs, dict) or set(theirs) != set(mine) or theirs["params"] != mine["params"]:
            raise refuse("has an optimizer state of another optimizer (its parameter groups differ)")
        for key, value in theirs.items():
            if key != "params" and not _same_kind(value, mine[key]):
                raise refuse(f"has optimizer {key}={_brief(value)}; this optimizer has {_brief(mine[key])}")
    ordered = [p for g in optimizer.param_groups for p in g["params"]]
    params = {i: p for i, p in enumerate(ordered)}
    flat = sum(p.numel() for p in ordered)
    history = max([int(g.get("history_size", 0) or 0) for g in groups] + [0]) + 1
    state = saved["state"]
    if not isinstance(state, dict) or not set(state) <= set(params):
        raise refuse("has optimizer state for parameters this network does not have")
    for index, entries in state.items():
        param = params[index]
        if not isinstance(entries, dict):
            raise refuse(f"has optimizer state {index} of type {type(entries).__name__}")
        for key, value in entries.items():
            values = value if isinstance(value, list) else [value]
            if isinstance(value, list) and len(value) > history:
                raise refuse(f"has optimizer {key} with {len(value)} entries (at most {history})")
            for v in values:
                if not _state_value_fits(v, param, flat):
                    raise refuse(f"has optimizer {key}={_brief(v)} for a parameter of shape {tuple(param.shape)}")


def _same_kind(value, mine) -> bool:
    numbers = (int, float)
    if mine is None or value is None:  # set as it runs (LM's damping lam starts unset)
        return value is None or (type(value) in numbers and math.isfinite(value)) or type(value) in (str, bool)
    if type(mine) in numbers and type(value) in numbers:
        return math.isfinite(value)
    if isinstance(mine, (tuple, list)) and isinstance(value, (tuple, list)):
        return len(mine) == len(value) and all(_same_kind(a, b) for a, b in zip(value, mine, strict=True))
    return type(value) is type(mine)


def _state_value_fits(v, param, flat: int) -> bool:
    import torch

    if v is None:  # L-BFGS before its first direction (al, d)
        return True
    if type(v) in (int, float):
        return math.isfinite(v) or v != v  # L-BFGS keeps prev_loss; NaN is a value it may hold
    if not isinstance(v, torch.Tensor):
        return False
    if v.layout != torch.strided or v.device.type == "meta" or v.is_complex() or v.dtype == torch.bool:
        return False
    return v.numel() == 1 or v.shape == param.shape or (v.dim() == 1 and v.numel() == flat)


def _check_run_id(state: dict, head: RunHead, resume_value: Any) -> None:
    run_file, file_id = head.path, str(head.run_id or "")
    ckpt_id = str(state.get("run_id") or "")
    if ckpt_id != file_id:
        raise ConfigError(
            "resume",
            resume_value,
            f"checkpoint {checkpoint_path(run_file).name} belongs to another run "
            f"(its run id {ckpt_id or '<none>'}, the run file's {file_id or '<none>'}); refusing to resume from it",
        )


def remove(run_path: str | Path) -> None:
    checkpoint_path(run_path).unlink(missing_ok=True)
    remove_stale_temporaries(run_path)


def remove_stale_temporaries(run_path: str | Path) -> None:
    """Temporary files of checkpoint writers that died mid-save (a run file has one writer:
    its file lock keeps a second one out). ``unlink`` removes a link, never its target."""
    final = checkpoint_path(run_path)
    for p in final.parent.glob(f"{final.name}{TMP_MARK}*"):
        with contextlib.suppress(OSError):
            if stat.S_ISREG(p.lstat().st_mode) or p.is_symlink():
                p.unlink()


def check_owner(state: dict[str, Any], head: RunHead, resume_value: Any) -> None:
    """Refuse a checkpoint that is not of the run file ``head`` describes (its run_id differs)
    or records more rows than the file holds. Called before anything in the state is used."""
    _check_run_id(state, head, resume_value)
    short = [
        f"{group}/{name} has {head.rows.get(group, {}).get(name, 0)}, the checkpoint {n}"
        for group, names in (state.get("rows") or {}).items()
        for name, n in names.items()
        if head.rows.get(group, {}).get(name, 0) < n
    ]
    updates = max(head.rows.get("updates", {}).values(), default=0)
    if state.get("step", 0) > updates:  # every update recorded before the checkpoint has its row
        raise ConfigError(
            "resume", resume_value, f"its checkpoint is at step {state['step']}, the run file records {updates} updates"
        )
    if short:
        raise ConfigError(
            "resume", resume_value, f"the run file holds fewer rows than its checkpoint records ({short[0]}); cannot resume"
        )


def _why(exc: UnreadableRunFile) -> str:
    """What to say of an unreadable run file: the error's name, or what was refused in it."""
    return exc.detail.split(": ", 1)[-1] if exc.kind == "refused" else exc.kind


# -- resolving what to resume ----------------------------------------------------------------


def run_file_of(resume: Any, run_dir: str | Path | None) -> Path:
    """The run file that ``resume=<value>`` designates (``true``: the one in ``run_dir``)."""
    if resume is True:
        if run_dir is None:
            raise ConfigError("resume", True, "needs hydra.run.dir=<run dir>, or give the run: resume=<run dir or run file>")
        return Path(run_dir) / RUN_FILE_NAME
    p = Path(str(resume)).expanduser()
    return run_file_path(p)


def inspect_run(run_file: Path, resume_value: Any) -> RunHead:
    """The head of a run to resume (status, stored config, rows); ConfigError if it cannot be resumed."""
    if run_file.is_symlink():  # the run would go on elsewhere while its checkpoint and logs stay here
        why = f"{run_file} is a symbolic link (to {os.readlink(run_file)}); resume runs in their own directory"
        raise ConfigError("resume", resume_value, why)
    if not run_file.is_file():
        raise ConfigError("resume", resume_value, f"no run file {run_file}")
    links = run_file.stat().st_nlink
    if links > 1:  # resume writes it in place: a snapshot sharing its inode (cp -al) would change too
        why = f"{run_file} has {links} hard links (a snapshot shares it); resume writes in place: copy it (cp, not cp -l) first"
        raise ConfigError("resume", resume_value, why)
    try:  # with file locking: a live writer holds the file, and we must not write into it
        head = read_head(run_file, locking=True)
    except RunFileLocked:
        raise ConfigError("resume", resume_value, f"{run_file} is open in another process (that run is still going)") from None
    except UnreadableRunFile as exc:
        raise ConfigError("resume", resume_value, f"{run_file} is not a readable run file ({_why(exc)})") from None
    status, config = str(head.attrs.get("status", "")), head.config_yaml
    if status not in RESUMABLE_STATUSES:
        raise ConfigError(
            "resume", resume_value, f"run is {status}, nothing to resume (resumable: {', '.join(RESUMABLE_STATUSES)})"
        )
    if not checkpoint_path(run_file).is_file():
        every = _checkpoint_every(config)
        why = (
            "set checkpoint_every to make runs resumable"
            if every is None
            else f"it stopped before its first checkpoint, due after {every} s of training clock"
        )
        raise ConfigError("resume", resume_value, f"no checkpoint next to {run_file} ({why})")
    if not config:
        raise ConfigError("resume", resume_value, f"{run_file} holds no config")
    return head


def _checkpoint_every(config_yaml: str):
    import yaml

    try:
        return (yaml.safe_load(config_yaml) or {}).get("checkpoint_every")
    except Exception:  # noqa: BLE001
        return None


def override_keys(overrides: list[str]) -> list[tuple[str, str]]:
    """(key, override text) of command-line overrides, parsed by Hydra's own grammar."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parsed = OverridesParser.create().parse_overrides(list(overrides))
    return [(o.key_or_group, o.input_line) for o in parsed]


def resume_config(stored: dict, composed: dict, overrides: list[str]) -> dict:
    """The stored config of the run, with the command-line changes that resuming allows.

    ``composed``: the config Hydra composed for this invocation; ``overrides``: the task
    overrides given on the command line. A key outside ``RESUMABLE_KEYS`` may be repeated
    with the run's own value (re-running the same command with ``resume=...``) but not
    changed: that would be another experiment.
    """
    merged = copy.deepcopy(stored)
    for key, line in override_keys(overrides):
        if key.startswith("hydra.") or key == "hydra":
            continue
        top = key.split(".")[0]
        new = dotted_get(composed, key)
        if top in RESUMABLE_KEYS:
            if new is not ABSENT:
                dotted_set(merged, key, new)
            continue
        old = dotted_get(stored, key)
        if new is ABSENT or old is ABSENT or new != old:
            shown = "<absent>" if old is ABSENT else show(old)
            raise ConfigError(
                key,
                line.split("=", 1)[-1],
                f"cannot change when resuming (the run has {key}={shown}); resumable keys: {', '.join(RESUMABLE_KEYS)}",
            )
    merged["resume"] = None
    return merged


# -- run dirs that recorded nothing ----------------------------------------------------------

EMPTY_FILE_BYTES = 64 * 1024  # an unopenable file this small was killed while being created


def recorded_nothing(run_file: Path) -> str | None:
    """Why ``run_file`` holds nothing worth keeping, or None (it does, or a process holds it).

    Nothing worth keeping: a file that is not an openable HDF5 file and is at most a few
    KiB (a run killed while it was being created), or a run that stopped (status running,
    interrupted or failed, no writer alive) before recording a single update and left no
    checkpoint. Such a run may be started again in place; its file is moved aside first.
    """
    run_file = Path(run_file)
    if not run_file.is_file() or checkpoint_path(run_file).exists():
        return None
    try:
        head = read_head(run_file, locking=True)  # a live writer on this host holds the lock
    except RunFileLocked:
        return None
    except UnreadableRunFile:
        try:  # readable without locking (a file system without locks): judged by its content
            read_head(run_file, locking=False)
        except UnreadableRunFile:  # not HDF5, truncated header
            if run_file.stat().st_size <= EMPTY_FILE_BYTES:
                return f"unreadable {run_file.stat().st_size}-byte file, killed while it was being created"
        return None
    status = str(head.attrs.get("status", ""))
    if status in RESUMABLE_STATUSES and head.n_updates == 0:
        return f"status {status}, no update recorded, no checkpoint"
    return None


def stopped_without_checkpoint(run_file: Path) -> str | None:
    """Why a sweep job's run must run again from the start, or None: it stopped (status
    running, interrupted or failed, no writer alive on this host) before its first
    checkpoint, so nothing can continue it. A sweep stopped with Ctrl-C hard-kills the
    parallel workers that were not yet writing one; the sweep's resume command reruns them
    (the stopped file is moved aside, never deleted)."""
    run_file = Path(run_file)
    if not run_file.is_file() or checkpoint_path(run_file).exists():
        return None
    try:
        head = read_head(run_file, locking=True)  # a live writer on this host holds the lock
    except UnreadableRunFile:
        return None
    status = str(head.attrs.get("status", ""))
    if status in RESUMABLE_STATUSES:
        return f"stopped ({status}) after {head.n_updates} updates, before its first checkpoint"
    return None


def move_aside(path: Path, label: str) -> Path:
    """Rename ``path`` to ``<name>.<label>-<time>`` beside it (never deleted: nothing is lost)."""
    path = Path(path)
    target = path.with_name(f"{path.name}.{label}-{time.strftime('%Y%m%d-%H%M%S')}")
    n = 1
    while target.exists():
        target = path.with_name(f"{path.name}.{label}-{time.strftime('%Y%m%d-%H%M%S')}-{n}")
        n += 1
    os.replace(path, target)
    return target
