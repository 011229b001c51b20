"""The plan of one run: what it trains, where it writes, and the inputs it reads, decided once.

``make_plan`` turns a composed, validated config and the job's output directory into a
``Plan``, an immutable value. Everything a run reads from disk is read here, once, before
anything is written: the stored config of a run to continue, its checkpoint (checked whole
against its schema and its run file's ``run_id``), the ``init_from`` run's final weights.
``runner.train.train(plan)`` then builds the problem, the network and the optimizer once,
checks these inputs against them (shapes, memory) before its run file exists, and trains.

What an existing directory means (the output policy):

* ``new``: no run file there; one is created (never over another run's).
* ``resume``: ``resume=<run>``: the run continues from its checkpoint, in place.
* ``restart``: the run file there recorded nothing (killed while being created, or stopped
  before its first update or checkpoint); it is moved aside and the run starts again.
* ``keep``: a sweep job whose directory already holds a run that is not continued.

A stored config is someone else's file: it may never make higbench build a callable that no
higbench config registers (``check_stored_targets``) nor open a file the user did not name
on this command line (``check_stored_paths``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any, Literal

from omegaconf import OmegaConf

from higbench.config import validate
from higbench.errors import ConfigError, dotted_get, given_value
from higbench.runfile.reader import RUN_FILE

Policy = Literal["new", "resume", "restart", "keep"]

# Everything higbench (and Hydra for it) writes in a run directory: none may be a link.
WRITTEN_NAMES = (".hydra", *(f".hydra/{n}.yaml" for n in ("config", "hydra", "overrides")), "higbench.log")
WRITTEN_NAMES += (RUN_FILE, f"{RUN_FILE}.ckpt")
PATH_KEYS = ("init_from",)  # config keys naming a file higbench opens


@dataclasses.dataclass(frozen=True)
class Plan:
    """One run, decided: its config, its run file and what to do with it, the inputs it reads.

    ``config`` is the validated task config (a continued run's stored config with the changes
    resuming allows); ``initial_weights`` the ``init_from`` run's final weights; ``checkpoint``
    the state a continued run starts from. Neither is read again by the run.
    """

    config: Mapping[str, Any]
    run_path: Path
    policy: Policy = "new"
    why: str = ""  # restart: why the file there recorded nothing; keep: why the run stays as it is
    initial_weights: Mapping[str, Any] | None = None
    checkpoint: Mapping[str, Any] | None = None
    overrides: tuple[str, ...] = ()  # the command line's task overrides (the run file records them)
    parallel_jobs: int = 1  # jobs of this sweep sharing the machine (the run file's /env records it)
    stop_with_parent: int | None = None  # a launcher worker's parent pid: the run stops cleanly once it is gone

    @property
    def resume(self) -> bool:
        return self.policy == "resume"

    @property
    def restart(self) -> bool:
        return self.policy == "restart"

    @property
    def kept(self) -> bool:
        return self.policy == "keep"

    def task(self) -> dict:
        """The config as a plain dict (a copy: the plan stays as it was)."""
        import copy

        return copy.deepcopy(dict(self.config))

    def start_config(self):
        """The config the start line shows: the stored run's when it resumes."""
        from omegaconf import OmegaConf

        return OmegaConf.create({**self.task(), "resume": True if self.resume else None})

    def in_sweep(self, parallel_jobs: int, stop_with_parent: int | None) -> Plan:
        """The plan of a sweep's job: how many jobs share the machine, and the pid of the
        launcher whose exit must stop it (a worker process), if any."""
        return dataclasses.replace(self, parallel_jobs=int(parallel_jobs), stop_with_parent=stop_with_parent)

    @classmethod
    def for_run(cls, cfg, run_path: str | Path, *, resume: bool = False, overrides=()) -> Plan:
        """The plan of a config that is already validated, for code that calls ``train`` itself
        (tests, notebooks): its ``init_from`` weights or, with ``resume``, its checkpoint loaded."""
        from higbench.config import to_plain

        task = to_plain(cfg)
        run_path = Path(run_path)
        if resume:
            state = _load_checkpoint(run_path, str(run_path))
            return cls(_frozen(task), run_path, "resume", checkpoint=state, overrides=tuple(overrides))
        return cls(_frozen(task), run_path, initial_weights=load_initial_weights(task), overrides=tuple(overrides))


def _frozen(task: dict) -> Mapping[str, Any]:
    return MappingProxyType(task)


# -- inputs, read once -----------------------------------------------------------------------


def load_initial_weights(task: Mapping) -> dict | None:
    """``init_from``: the final weights of an existing, readable, finished run of the same
    problem (ConfigError otherwise). Their shapes are checked against the network in
    ``runner.train`` once it is built, still before anything is written."""
    import numpy as np

    from higbench.runfile.reader import UnreadableRunFile, read_head, run_file_path

    path = task.get("init_from")
    if not path:
        return None
    problem_name = task["problem"]["name"]
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


