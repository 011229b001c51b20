"""Checkpoints: save, load, and the checks that one fits its run (to continue it exactly).

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
``run_id`` is compared with the run file's before anything in it is used.

The runner writes one every ``checkpoint_every`` seconds of training clock (null: off)
and one when it stops on SIGINT/SIGTERM; ``resume=`` is planned by ``runner.plan``.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import stat
import tempfile
import time
import zipfile
from pathlib import Path
from typing import Any

from higbench.errors import ConfigError, show
from higbench.runfile.reader import RunHead
from higbench.runfile.writer import RESERVE_BYTES, DiskFull, RunFileFault, free_bytes

SUFFIX = ".ckpt"
FORMAT = 1  # every format-1 checkpoint holds only tensors and plain containers
READABLE_FORMATS = (1,)
TMP_MARK = ".tmp"  # temporaries: run.h5.ckpt.tmp<random>


def checkpoint_path(run_path: str | Path) -> Path:
    return Path(run_path).with_name(Path(run_path).name + SUFFIX)


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
        need = f"{free // 1024} KiB free, it needs {len(data) // 1024} KiB plus the reserve for closing the run file"
        raise DiskFull(f"no space left for checkpoint {final} ({need}); run stopped before writing")
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
    except BaseException as exc:
        if tmp is not None:
            tmp.unlink(missing_ok=True)  # the previous checkpoint stays as it was
        if isinstance(exc, OSError):
            raise RunFileFault(exc.errno, f"cannot write checkpoint {final} ({exc.strerror or exc}); run stopped") from None
        raise
    with contextlib.suppress(OSError):  # make the rename itself durable
        fd = os.open(final.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    return final


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def load(head: RunHead, resume_value: Any) -> dict[str, Any]:
    """The checkpoint of the run file ``head`` describes: checked, deserialised without running
    code, and of this very run file (``check_owner``).

    Refused (``ConfigError`` on ``resume``): a missing checkpoint, a link, anything but a
    torch zip archive of uncompressed records (a plain pickle is never unpickled), an archive
    holding any object but tensors and plain containers (``weights_only=True``: torch's
    restricted unpickler constructs nothing else and calls no function), another format, a
    checkpoint of another run, or of more rows than its run file holds.
    """
    path, value = checkpoint_path(head.path), resume_value

    def refuse(why: str) -> ConfigError:
        return ConfigError("resume", value, f"checkpoint {path.name} {why}")

    if not os.path.lexists(path):
        why = f"no checkpoint {path.name} next to the run file (was checkpoint_every null and the run killed?)"
        raise ConfigError("resume", value, why)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        link = "is a symbolic link; checkpoints are never read through links"
        raise refuse(link if os.path.islink(path) else f"cannot be opened ({exc.strerror})") from None
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
    check_owner(state, head, value)
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


def check_fits(state: dict, model, optimizer, batches_per_epoch: int | None, run_path: Path) -> None:
    """The checkpoint's weights and optimizer state fit the network and optimizer built from
    the run's stored config: the same keys, dtypes and shapes, dense tensors, ranges. Run
    before the run file is reopened; ``ConfigError`` on ``resume`` otherwise."""

    def refuse(why: str) -> ConfigError:
        return ConfigError("resume", str(run_path), f"checkpoint {checkpoint_path(run_path).name} {why}")

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
    from higbench.optim.contract import uses_jacobian

    # torch.optim's classes and higbench's Jacobian-power family: torch's state_dict layout,
    # per-parameter state shaped as the parameter (or scalars, or L-BFGS's flat histories)
    if type(optimizer).__module__.startswith("torch.optim") or uses_jacobian(optimizer):
        _check_optimizer_state(state["optimizer"], optimizer, refuse)
    else:  # another layout (a split optimizer, Shampoo's preconditioners): plain values, bounded sizes
        params = [p for g in optimizer.param_groups for p in g["params"]]
        largest = max([p.numel() for p in params] + [d for p in params for d in p.shape] + [1])
        _check_plain_tree(state["optimizer"], 4 * max(sum(p.numel() for p in params), largest**2), refuse)


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

    dense = isinstance(t, torch.Tensor) and t.layout == torch.strided and t.device.type != "meta"
    return dense and t.dtype == dtype and t.shape == shape


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


def remove(run_path: str | Path) -> None:
    """A run that ended (completed, diverged) has nothing left to resume."""
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
    file_id, ckpt_id = str(head.run_id or ""), str(state.get("run_id") or "")
    if ckpt_id != file_id:
        why = f"(its run id {ckpt_id or '<none>'}, the run file's {file_id or '<none>'}); refusing to resume from it"
        raise ConfigError("resume", resume_value, f"checkpoint {checkpoint_path(head.path).name} belongs to another run {why}")
    short = [
        f"{group}/{name} has {head.rows.get(group, {}).get(name, 0)}, the checkpoint {n}"
        for group, names in (state.get("rows") or {}).items()
        for name, n in names.items()
        if head.rows.get(group, {}).get(name, 0) < n
    ]
    updates = max(head.rows.get("updates", {}).values(), default=0)
    if state.get("step", 0) > updates:  # every update recorded before the checkpoint has its row
        why = f"its checkpoint is at step {state['step']}, the run file records {updates} updates"
        raise ConfigError("resume", resume_value, why)
    if short:
        why = f"the run file holds fewer rows than its checkpoint records ({short[0]}); cannot resume"
        raise ConfigError("resume", resume_value, why)
