"""The checks before Hydra writes anything: a Hydra callback, ``Checks``.

Hydra calls ``on_run_start`` / ``on_multirun_start`` of the callbacks listed under
``hydra.callbacks`` (conf/config.yaml) after composing the config and before it creates
any directory. ``check_run`` and ``check_sweep`` check what would run (every job of a
basic-sweeper multirun): keys, types and ranges (``higbench.config``), what needs the
network (``train.preflight``: ``init_from`` weights that fit, the GN/HIG memory guard), the
output directory, an existing run file in ``hydra.run.dir``, and what ``resume=`` points
at (``resume_plan``, which the job uses too). Any problem is one line on stderr,
``higbench: error: <key>=<value>: <why>``, and exit code 2, with nothing written.
``composition_error`` makes such a line of Hydra's own composition errors.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import sys
import time
import traceback
from pathlib import Path

from hydra.core.global_hydra import GlobalHydra
from hydra.core.hydra_config import HydraConfig
from hydra.errors import HydraException
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf, open_dict, read_write
from omegaconf.errors import OmegaConfBaseException

from higbench.config import check_hydra_references, constructor_args, optimizer_class, to_plain, validate
from higbench.errors import ConfigError, fail
from higbench.runfile.reader import RUN_FILE

MAX_PRECHECK_JOBS = 256  # larger sweeps: the first 256 jobs are checked up front, all in-job


def composition_error(exc: Exception, overrides: list[str]) -> ConfigError:
    """A one-line ConfigError from Hydra's composition errors (unknown key, config, syntax)."""
    cause = exc.__cause__ if exc.__cause__ is not None else exc
    text = str(exc)
    full_key = getattr(cause, "full_key", None)
    if full_key and isinstance(cause, OmegaConfBaseException) and "Could not override" not in text and "not in" not in str(cause):
        value = _explicit(overrides, str(full_key)) or "?"  # a bad type: Hydra's check against the schema
        why = str(cause.msg if hasattr(cause, "msg") else cause).split("\n")[0]
        return ConfigError(str(full_key), value, " ".join(why.split()))
    if full_key:
        value = _explicit(overrides, str(full_key))
        value = "<missing>" if value is None else value
        parent = full_key.rsplit(".", 1)[0] if "." in full_key else ""
        others = [o for o in overrides if o.split("=", 1)[0].lstrip("+~") != full_key]
        base = None
        with contextlib.suppress(Exception):  # list the keys that are there
            base = _compose_plain(others)
        node = OmegaConf.select(OmegaConf.create(base), parent) if base is not None and parent else base
        valid = sorted(node.keys()) if hasattr(node, "keys") else []
        if parent == "optimizer" and hasattr(node, "get") and node.get("_target_"):
            leaf = full_key.rsplit(".", 1)[-1]
            with contextlib.suppress(ConfigError):
                if leaf in constructor_args(optimizer_class(dict(node))):
                    # A constructor argument the optimizer's YAML does not list: Hydra adds it with `+`.
                    yaml_file = f"conf/optimizer/{node.get('name')}.yaml"
                    return ConfigError(full_key, value, f"not set in {yaml_file}; add it with +{full_key}={value}")
        where = f" under {parent}" if parent else ""
        return ConfigError(full_key, value, f"unknown key; valid keys{where}: {', '.join(map(str, valid))}")
    if "Could not find" in text and "Available options in" in text:
        lines = [ln.strip() for ln in text.splitlines()]
        group_path = text.split("Could not find '", 1)[1].split("'", 1)[0]
        group, _, choice = group_path.rpartition("/")
        start = next(i for i, ln in enumerate(lines) if ln.startswith("Available options"))
        options = [ln for ln in lines[start + 1 :] if ln and not ln.startswith("Config search path")]
        options = options[: next((i for i, ln in enumerate(options) if "provider=" in ln), len(options))]
        return ConfigError(group or "config", choice, f"no such config; valid choices: {', '.join(options)}")
    first = text.strip().splitlines()[0] if text.strip() else type(exc).__name__
    from hydra.core.override_parser.overrides_parser import OverridesParser

    for line in overrides:  # name the override that does not parse, if one does not
        try:
            OverridesParser.create().parse_overrides([line])
        except Exception:  # noqa: BLE001
            key, _, value = line.partition("=")
            return ConfigError(key, value, f"cannot parse this override ({first})")
    return ConfigError("overrides", " ".join(overrides), first)


def _compose_plain(overrides: list[str]) -> dict:
    """The task config of ``overrides``, unresolved (in the running Hydra app, or a new one)."""
    from hydra import compose, initialize_config_dir

    from higbench.cli import config_dir

    if GlobalHydra.instance().is_initialized():
        return OmegaConf.to_container(compose("config", overrides=overrides), resolve=False)
    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        return OmegaConf.to_container(compose("config", overrides=overrides), resolve=False)


