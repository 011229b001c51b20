"""The plan of one run: what it trains, where it writes, and the inputs it reads, decided once.

``make_plan`` turns a composed config and the job's output directory into a ``Plan``, an
immutable value with typed parts: ``run`` (the top-level keys as a ``config.RunConfig``),
``problem`` (its config node), ``optimizer`` (its class and checked arguments, resolved once
by ``config.validate``), ``sinks`` (the side sinks it names) and ``dir`` (the ``RunDir``,
``runner.rundir``: every question about what the directory already holds is answered there,
one call per kind of run). Everything a run reads from disk is read here, once, before
anything is written: the stored config of a run to continue (``runner.stored``), its
checkpoint (checked whole against its schema and its run file's ``run_id``), the ``init_from``
run's final weights. ``runner.train.train(plan)`` then builds the problem, the network and the
optimizer once, checks these inputs against them (shapes, memory) before its run file exists,
and trains.

What an existing directory means (the output policy):

* ``new``: no run file there; one is created (never over another run's).
* ``resume``: ``resume=<run>``: the run continues from its checkpoint, in place.
* ``restart``: the run file there recorded nothing (killed while being created, or stopped
  before its first update or checkpoint); it is moved aside and the run starts again.
* ``keep``: a sweep job whose directory already holds a run that is not continued.

A stored config is someone else's file: ``runner.stored.stored_task`` makes it the task a
resumed run trains, refusing what it may never make higbench do (build a callable no higbench
config registers, open a file the user did not name) and keys resuming may not change.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any, Literal

from omegaconf import DictConfig, OmegaConf

from higbench.config import Checked, RunConfig, typed, validate
from higbench.errors import ConfigError
from higbench.optim.choice import OptimizerChoice
from higbench.runfile.reader import RUN_FILE
from higbench.runner import checkpoint
from higbench.runner.rundir import RunDir, final_weights, run_file_of
from higbench.runner.sinks import side_sink_specs
from higbench.runner.stored import stored_task

Policy = Literal["new", "resume", "restart", "keep"]


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
    sinks: Mapping[str, Any] = dataclasses.field(default_factory=dict)  # its side sinks: NAME -> {_target_, args}
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
    def for_run(cls, cfg, run_path: str | Path, *, resume: bool = False, overrides=(), checked: Checked | None = None) -> Plan:
        """The plan of a config already validated (``checked``: its validation) or vouched for (it
        is not checked again: ``config.typed``), for code that calls ``train`` itself (tests,
        notebooks) and the sweep's up-front check: its ``init_from`` weights or, with ``resume``,
        its checkpoint loaded."""
        from higbench.config import to_plain
        from higbench.runfile.reader import UnreadableRunFile, read_head

        task, run_dir, state = to_plain(cfg), RunDir(Path(run_path)), None
        checked = checked or typed(task)
        if resume:
            try:
                head = read_head(run_dir.run_file)
            except UnreadableRunFile as exc:
                raise ConfigError("resume", str(run_path), f"{run_path} is not a readable run file ({exc})") from None
            state = checkpoint.load(head, str(run_path))
        weights = None if resume else final_weights(task.get("init_from"), task["problem"]["name"])
        parts = dict(run=checked.run, problem=checked.problem, optimizer=checked.optimizer, sinks=side_sink_specs(task))
        inputs = dict(initial_weights=weights, checkpoint=state)
        return cls(MappingProxyType(task), run_dir, "resume" if resume else "new", **parts, **inputs, overrides=tuple(overrides))


def make_plan(task: dict, output_dir: Path, overrides: list[str], *, multirun: bool, checked: Checked | None = None) -> Plan:
    """The one decision about a job (ConfigError when it must not run): its policy, its
    config and its inputs, each asked of its owner once. ``task``: the composed config;
    ``checked``: its validation, where done already (a sweep's jobs, validated up front)."""
    output_dir, overrides, state = Path(output_dir), tuple(overrides), None
    resume = task.get("resume")
    if not resume:
        config, checked = task, checked or validate(task)
        sinks = side_sink_specs(config)
        run_dir = RunDir(output_dir / RUN_FILE)
        found = run_dir.fresh_start(multirun, tensorboard="tensorboard" in sinks)
        if found.policy == "keep":
            return Plan(MappingProxyType(task), run_dir, "keep", found.why, overrides=overrides)
    else:
        run_dir = RunDir(run_file_of(resume, output_dir), "resume")
        found = run_dir.resumption(resume, multirun)
        if found.fresh:
            config = {**task, "resume": None}
        else:  # a stored config: someone else's file (a sweep job's is its own composed one)
            theirs = found.stored_yaml is not None  # a sweep job's own config names the user's files
            stored = found.stored_yaml if theirs else task
            config = stored_task(stored, task, overrides, resume, restart=found.policy == "restart" and theirs)
        # a continued run's weights are its checkpoint's: a stored init_from is a record, never opened
        checked = validate({**config, "init_from": None} if found.head else config)
        state = checkpoint.load(found.head, resume) if found.head else None
        sinks = side_sink_specs(config)
        run_dir.check_tensorboard_dir("tensorboard" in sinks)
    # the inputs read once: a continued run's weights are its checkpoint's, else init_from's run's
    weights = None if state is not None else final_weights(config.get("init_from"), config["problem"]["name"])
    parts = dict(run=checked.run, problem=checked.problem, optimizer=checked.optimizer, sinks=sinks)
    inputs = dict(initial_weights=weights, checkpoint=state)
    return Plan(MappingProxyType(config), run_dir, found.policy, found.why, **parts, **inputs, overrides=overrides)
