"""`higbench` console script: Hydra composes the config, higbench checks it, trains, reports.

    higbench problem=oscillator optimizer=hig
    higbench -m problem=toy optimizer=adam,hig        # one run file per job
    higbench resume=outputs/runs/<date>/<run>         # continue an interrupted run

Bad input never gets as far as a run directory. ``main`` is Hydra's own ``@hydra.main``
app; the checks run in a Hydra callback (``Checks``, listed under ``hydra.callbacks`` in
conf/config.yaml) whose ``on_run_start`` / ``on_multirun_start`` Hydra calls after
composing the config and before it creates any directory. They check what would run
(every job of a basic-sweeper multirun): types, ranges and unknown keys
(``higbench.config``), then what needs the network (``train.preflight``: ``init_from``
weights that fit, the GN/HIG memory guard), the output directory, an existing run file in
``hydra.run.dir``, and what ``resume=`` points at. Hydra's own composition errors (an
unknown key or config, an override that does not parse) are caught by ``main``. Any
problem is one line on stderr, ``higbench: error: <key>=<value>: <why>``, and exit code 2,
with nothing written. The job checks again (sweepers whose jobs cannot be listed in
advance, e.g. Optuna); a job refused there removes the files Hydra made for it, exit 2.

Existing runs are never overwritten: a ``hydra.run.dir`` that already holds a run file is
refused, and of two runs racing for one directory the second fails to create the file
("w-") and exits 2. The only way to write into an existing run file is ``resume=`` (see
``higbench.runner.checkpoint``); it points Hydra's run directory at the run's own.

Output locations are checked too (``higbench.runner.outputs``): a directory that is a
file, read-only, too long a name, too little free space, a ``run.h5`` that is a link.
A run dir whose run recorded nothing (``checkpoint.recorded_nothing``) is started again in
place, its dead file moved aside. A multirun into an existing sweep directory keeps every
job that already has a run (``resume=true`` resumes the interrupted and failed ones), and
Hydra's files for such a job go to ``.hydra/rerun-<time>`` (``_output_subdir``).

Exit codes: 0 completed or diverged (a diverged run is a result: its file says where and
why), 2 bad input, 128+signal for a run stopped by SIGINT/SIGTERM (its file is closed,
status ``interrupted``, resumable), 1 for anything else (the run file says ``failed``;
a file-system fault such as a full disk is one line, ``RunFileFault``).
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import math
import os
import shlex
import signal
import sys
import time
import traceback
from importlib import resources
from pathlib import Path

import hydra
from hydra.core.global_hydra import GlobalHydra
from hydra.core.hydra_config import HydraConfig
from hydra.errors import HydraException
from hydra.experimental.callback import Callback
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf, open_dict, read_write
from omegaconf.errors import OmegaConfBaseException

from higbench.config import ConfigError, check_hydra_references, constructor_args, optimizer_class, to_plain, validate
from higbench.runfile.reader import RUN_FILE

RUN_FILE_NAME = RUN_FILE  # kept as a name for the callers
EXIT_BAD_INPUT = 2
MAX_PRECHECK_JOBS = 256  # larger sweeps: the first 256 jobs are checked up front, all in-job


def config_dir() -> str:
    """conf/ of a checkout (or editable install), else the copy shipped in the wheel."""
    checkout = Path(__file__).resolve().parent.parent / "conf"
    if (checkout / "config.yaml").is_file():
        return str(checkout)
    return str(resources.files("higbench") / "conf")


def fail(exc: BaseException | str, code: int = EXIT_BAD_INPUT) -> None:
    from higbench.runner.progress import clear_transient

    clear_transient()  # the terminal's "checking" line: the error replaces it
    message = " ".join(str(exc).split())  # one line, whatever the cause
    print(f"higbench: error: {message}", file=sys.stderr, flush=True)
    sys.exit(code)


def _output_subdir(*, _root_: DictConfig) -> str:
    """``hydra.output_subdir`` of a job: ``.hydra``, or a new subfolder where a run already is.

    Hydra writes the job's config files before the job starts; for a job directory that
    already holds a run (a sweep run again into its directory), they go to
    ``.hydra/rerun-<time>`` so the run's own ``.hydra/`` keeps describing the run.
    """
    output_dir = OmegaConf.select(_root_, "hydra.runtime.output_dir", default=None, throw_on_missing=False)
    if output_dir is not None and os.path.lexists(Path(str(output_dir)) / RUN_FILE_NAME):
        return f".hydra/rerun-{time.strftime('%Y%m%d-%H%M%S')}-{time.time_ns() % 1_000_000:06d}"
    return ".hydra"


OmegaConf.register_new_resolver("higbench_output_subdir", _output_subdir, replace=True)


# -- checks before Hydra creates anything ---------------------------------------------------


def _composition_error(exc: Exception, overrides: list[str]) -> ConfigError:
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
    axes = []
    for o in parser.parse_overrides(lines):
        if not o.is_sweep_override():
            axes.append([o.input_line])
        elif o.is_discrete_sweep():
            axes.append([f"{o.get_key_element()}={v}" for v in o.sweep_string_iterator()])
    jobs = [list(job) for job in itertools.islice(itertools.product(*axes), MAX_PRECHECK_JOBS)]
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
    check_output_dir(out, "hydra.run.dir", RUN_FILE_NAME)
    if (out / RUN_FILE_NAME).exists() and not checkpoint.recorded_nothing(out / RUN_FILE_NAME):
        raise ConfigError(
            "hydra.run.dir",
            str(out),
            f"already holds a run file ({RUN_FILE_NAME}); refusing to overwrite it "
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
            raise _composition_error(exc, job) from None
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

    with initialize_config_dir(config_dir=config_dir(), version_base="1.3", job_name="higbench"):
        try:
            config = compose("config", overrides=list(overrides), return_hydra_config=True)
        except (HydraException, OmegaConfBaseException) as exc:
            raise _composition_error(exc, list(overrides)) from None
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


# -- the job ---------------------------------------------------------------------------------


def remove_hydra_outputs(output_dir: Path, output_subdir: str | None) -> None:
    """Undo what Hydra made for a job refused before it wrote anything (no run file there).

    Removes Hydra's saved configs and the job's log file, then the directory and its empty
    parents below the working directory. A directory holding any other file is kept.
    """
    output_dir = Path(output_dir).resolve()
    if any(output_dir.glob("*.h5")):
        return
    for handler_owner in [logging.getLogger(), *[logging.getLogger(n) for n in list(logging.root.manager.loggerDict)]]:
        for h in list(getattr(handler_owner, "handlers", [])):
            filename = getattr(h, "baseFilename", None)
            if filename and Path(filename).resolve().parent == output_dir:
                handler_owner.removeHandler(h)
                h.close()
                Path(filename).unlink(missing_ok=True)
    if output_subdir is not None:
        sub = output_dir / output_subdir
        for name in ("config.yaml", "hydra.yaml", "overrides.yaml"):
            (sub / name).unlink(missing_ok=True)
        for d in (sub, *sub.parents):
            if d == output_dir or output_dir not in d.parents:
                break
            with contextlib.suppress(OSError):
                d.rmdir()
    cwd = Path.cwd().resolve()
    with contextlib.suppress(OSError):
        output_dir.rmdir()
        for parent in output_dir.parents:
            if parent == cwd or cwd not in parent.parents:
                break
            parent.rmdir()


def _run_job(cfg: DictConfig) -> float:
    from higbench.runner.progress import announce, start_text

    announce(cfg.get("progress", True), start_text(cfg))  # replaces precheck's transient line
    from higbench.runfile.writer import DiskFull, RunFileBusy, RunFileExists, RunFileFault
    from higbench.runner import checkpoint
    from higbench.runner.train import train

    hydra_cfg = HydraConfig.get()
    output_dir = Path(hydra_cfg.runtime.output_dir)
    overrides = list(hydra_cfg.overrides.task)
    multirun = hydra_cfg.mode == RunMode.MULTIRUN
    resume = False
    run_path = output_dir / RUN_FILE_NAME
    empty = None
    if cfg.get("resume"):
        run_path = checkpoint.run_file_of(cfg.resume, output_dir)
        empty = checkpoint.recorded_nothing(run_path)
        try:
            merged, resume = resume_plan(to_plain(cfg), run_path, overrides, multirun=multirun)
        except ConfigError as exc:
            if multirun and run_path.exists():
                return _kept(run_path, str(exc).split(": ", 1)[-1])
            raise
        cfg = OmegaConf.create(merged)
    elif os.path.lexists(run_path):
        empty = checkpoint.recorded_nothing(run_path)
        if not empty:
            if multirun:  # a sweep run again into its directory: its runs stay as they are
                return _kept(run_path, "already holds a run (resume=true completes interrupted and failed jobs)")
            raise ConfigError(
                "hydra.run.dir", str(output_dir), f"already holds a run file ({RUN_FILE_NAME}); refusing to overwrite it"
            )
    if empty and not resume:
        aside = checkpoint.move_aside(run_path, "empty")
        print(f"higbench: {run_path} recorded nothing ({empty}); moved to {aside.name}, starting the run again", file=sys.stderr)
    if not resume and checkpoint.checkpoint_path(run_path).exists():  # never adopt another run's checkpoint
        aside = checkpoint.move_aside(checkpoint.checkpoint_path(run_path), "stray")
        print(f"higbench: a checkpoint without its run was in {output_dir}; moved to {aside.name}", file=sys.stderr)
    try:
        summary = train(cfg, run_path, overrides=overrides, resume=resume)
    except RunFileExists as exc:
        raise ConfigError("hydra.run.dir", str(output_dir), str(exc)) from None
    except RunFileBusy as exc:
        raise ConfigError("resume", str(run_path), str(exc)) from None
    except RunFileFault as exc:  # disk full, file gone: the file (if any) says failed
        if isinstance(exc, DiskFull) and not os.path.lexists(run_path):  # refused before its file existed
            remove_hydra_outputs(output_dir, hydra_cfg.output_subdir)
        if multirun:
            print(f"higbench: error: {' '.join(str(exc).split())}", file=sys.stderr, flush=True)
            return math.inf
        fail(exc, code=1)
    for line in summary_lines(summary, cfg):  # through logging: the console and <run dir>/higbench.log
        log.info(line)
    if summary.status == "interrupted":
        print(f"resume with: higbench {shlex.quote(f'resume={summary.path.parent}')}", file=sys.stderr)
        signum = next((s for s in (signal.SIGINT, signal.SIGTERM) if s.name in summary.reason), signal.SIGINT)
        sys.stdout.flush()
        sys.exit(128 + int(signum))
    # The return value is what sweepers (Optuna) minimise; a diverged run scores worst.
    loss = summary.final_test_loss
    return loss if summary.status == "completed" and math.isfinite(loss) else float("inf")


SUMMARY_THRESHOLDS = (1e-3, 1e-4, 1e-5)  # test-loss levels whose training-clock time the summary shows
log = logging.getLogger("higbench")


def summary_lines(summary, cfg: DictConfig) -> list[str]:
    """The end-of-run lines, read back from the closed run file (the numbers the index shows)."""
    from higbench.results.index import read_run_summary, threshold_column
    from higbench.runner.progress import job_label

    label = job_label()
    head = f"{label}{summary.status}: {cfg.problem.name}/{cfg.optimizer.name} {summary.steps} updates in {summary.wall_time:.1f}s"
    row, _ = read_run_summary(summary.path, thresholds=SUMMARY_THRESHOLDS)  # never raises
    if "final_test_loss" not in row:  # an unreadable file: say what the loop knew
        row["final_test_loss"] = summary.final_test_loss
    final = row.get("final_test_loss", math.nan)
    at = f" (last evaluated at step {row['final_step']})" if "final_step" in row and row["final_step"] != summary.steps else ""
    lines = [f"{head}, final test loss {final:.4e}{at}" + (f" ({summary.reason})" if summary.reason else "")]
    times = []
    for t in SUMMARY_THRESHOLDS:
        value = row.get(threshold_column(t), math.nan)
        times.append(f"{t:.0e}: " + (f"{value:.1f}s" if math.isfinite(value) else "not reached"))
    lines.append(f"{label}time to test loss " + ", ".join(times))
    lines.append(f"{label}run file: {summary.path}")
    return lines


def _kept(run_path: Path, why: str) -> float:
    """A sweep job whose directory holds a run that is not continued: leave it, report its result."""
    from higbench.runfile.reader import load_run

    try:
        meta, curves = load_run(run_path)
        status = meta.get("status", "?")
        loss = float(curves["test_loss"].iloc[-1]) if status == "completed" and len(curves) else math.inf
    except Exception:  # noqa: BLE001
        status, loss = "unreadable", math.inf
    print(f"higbench: {run_path} ({status}) kept as it is: {why}", file=sys.stderr, flush=True)
    return loss if math.isfinite(loss) else math.inf


_JOB_STARTED = False  # set once a job runs: errors after that are the job's, not the command line's


@hydra.main(version_base="1.3", config_path=config_dir(), config_name="config")
def _hydra_main(cfg: DictConfig) -> float:
    global _JOB_STARTED
    _JOB_STARTED = True
    hydra_cfg = HydraConfig.get()
    output_dir = Path(hydra_cfg.runtime.output_dir)
    try:
        validate(cfg)
        return _run_job(cfg)
    except ValueError as exc:  # ConfigError, or a problem/optimizer refusing its arguments
        if not isinstance(exc, ConfigError) and any(output_dir.glob("*.h5")):
            raise  # not bad input: the run had started (its file says failed)
        remove_hydra_outputs(output_dir, hydra_cfg.output_subdir)
        fail(exc)
        raise  # unreachable: fail() exits


def main(argv: list[str] | None = None) -> None:
    """Console-script entry: Hydra's app; its composition errors become one line (exit 2)."""
    global _JOB_STARTED
    argv = list(sys.argv[1:] if argv is None else argv)
    sys.argv = [sys.argv[0], *argv]
    overrides = [a for a in argv if not a.startswith("-") and ("=" in a or a.startswith("~"))]
    full_error = os.environ.get("HYDRA_FULL_ERROR")
    os.environ["HYDRA_FULL_ERROR"] = "1"  # Hydra raises its errors instead of printing them
    _JOB_STARTED = False
    try:
        _hydra_main()
    except (HydraException, OmegaConfBaseException) as exc:
        if _JOB_STARTED:
            raise
        fail(_composition_error(exc, overrides))
    finally:
        if full_error is None:
            os.environ.pop("HYDRA_FULL_ERROR", None)
        else:
            os.environ["HYDRA_FULL_ERROR"] = full_error
        GlobalHydra.instance().clear()


if __name__ == "__main__":
    main()
