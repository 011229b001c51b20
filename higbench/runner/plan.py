"""The plan of one run: what it trains, where it writes, and the inputs it reads, decided once.

``make_plan`` turns a composed config and the job's output directory into a ``Plan``, an
immutable value with typed parts: ``run`` (the top-level keys as a ``config.RunConfig``),
``problem`` (its config node), ``optimizer`` (its class and checked arguments, resolved once
by ``config.validate``) and ``dir`` (the ``RunDir``, ``runner.rundir``: every question about
what the directory already holds is answered there). Everything a run reads from disk is read
here, once, before anything is written: the stored config of a run to continue, its checkpoint
(checked whole against its schema and its run file's ``run_id``), the ``init_from`` run's
final weights. ``runner.train.train(plan)`` then builds the problem, the network and the
optimizer once, checks these inputs against them (shapes, memory) before its run file exists,
and trains.

What an existing directory means (the output policy):

* ``new``: no run file there; one is created (never over another run's).
* ``resume``: ``resume=<run>``: the run continues from its checkpoint, in place.
* ``restart``: the run file there recorded nothing (killed while being created, or stopped
  before its first update or checkpoint); it is moved aside and the run starts again.
* ``keep``: a sweep job whose directory already holds a run that is not continued.

A stored config is someone else's file: it may never make higbench build a callable that no
higbench config registers (``check_stored_targets``) nor open a file the user did not name
on this command line (``check_stored_paths``); a resumed run may change only the keys the
schema marks resumable (``resume_config``).
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import os
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any, Literal

from omegaconf import DictConfig, OmegaConf

from higbench.config import COSMETIC_KEYS, RESUMABLE_KEYS, Checked, RunConfig, typed, validate
from higbench.errors import ABSENT, ConfigError, dotted_get, dotted_set, given_value, show
from higbench.optim.choice import OptimizerChoice
from higbench.runfile.reader import RUN_FILE
from higbench.runner import checkpoint
from higbench.runner.rundir import RunDir, run_file_of

Policy = Literal["new", "resume", "restart", "keep"]
PATH_KEYS = ("init_from",)  # config keys naming a file higbench opens


@dataclasses.dataclass(frozen=True)
class Plan:
    """One run, decided: its config (typed parts beside it), its directory and what to do with
    it, the inputs it reads. ``config`` is the task config the run file records (a continued
    run's stored config with the changes resuming allows); ``initial_weights`` the ``init_from``
    run's final weights; ``checkpoint`` the state a continued run starts from. Neither is read
    again by the run. A kept run (``keep``) has no typed parts: it is not trained."""

    config: Mapping[str, Any]
    dir: RunDir
    policy: Policy = "new"
    why: str = ""  # restart: why the file there recorded nothing; keep: why the run stays as it is
    run: RunConfig | None = None
    problem: DictConfig | None = None
    optimizer: OptimizerChoice | None = None
    initial_weights: Mapping[str, Any] | None = None
    checkpoint: Mapping[str, Any] | None = None
    overrides: tuple[str, ...] = ()  # the command line's task overrides (the run file records them)
    parallel_jobs: int = 1  # jobs of this sweep sharing the machine (the run file's /env records it)
    stop_with_parent: int | None = None  # a launcher worker's parent pid: the run stops cleanly once it is gone

    @property
    def run_path(self) -> Path:
        return self.dir.run_file

    @property
    def resume(self) -> bool:
        return self.policy == "resume"

    def task(self) -> dict:
        """The config as a plain dict (a copy: the plan stays as it was)."""
        return copy.deepcopy(dict(self.config))

    def start_config(self) -> DictConfig:
        """The config the start line shows: the stored run's when it resumes."""
        return OmegaConf.create({**self.task(), "resume": True if self.resume else None})

    def in_sweep(self, parallel_jobs: int, stop_with_parent: int | None) -> Plan:
        """The plan of a sweep's job: how many jobs share the machine, and the pid of the
        launcher whose exit must stop it (a worker process), if any."""
        return dataclasses.replace(self, parallel_jobs=int(parallel_jobs), stop_with_parent=stop_with_parent)

    @classmethod
    def for_run(cls, cfg, run_path: str | Path, *, resume: bool = False, overrides=()) -> Plan:
        """The plan of a config already validated (or vouched for: it is not checked again), for
        code that calls ``train`` itself (tests, notebooks): its ``init_from`` weights or, with
        ``resume``, its checkpoint loaded."""
        from higbench.config import to_plain
        from higbench.runfile.reader import UnreadableRunFile, read_head

        task, run_dir = to_plain(cfg), RunDir(Path(run_path))
        if not resume:
            return planned(task, typed(task), run_dir, overrides=overrides)
        try:
            head = read_head(run_dir.run_file)
        except UnreadableRunFile as exc:
            raise ConfigError("resume", str(run_path), f"{run_path} is not a readable run file ({exc})") from None
        state = checkpoint.load(head, str(run_path))
        return planned(task, typed(task), run_dir, "resume", "", overrides, state)


def planned(
    task: dict, checked: Checked, run_dir: RunDir, policy: Policy = "new", why: str = "", overrides=(), state=None
) -> Plan:
    """A plan to train: its typed parts, and its ``init_from`` weights unless it continues."""
    problem = OmegaConf.create(dict(checked.problem), flags={"readonly": True})
    weights = load_initial_weights(task) if state is None else None
    parts = dict(run=checked.run, problem=problem, optimizer=checked.optimizer, initial_weights=weights, checkpoint=state)
    return Plan(MappingProxyType(task), run_dir, policy, why, **parts, overrides=tuple(overrides))


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


# -- the decision -----------------------------------------------------------------------------


def make_plan(task: dict, output_dir: Path, overrides: list[str], *, multirun: bool, checked: Checked | None = None) -> Plan:
    """The one decision about a job (ConfigError when it must not run): its policy, its
    config and its inputs. ``task``: the composed config; ``checked``: its validation, where
    done already (a sweep's jobs, validated up front)."""
    output_dir, overrides = Path(output_dir), tuple(overrides)
    if task.get("resume"):
        return _resume_plan(task, output_dir, overrides, multirun=multirun)
    checked = checked or validate(task)
    run_dir = RunDir(output_dir / RUN_FILE)
    run_dir.check()
    run_dir.check_tensorboard_dir(task)
    if not os.path.lexists(run_dir.run_file):
        return planned(task, checked, run_dir, overrides=overrides)
    empty = run_dir.recorded_nothing(run_dir.look())
    if empty:
        return planned(task, checked, run_dir, "restart", empty, overrides)
    if multirun:  # a sweep run again into its directory: its runs stay as they are
        why = "already holds a run (resume=true completes interrupted and failed jobs)"
        return Plan(MappingProxyType(task), run_dir, "keep", why, overrides=overrides)
    raise run_dir.refuse(
        f"already holds a run file ({RUN_FILE}); refusing to overwrite it "
        f"(resume={output_dir} continues it, or pick a new hydra.run.dir)"
    )


def _resume_plan(task: dict, output_dir: Path, overrides: tuple[str, ...], *, multirun: bool) -> Plan:
    """``resume=``: continue the run from its checkpoint, or start it again when it recorded
    nothing; a sweep job that never started, or stopped before its first checkpoint, starts now."""
    resume = task["resume"]
    run_dir = RunDir(run_file_of(resume, output_dir), "resume")
    run_dir.check()
    seen = run_dir.look()
    stopped = run_dir.stopped_without_checkpoint(seen) if multirun else None
    if multirun and (stopped or not run_dir.run_file.exists()):
        config, policy, why = {**task, "resume": None}, "restart" if stopped else "new", stopped or ""
    else:
        why = run_dir.recorded_nothing(seen)
        if not why:
            return _continue(task, run_dir, overrides)
        stored = task if multirun else _parse_stored(run_dir.stored_config(seen, resume), resume)
        check_stored_targets(stored, task, resume)  # before anything of it is built
        config, policy = resume_config(stored, task, list(overrides)), "restart"
        # started again from its stored config: it would read the file its init_from names
        check_stored_paths(stored, list(overrides), resume)
    run_dir.check_tensorboard_dir(config)
    return planned(config, validate(config), run_dir, policy, why, overrides)


def _continue(task: dict, run_dir: RunDir, overrides: tuple[str, ...]) -> Plan:
    """The run continued from its checkpoint: its stored config (with the changes resuming
    allows), its checkpoint checked against its run file. The weights are the checkpoint's;
    a stored ``init_from`` is a record, never opened."""
    resume = task["resume"]
    head = run_dir.inspect(resume)
    stored = _parse_stored(head.config_yaml, resume)
    check_stored_targets(stored, task, resume)  # before anything of it is built
    merged = resume_config(stored, task, list(overrides))
    checked = validate({**merged, "init_from": None})
    state = checkpoint.load(head, resume)
    run_dir.check_tensorboard_dir(merged)
    return planned(merged, checked, run_dir, "resume", "", overrides, state)


def resume_config(stored: dict, composed: dict, overrides: list[str]) -> dict:
    """The stored config of the run, with the command-line changes that resuming allows.

    ``composed``: the config Hydra composed for this invocation; ``overrides``: the task
    overrides given on the command line. A key outside ``RESUMABLE_KEYS`` may be repeated
    with the run's own value (re-running the same command with ``resume=...``) but not
    changed: that would be another experiment.
    """
    from hydra.core.override_parser.overrides_parser import OverridesParser

    # a key that changes no result and that an older run file lacks: conf/config.yaml's value
    merged = {**{k: composed[k] for k in COSMETIC_KEYS if k not in stored and k in composed}, **copy.deepcopy(stored)}
    for override in OverridesParser.create().parse_overrides(list(overrides)):
        key, line = override.key_or_group, override.input_line
        if key.startswith("hydra.") or key == "hydra":
            continue
        new = dotted_get(composed, key)
        if key.split(".")[0] in RESUMABLE_KEYS:
            if new is not ABSENT:
                dotted_set(merged, key, new)
            continue
        old = dotted_get(stored, key)
        if new is ABSENT or old is ABSENT or new != old:
            shown = "<absent>" if old is ABSENT else show(old)
            why = f"cannot change when resuming (the run has {key}={shown}); resumable keys: {', '.join(RESUMABLE_KEYS)}"
            raise ConfigError(key, line.split("=", 1)[-1], why)
    merged["resume"] = None
    return merged


def _parse_stored(yaml_text: str, resume_value) -> dict:
    """A stored config, parsed with the run-file reader's bounds (size, aliases expanded)."""
    from higbench.runfile.reader import UnreadableRunFile, parse_config

    try:
        return parse_config(yaml_text)
    except UnreadableRunFile as exc:
        raise ConfigError("resume", resume_value, f"its stored config is refused: {exc}") from None


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