def _explicit(overrides: list[str], key: str) -> str | None:
    for o in overrides:
        k, sep, v = o.partition("=")
        if k.lstrip("+~") == key:
            return v if sep else "<missing>"
    return None


def sweep_jobs(config: DictConfig) -> list[list[str]]:
    """Override lists of the jobs a multirun launches: all of them for Hydra's basic sweeper
    (its ``params`` and the command line's comma lists, crossed), the first one for others
    (Optuna samples its jobs as it goes; those are checked in-job)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    lines = list(config.hydra.overrides.task)
    basic = "BasicSweeper" in str(OmegaConf.select(config, "hydra.sweeper._target_", default=""))
    params = OmegaConf.select(config, "hydra.sweeper.params", default=None) if basic else None
    if params is not None:
        lines = [f"{k}={v}" for k, v in OmegaConf.to_container(params, resolve=False).items()] + lines
    parser = OverridesParser.create(config_loader=GlobalHydra.instance().config_loader())
    axes: dict[str, list[str]] = {}  # per key, as Hydra's sweeper: the command line wins over params
    for o in parser.parse_overrides(lines):
        if not o.is_sweep_override():
            axes[o.get_key_element()] = [o.input_line]
        elif o.is_discrete_sweep():
            axes[o.get_key_element()] = [f"{o.get_key_element()}={v}" for v in o.sweep_string_iterator()]
        else:
            axes.pop(o.get_key_element(), None)  # an interval (Optuna's): not listed
    jobs = [list(job) for job in itertools.islice(itertools.product(*axes.values()), MAX_PRECHECK_JOBS)]
    return jobs if basic else jobs[:1]


def resume_plan(task: dict, run_path: Path, overrides: list[str], *, multirun: bool) -> tuple[dict, bool]:
    """The config a ``resume=`` job runs, and whether it continues ``run_path``'s checkpoint.

    A sweep job that never started starts now; a run that recorded nothing starts again
    from the beginning with its own config; anything else continues from its checkpoint
    (ConfigError when it cannot: finished, no checkpoint, another run's, a changed key).
    """
    from higbench.runner import checkpoint

    if multirun and not run_path.exists():
        return {**task, "resume": None}, False
    if checkpoint.recorded_nothing(run_path):
        stored = task if multirun else OmegaConf.to_container(OmegaConf.create(_stored_config(run_path, task["resume"])))
        merged = checkpoint.resume_config(stored, task, overrides)
        validate(merged)
        return merged, False
    _status, stored_yaml = checkpoint.inspect_run(run_path, task["resume"])
    merged = checkpoint.resume_config(OmegaConf.to_container(OmegaConf.create(stored_yaml)), task, overrides)
    validate(merged)
    checkpoint.check_owner(checkpoint.load(run_path), run_path, task["resume"])  # readable, of this format, of this run
    return merged, True


def _checked_task(config: DictConfig) -> dict:
    """The task part of a composed config (with its hydra node), validated."""
    with contextlib.suppress(Exception):  # ${hydra:...} resolves against this job's Hydra config
        HydraConfig.instance().set_config(config)
    check_hydra_references(config)
    task = to_plain(config)
    validate(task)
    return task


def check_run(config: DictConfig) -> None:
    """Everything a single run needs, before Hydra makes its directory (ConfigError otherwise).

    For ``resume=<run>`` Hydra's run directory becomes the run's own directory (unless
    ``hydra.run.dir`` is given) and its files go to ``.hydra/resume-<time>``.
    """
    from higbench.runner import checkpoint
    from higbench.runner.outputs import check_output_dir
    from higbench.runner.progress import announce, start_text

    task = _checked_task(config)
    # on a terminal, a line at once: torch and the pre-flight take seconds
    announce(task.get("progress", True), start_text(OmegaConf.create(task)) + " - checking", transient=True)
    from higbench.runner.train import preflight  # imports torch: only once the cheap checks pass

    overrides = [*config.hydra.overrides.hydra, *config.hydra.overrides.task]
    explicit_dir = _explicit(overrides, "hydra.run.dir") is not None
    if task.get("resume"):
        run_file = checkpoint.run_file_of(task["resume"], str(config.hydra.run.dir) if explicit_dir else None)
        check_output_dir(run_file.parent, "resume")
        merged, continues = resume_plan(task, run_file, list(config.hydra.overrides.task), multirun=False)
        preflight(OmegaConf.create({**merged, "init_from": None} if continues else merged))  # weights: the checkpoint's
        with read_write(config.hydra), open_dict(config.hydra):
            if not explicit_dir:
                config.hydra.run.dir = str(run_file.parent)
            if _explicit(overrides, "hydra.output_subdir") is None:
                config.hydra.output_subdir = f".hydra/resume-{time.strftime('%Y%m%d-%H%M%S')}"
        return
    out = Path(str(config.hydra.run.dir))
    check_output_dir(out, "hydra.run.dir", RUN_FILE)
    if (out / RUN_FILE).exists() and not checkpoint.recorded_nothing(out / RUN_FILE):
        raise ConfigError(
            "hydra.run.dir",
            str(out),
            f"already holds a run file ({RUN_FILE}); refusing to overwrite it "
            f"(resume={out} continues it, or pick a new hydra.run.dir)",
        )
    preflight(OmegaConf.create(task))


def check_sweep(config: DictConfig) -> None:
    """Every job of a multirun (see ``sweep_jobs``), before Hydra makes the sweep directory."""
    from higbench.runner.outputs import check_output_dir
    from higbench.runner.train import preflight

    loader = GlobalHydra.instance().config_loader()
    tasks = []
    for job in sweep_jobs(config) or [[]]:
        try:
            job_config = loader.load_sweep_config(config, job)
        except (HydraException, OmegaConfBaseException) as exc:
            raise composition_error(exc, job) from None
        tasks.append(_checked_task(job_config))
    sweep_dir = Path(str(config.hydra.sweep.dir))
    check_output_dir(sweep_dir, "hydra.sweep.dir")
    _remember_multirun_yaml(sweep_dir)
    if any(task.get("resume") for task in tasks):
        return  # which jobs resume is known only in their directories: checked in-job
    seen = set()
    for task in tasks:  # the network-sized checks once per distinct network and batch
        sizing = {k: task.get(k) for k in ("problem", "batch_size", "dtype", "device", "init_from", "memory_limit_mb")}
        sizing["optimizer"] = {k: v for k, v in task["optimizer"].items() if k != "lr"}
        key = OmegaConf.to_yaml(sizing)
        if key not in seen:
            seen.add(key)
            preflight(OmegaConf.create(task))


def _checked(check, config: DictConfig) -> None:
    """Run a check; Hydra turns a callback's exceptions into warnings and goes on, so exit here."""
    try:
        check(config)
    except ConfigError as exc:
        fail(exc)
    except Exception:  # noqa: BLE001 - not bad input: the traceback, exit 1, before anything is written
        traceback.print_exc()
        sys.exit(1)


class Checks(Callback):
    """Hydra calls these after composing and before creating any directory (conf/config.yaml)."""

    def on_run_start(self, config: DictConfig, **kwargs) -> None:
        _checked(check_run, config)

    def on_multirun_start(self, config: DictConfig, **kwargs) -> None:
        _checked(check_sweep, config)

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        _restore_multirun_yaml()


def precheck(overrides: list[str]) -> DictConfig:
    """The checks of ``higbench <overrides>`` (one run) in this process; ConfigError if refused."""
    from hydra import compose, initialize_config_dir

    from higbench.cli import config_dir

    with initialize_config_dir(config_dir=config_dir(), version_base="1.3", job_name="higbench"):
        try:
            config = compose("config", overrides=list(overrides), return_hydra_config=True)
        except (HydraException, OmegaConfBaseException) as exc:
            raise composition_error(exc, list(overrides)) from None
        check_run(config)
    return config


def _stored_config(run_file: Path, resume_value) -> str:
    """Config YAML of a run: from its run file, else (a file killed at creation) Hydra's copy."""
    from higbench.runfile.reader import UnreadableRunFile, read_head

    try:
        stored = read_head(run_file).config_yaml
        if stored:
            return stored
    except UnreadableRunFile:
        pass
    saved = run_file.parent / ".hydra" / "config.yaml"
    if saved.is_file():
        return saved.read_text()
    raise ConfigError("resume", resume_value, f"{run_file} recorded nothing and its config is unknown (no .hydra/config.yaml)")


_MULTIRUN_YAML: tuple[Path, bytes] | None = None


def _remember_multirun_yaml(sweep_dir: Path) -> None:
    """A sweep run again into its directory: keep the sweep's own multirun.yaml (see Checks)."""
    global _MULTIRUN_YAML
    existing = sweep_dir / "multirun.yaml"
    _MULTIRUN_YAML = (existing, existing.read_bytes()) if existing.is_file() else None


def _restore_multirun_yaml() -> None:
    """Put the sweep's first multirun.yaml back; Hydra's new one goes to multirun-rerun-<time>.yaml."""
    if _MULTIRUN_YAML is None:
        return
    path, original = _MULTIRUN_YAML
    with contextlib.suppress(OSError):
        if path.is_file() and path.read_bytes() != original:
            os.replace(path, path.with_name(f"multirun-rerun-{time.strftime('%Y%m%d-%H%M%S')}.yaml"))
        if not path.exists():
            path.write_bytes(original)