def _load_checkpoint(run_path: Path, resume_value, head=None) -> dict:
    """The checkpoint of the run to continue, checked whole, and of this very run file
    (``head``: the run file's head, already read)."""
    from higbench.runfile.reader import UnreadableRunFile, read_head
    from higbench.runner import checkpoint

    state = checkpoint.load(run_path, resume_value)
    if head is None:
        try:
            head = read_head(run_path)
        except UnreadableRunFile as exc:
            raise ConfigError("resume", resume_value, f"{run_path} is not a readable run file ({exc})") from None
    checkpoint.check_owner(state, head, resume_value)
    return state


# -- the decision -----------------------------------------------------------------------------


def make_plan(task: dict, output_dir: Path, overrides: list[str], *, multirun: bool) -> Plan:
    """The one decision about a job (ConfigError when it must not run): its policy, its
    config and its inputs. ``task`` is the composed config (validated unless it resumes)."""
    from higbench.runner.output_location import check_output_dir

    output_dir, overrides = Path(output_dir), tuple(overrides)
    if task.get("resume"):
        return _resume_plan(task, output_dir, overrides, multirun=multirun)
    run_path = output_dir / RUN_FILE
    check_output_dir(output_dir, "hydra.run.dir", RUN_FILE)
    check_no_links(output_dir, "hydra.run.dir")
    check_tensorboard_dir(task, output_dir, "hydra.run.dir")
    policy, why = "new", ""
    if os.path.lexists(run_path):
        policy, why = _existing_run(run_path, output_dir, multirun)
    if policy == "keep":
        return Plan(_frozen(task), run_path, "keep", why, overrides=overrides)
    return Plan(_frozen(task), run_path, policy, why, initial_weights=load_initial_weights(task), overrides=overrides)


def _existing_run(run_path: Path, output_dir: Path, multirun: bool) -> tuple[Policy, str]:
    from higbench.runner import checkpoint

    empty = checkpoint.recorded_nothing(run_path)
    if empty:
        return "restart", empty
    if multirun:  # a sweep run again into its directory: its runs stay as they are
        return "keep", "already holds a run (resume=true completes interrupted and failed jobs)"
    raise ConfigError(
        "hydra.run.dir",
        str(output_dir),
        f"already holds a run file ({RUN_FILE}); refusing to overwrite it "
        f"(resume={output_dir} continues it, or pick a new hydra.run.dir)",
    )


def _resume_plan(task: dict, output_dir: Path, overrides: tuple[str, ...], *, multirun: bool) -> Plan:
    """``resume=``: continue the run from its checkpoint, or start it again when it recorded
    nothing; a sweep job that never started starts now."""
    from higbench.runner import checkpoint
    from higbench.runner.output_location import check_output_dir

    resume = task["resume"]
    run_path = checkpoint.run_file_of(resume, output_dir)
    check_output_dir(run_path.parent, "resume")
    check_no_links(run_path.parent, "resume")
    fresh = {**task, "resume": None}
    if multirun and not run_path.exists():
        plan = Plan(_frozen(fresh), run_path, overrides=overrides)
    elif multirun and checkpoint.stopped_without_checkpoint(run_path):
        # killed with its sweep before its first checkpoint: it runs again from the start
        why = checkpoint.stopped_without_checkpoint(run_path)
        plan = Plan(_frozen(fresh), run_path, "restart", why, overrides=overrides)
    else:
        plan = _continue_or_restart(task, run_path, overrides, multirun=multirun)
    check_tensorboard_dir(plan.config, run_path.parent, "resume")
    if plan.policy == "resume":
        return plan
    validate(plan.task())
    return dataclasses.replace(plan, initial_weights=load_initial_weights(plan.config))


def _continue_or_restart(task: dict, run_path: Path, overrides: tuple[str, ...], *, multirun: bool) -> Plan:
    from higbench.runner import checkpoint

    resume = task["resume"]
    empty = checkpoint.recorded_nothing(run_path)
    if empty:
        stored = task if multirun else _parse_stored(_stored_config(run_path, resume), resume)
    else:
        head = checkpoint.inspect_run(run_path, resume)
        stored = _parse_stored(head.config_yaml, resume)
    check_stored_targets(stored, task, resume)  # before anything of it is built
    merged = checkpoint.resume_config(stored, task, list(overrides))
    if empty:  # started again from its stored config: it would read the file its init_from names
        check_stored_paths(stored, list(overrides), resume)
        return Plan(_frozen(merged), run_path, "restart", empty, overrides=overrides)
    # continued: the weights are the checkpoint's; the stored init_from is a record, never opened
    validate({**merged, "init_from": None})
    state = _load_checkpoint(run_path, resume, head)
    return Plan(_frozen(merged), run_path, "resume", checkpoint=state, overrides=overrides)


def _parse_stored(yaml_text: str, resume_value) -> dict:
    """A stored config, parsed with the run-file reader's bounds (size, aliases expanded)."""
    from higbench.runfile.reader import UnreadableRunFile, parse_config

    try:
        return parse_config(yaml_text)
    except UnreadableRunFile as exc:
        raise ConfigError("resume", resume_value, f"its stored config is refused: {exc}") from None


def _stored_config(run_file: Path, resume_value) -> str:
    """Config YAML of a run: from its run file, else (a file killed at creation) Hydra's copy."""
    from higbench.runfile.reader import UnreadableRunFile, read_head

    with contextlib.suppress(UnreadableRunFile):
        stored = read_head(run_file).config_yaml
        if stored:
            return stored
    saved = run_file.parent / ".hydra" / "config.yaml"
    if saved.is_file() and not saved.is_symlink():
        return saved.read_text()
    raise ConfigError("resume", resume_value, f"{run_file} recorded nothing and its config is unknown (no .hydra/config.yaml)")


# -- what a directory and a stored config may make higbench do --------------------------------


def check_no_links(out: Path, key: str) -> None:
    """Refuse a run directory where something higbench writes is a symbolic link."""
    for name in WRITTEN_NAMES:
        path = Path(out) / name
        if path.is_symlink():
            why = f"{path} is a symbolic link (to {os.readlink(path)}); higbench never writes through links"
            raise ConfigError(key, str(out), why)


def check_tensorboard_dir(task: Mapping, out: Path, key: str) -> None:
    """TensorBoard asked for (``tensorboard=true`` or ``sink=tensorboard``): its directory in
    the run dir is absent or a real directory (a link would take the event files elsewhere; a
    file or a dangling link would fail mid-run)."""
    from higbench.runner.sinks import side_sink_specs
    from higbench.runner.tensorboard import TENSORBOARD_DIR

    path = Path(out) / TENSORBOARD_DIR
    if "tensorboard" not in side_sink_specs(task) or not os.path.lexists(path):
        return
    if path.is_symlink():
        why = f"{path} is a symbolic link (to {os.readlink(path)}); higbench never writes through links"
        raise ConfigError(key, str(out), why)
    if not path.is_dir():
        raise ConfigError(key, str(out), f"{path} exists and is not a directory; tensorboard=true writes its event files there")


# The config groups whose files may name a class to build: where a stored config's ``_target_``s
# may come from (problem_optimizer and experiment files set keys of these nodes).
TARGET_GROUPS = ("problem", "optimizer", "sink", "problem_optimizer", "experiment")


def registered_targets() -> dict[str, set[str]]:
    """Where a config may name a class, and which: ``{key: {target, ...}}`` for every ``_target_``
    that a config file in Hydra's search path (conf/, and ``hydra.searchpath`` given on the
    command line) sets, at the key it sets it (``optimizer._target_``, the nested
    ``optimizer.parts.PART._target_`` of muon.yaml, ``sink.tensorboard._target_``), and
    every registered Problem class at ``problem._target_``."""
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.object_type import ObjectType

    from higbench.config import config_dir
    from higbench.problems.base import registry

    if not GlobalHydra.instance().is_initialized():
        from hydra import initialize_config_dir

        with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
            return registered_targets()
    targets: dict[str, set[str]] = {"problem._target_": {f"{c.__module__}.{c.__qualname__}" for c in registry().values()}}
    for source in GlobalHydra.instance().config_loader().get_sources():
        for group in TARGET_GROUPS:
            if not source.is_group(group):
                continue
            for name in source.list(group, ObjectType.CONFIG):
                with contextlib.suppress(Exception):  # a YAML that does not load names nothing
                    loaded = source.load_config(f"{group}/{name}")
                    package = loaded.header.get("package") or group  # Hydra's default package: the group
                    prefix = "" if package == "_global_" else f"{package.removeprefix('_global_.')}."
                    for key, target in _targets(OmegaConf.to_container(loaded.config), prefix):
                        targets.setdefault(key, set()).add(str(target))
    return targets


def check_stored_targets(stored: dict, composed: Mapping, resume_value) -> None:
    """Refuse a stored config (a run file's, or .hydra/config.yaml) naming a ``_target_`` that
    no config file sets at that key (``registered_targets``) and this command line does not
    name there either: it would be built (called) before anything else is checked."""
    registered, composed = registered_targets(), dict(composed)
    for key, target in _targets(stored):
        if str(target) not in registered.get(key, set()) and str(target) != str(dotted_get(composed, key, "")):
            why = f"its stored config names {key}={target}, which no config file sets there; refusing to build it"
            raise ConfigError("resume", resume_value, why)


def check_stored_paths(stored: dict, overrides: list[str], resume_value) -> None:
    """A stored config (someone else's file) never makes higbench open a file: a path it
    names must be given again on this command line, where the user names what is opened."""
    for key in PATH_KEYS:
        path = stored.get(key)
        if path and given_value(overrides, key) != str(path):
            why = (
                f"its stored config names {key}={path}; a stored config never makes higbench open a file: "
                f"give {key}={path} on the command line to start it again from that file"
            )
            raise ConfigError("resume", resume_value, why)


def _targets(node, prefix: str = ""):
    if isinstance(node, dict):
        for k, v in node.items():
            if k == "_target_":
                yield f"{prefix}{k}", v
            yield from _targets(v, f"{prefix}{k}.")
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _targets(v, f"{prefix}{i}.")
