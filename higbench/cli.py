"""`higbench` console script: Hydra's app. Hydra composes the config, higbench trains, reports.

    higbench problem=oscillator optimizer=hig
    higbench -m problem=toy optimizer=adam,hig        # one run file per job
    higbench resume=outputs/runs/<date>/<run>         # continue an interrupted run

One pass, in order: Hydra composes; ``higbench.preflight.Preflight`` (a Hydra callback,
before Hydra creates anything) makes the run's ``Plan`` (``higbench.runner.plan``: the
config validated and typed, the output policy, the inputs read once); the job claims its
directory (``claimed_dir``: of two runs started into one directory, the second is refused
with nothing written), makes room as planned (``RunDir.make_room``, ``higbench.runner.rundir``),
writes Hydra's files itself (``write_job_files``: never through a link, never over another
run's) and calls ``runner.train.train(plan)``. Hydra's own composition errors (an unknown
key or config, an override that does not parse) become the same one line,
``higbench: error: <key>=<value>: <why>``, exit code 2, nothing written. Sweep jobs are
planned in the job (sweepers whose jobs cannot be listed in advance, e.g. Optuna). What
higbench does here that Hydra would do itself is each marked "Hydra's wart", with the test
that shows why.

Existing runs are never overwritten: what an existing directory means (a run to refuse, to
continue with ``resume=``, to start again because it recorded nothing, or a sweep's job to
keep) is the plan's output policy. Hydra's files for a job whose directory already has
them go to ``.hydra/rerun-<time>`` (``.hydra/resume-<time>``).

Exit codes: 0 completed or diverged (a diverged run is a result: its file says where and
why), 2 bad input, 128+signal for a run stopped by SIGINT/SIGTERM (its file is closed,
status ``interrupted``, resumable), 1 for anything else (the run file says ``failed``;
a file-system fault such as a full disk is one line, ``RunFileFault``; a sweep in which
any job failed says how many).
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import logging
import math
import os
import shlex
import signal
import stat
import sys
import time
import traceback
from pathlib import Path

import hydra
from hydra.core.global_hydra import GlobalHydra
from hydra.core.hydra_config import HydraConfig
from hydra.errors import HydraException
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from higbench.config import check_hydra_references
from higbench.errors import EXIT_BAD_INPUT, ConfigError, given_value, output_never_fails, quiet_broken_pipe
from higbench.preflight import Preflight, composition_error, config_dir, invocation, new_invocation, precheck, refuse, take_plan
from higbench.runner.plan import Plan

__all__ = ["main", "config_dir", "Preflight", "precheck", "check_hydra_references", "ConfigError", "EXIT_BAD_INPUT"]
log = logging.getLogger("higbench")

# -- the job's directory: claimed, Hydra's files written by us, never through a link ----------


class DirectoryHeld(ConfigError):
    """The job's directory is held by another run: the refused job leaves it, and everything in
    it, alone (removing it as an empty leftover pulled it from under the run that holds it)."""


@contextlib.contextmanager
def claimed_dir(output_dir: Path, key: str):
    """Hold a lock on the job's directory while the job runs (flock on the directory itself).

    Two runs started into one directory at the same moment: the second finds it held and is
    refused, before it writes anything.
    """
    fd = os.open(output_dir, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise DirectoryHeld(key, str(output_dir), "another higbench process is running in it; refusing to overwrite it") from None
    except OSError:  # a file system without locks: the run file's exclusive creation still decides
        pass
    try:
        yield
    finally:
        os.close(fd)


# Hydra's wart: its file handler opens <run dir>/higbench.log by path, following a link planted
# there (tests/reliability/test_own_files_only.py::test_a_log_link_planted_after_the_checks_is_not_written_through).
def guard_log_files(output_dir: Path, key: str) -> None:
    """The job's log file is never opened through a link, and never one with a second hard link.

    Hydra's handler opens ``higbench.log`` by path at its first line (``delay: true``: a
    refused job makes none), so a link planted in the directory after the checks would be
    followed. A link there now is refused; the handler's opener is replaced by one with
    ``O_NOFOLLOW`` that checks the opened file, so one planted later is never written through.
    """
    for owner in [logging.getLogger(), *[logging.getLogger(n) for n in list(logging.root.manager.loggerDict)]]:
        for handler in getattr(owner, "handlers", []):
            filename = getattr(handler, "baseFilename", None)
            if not filename or Path(filename).parent != Path(output_dir).absolute():
                continue
            if os.path.islink(filename):
                raise ConfigError(key, str(output_dir), f"{filename} is a symbolic link; higbench never writes through links")
            handler._open = functools.partial(_open_log_or_off, filename, getattr(handler, "encoding", None))


def _open_log(filename: str, encoding: str | None):
    """Append to ``filename``, a regular file with one link, never reached through a link."""
    fd = os.open(filename, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode) or st.st_nlink > 1:
        os.close(fd)
        raise OSError(f"{filename} is not the run's own log file (not a regular file, or has a second hard link)")
    os.set_blocking(fd, True)
    return os.fdopen(fd, "a", encoding=encoding or "utf-8")


def _open_log_or_off(filename: str, encoding: str | None):
    """The log is a side sink: refused at its first line (a link planted since the checks), it is
    turned off with one line and the run goes on; the run file is the record."""
    try:
        return _open_log(filename, encoding)
    except OSError as exc:
        why = " ".join(f"{type(exc).__name__}: {exc}".split())[:300]
        line = f"higbench: {filename} turned off ({why}); the run goes on, its run file is the record"
        print(line, file=sys.stderr, flush=True)
        return open(os.devnull, "a", encoding=encoding or "utf-8")  # noqa: SIM115 - the handler owns and closes it


# Hydra's wart (why conf/config.yaml sets hydra.output_subdir: null): Hydra writes .hydra/*.yaml by
# path, through links and over a continued run's own record, before the job can check anything
# (tests/reliability/test_front_door_security.py::test_job_files_are_created_exclusively_and_never_through_links).
def write_job_files(output_dir: Path, label: str, hydra_cfg: DictConfig, task_cfg: DictConfig) -> list[Path]:
    """Hydra's ``.hydra/{config,hydra,overrides}.yaml`` of this job, created exclusively.

    Into ``.hydra`` when the directory has none yet, else into a new ``.hydra/<label>-<time>``
    (a run continued or started again keeps its first description). Never through a link,
    never over an existing file. Returns what it made (removed again if the job is refused).
    """
    base = output_dir / ".hydra"
    target = base if not os.path.lexists(base) else base / f"{label}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
    os.mkdir(target)  # FileExistsError on a link or a name taken meanwhile: refused by the caller
    made = [target]
    contents = {
        "config.yaml": OmegaConf.to_yaml(task_cfg),
        "hydra.yaml": OmegaConf.to_yaml({"hydra": hydra_cfg}),
        "overrides.yaml": OmegaConf.to_yaml(list(hydra_cfg.overrides.task)),
    }
    for name, text in contents.items():
        fd = os.open(target / name, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)
        made.append(target / name)
        with os.fdopen(fd, "w") as f:
            f.write(text)
    return made


def remove_job_files(made: list[Path]) -> None:
    """Undo ``write_job_files`` (only what it made: files first, then its directory)."""
    for path in reversed(made):
        with contextlib.suppress(OSError):
            path.rmdir() if path.is_dir() and not path.is_symlink() else path.unlink()


# Hydra's wart: it makes the job's directory (and its log handler) before the job runs, so a job
# refused in the job would leave an empty directory (tests/reliability/test_bad_config.py::
# test_bad_input_is_refused_and_nothing_is_written: files_under(work) == []).
def remove_hydra_outputs(output_dir: Path, output_subdir: str | None) -> None:
    """Undo what Hydra made for a job refused before it wrote anything (no run file there).

    Removes Hydra's saved configs and the job's log file, then the directory and its empty
    parents below the working directory. A directory holding any other file is kept.
    """
    output_dir = Path(output_dir).resolve()
    if any(output_dir.glob("*.h5")):
        return
    for owner in [logging.getLogger(), *[logging.getLogger(n) for n in list(logging.root.manager.loggerDict)]]:
        for h in list(getattr(owner, "handlers", [])):
            filename = getattr(h, "baseFilename", None)
            if filename and Path(filename).resolve().parent == output_dir:
                owner.removeHandler(h)
                h.close()
                with contextlib.suppress(OSError):
                    if os.path.getsize(filename) == 0:
                        os.unlink(filename)
    if output_subdir is not None:
        sub = output_dir / output_subdir
        remove_job_files([sub, *(sub / f"{n}.yaml" for n in ("config", "hydra", "overrides"))])
    cwd = Path.cwd().resolve()
    with contextlib.suppress(OSError):
        output_dir.rmdir()
        for parent in output_dir.parents:
            if parent == cwd or cwd not in parent.parents:
                break
            parent.rmdir()


# -- the job ---------------------------------------------------------------------------------


def _prepare(plan: Plan, output_dir: Path, hydra_cfg: DictConfig, task_cfg: DictConfig) -> list[Path]:
    """Make room for the run as planned (``RunDir.make_room``), write Hydra's files (the caller holds it)."""
    for line in plan.dir.make_room(plan.policy, plan.why, output_dir):
        print(f"higbench: {line}", file=sys.stderr)
    if hydra_cfg.output_subdir is not None:  # the user asked Hydra to write them: it has
        return []
    try:
        return write_job_files(output_dir, "resume" if plan.resume else "rerun", hydra_cfg, task_cfg)
    except FileExistsError as exc:
        raise ConfigError(
            plan.dir.key, str(output_dir), f"{exc.filename} appeared while starting; refusing to write over it"
        ) from None


def parallel_jobs(hydra_cfg: DictConfig) -> int:
    """How many jobs of this sweep share the machine: a joblib launcher's workers, capped at
    the jobs its sweeper launches together (``preflight.launched_together``), else one."""
    launcher = OmegaConf.select(hydra_cfg, "launcher", default=None)
    if hydra_cfg.mode != RunMode.MULTIRUN or launcher is None or "Joblib" not in str(launcher.get("_target_", "")):
        return 1  # a single run is alone even with hydra/launcher=joblib given
    n_jobs = int(launcher.get("n_jobs", -1) or -1)
    cores = os.cpu_count() or 1
    workers = max(1, cores + 1 + n_jobs if n_jobs < 0 else n_jobs)  # joblib: -1 is every core
    return min(workers, int(os.environ.get("HIGBENCH_SWEEP_JOBS", workers)))  # a sweep of 2 jobs: 2 at most


def _train(plan: Plan, parent: int | None):
    """Train per the plan; the run file's refusals become ConfigError, faults one line."""
    from higbench.runfile.writer import DiskFull, RunFileBusy, RunFileExists, RunFileFault, RunFileReadOnly
    from higbench.runner.train import train

    try:
        return train(plan.in_sweep(parallel_jobs(HydraConfig.get()), parent))
    except RunFileExists as exc:
        raise ConfigError("hydra.run.dir", str(plan.run_path.parent), str(exc)) from None
    except RunFileBusy as exc:
        raise ConfigError("resume", str(plan.run_path), str(exc)) from None
    except RunFileFault as exc:  # disk full, file gone: the file (if any) says failed
        if isinstance(exc, RunFileReadOnly):  # closing it (also at exit) would write, fail and crash HDF5
            print(f"higbench: error: {' '.join(str(exc).split())}", file=sys.stderr, flush=True)
            logging.shutdown()
            os._exit(1)
        refused_at_creation = isinstance(exc, DiskFull) and not os.path.lexists(plan.run_path)
        raise JobFailed(" ".join(str(exc).split()), written=not refused_at_creation) from None


class JobFailed(Exception):
    """A job that failed for a reason already said in one line (a sweep counts them)."""

    def __init__(self, message: str, written: bool = True):
        super().__init__(message)
        self.written = written


def _run_job(plan: Plan, multirun: bool) -> float:
    start = plan.start_config()
    # A launcher's worker (joblib) is a process of its own: if the sweep's parent is killed
    # alone (a scheduler's SIGTERM to its pid), the worker's run stops cleanly, resumable,
    # instead of training on, orphaned; and the worker then exits instead of lingering. The
    # same for a sweep a driver launched (the league, the figures: DRIVER_ENV names it), which
    # would otherwise go on through its jobs list with no driver to read the results.
    from higbench.results import end_of_run  # pandas: read once the run is over, not at start-up
    from higbench.runner.progress import job_label
    from higbench.runner.train import DRIVER_ENV

    parent = None if invocation().main else os.getppid()
    if parent is None and os.environ.get(DRIVER_ENV) == str(os.getppid()):
        parent = os.getppid()
    summary = _train(plan, parent)
    # The file is closed with its status: a stop signal now must not end the process with
    # 128+signal while the file says completed. Ignored while reporting (and, for a single
    # run, until exit); a sweep gets its handlers back for the next job.
    previous = {s: signal.signal(s, signal.SIG_IGN) for s in (signal.SIGINT, signal.SIGTERM)}
    for line in end_of_run.summary_lines(summary, start, job_label()):  # through logging: the console and <run dir>/higbench.log
        log.info(line)
    if multirun:
        for s, handler in previous.items():
            signal.signal(s, handler)
    if summary.status == "interrupted":
        _interrupted(summary, multirun, parent)
    # The return value is what sweepers (Optuna) minimise; a diverged run scores worst.
    loss = summary.final_test_loss
    return loss if summary.status == "completed" and math.isfinite(loss) else float("inf")


def _interrupted(summary, multirun: bool, parent: int | None = None) -> None:
    """Say how to continue (the sweep, or the run if it left a checkpoint), exit 128+signal."""
    from higbench.runner import checkpoint

    if checkpoint.checkpoint_path(summary.path).exists():
        print(f"resume with: higbench {shlex.quote(f'resume={summary.path.parent}')}", file=sys.stderr)
    elif not multirun:
        why = "checkpoint_every=null, or stopped before the first"
        print(f"no checkpoint was written ({why}): it cannot be resumed", file=sys.stderr)
    if multirun:  # the whole sweep stops: one command runs what is left and continues this job
        print(f"complete the sweep with: {sweep_resume_command(HydraConfig.get().sweep.dir)}", file=sys.stderr)
    signum = next((s for s in (signal.SIGINT, signal.SIGTERM) if s.name in summary.reason), signal.SIGINT)
    sys.stdout.flush()
    if parent is not None and os.getppid() != parent:  # an orphaned worker: nobody takes its result
        sys.stderr.flush()
        logging.shutdown()
        os._exit(128 + int(signum))
    sys.exit(128 + int(signum))


def sweep_resume_command(sweep_dir: str) -> str:
    """The command that completes this sweep: the same arguments, its directory, resume=true."""
    sweep_dir = os.path.abspath(str(sweep_dir))
    args = [a for a in sys.argv[1:] if not a.startswith(("hydra.sweep.dir=", "resume="))]
    return shlex.join(["higbench", *args, f"hydra.sweep.dir={sweep_dir}", "resume=true"])


def _report_kept_run(run_path: Path, why: str) -> float:
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


@hydra.main(version_base="1.3", config_path=config_dir(), config_name="config")
def _hydra_main(cfg: DictConfig) -> float:
    shared = invocation()
    shared.job_started = True
    hydra_cfg = HydraConfig.get()
    output_dir = Path(hydra_cfg.runtime.output_dir)
    multirun = hydra_cfg.mode == RunMode.MULTIRUN
    overrides = list(hydra_cfg.overrides.task)
    shared.jobs += 1
    made: list[Path] = []
    try:
        guard_log_files(output_dir, "hydra.sweep.dir" if multirun else "hydra.run.dir")  # before any line is logged
        plan = take_plan(cfg, output_dir, overrides, multirun=multirun)
        if plan.policy == "keep":
            return _report_kept_run(plan.run_path, plan.why)
        with claimed_dir(output_dir, plan.dir.key):
            made = _prepare(plan, output_dir, hydra_cfg, cfg)
            return _run_job(plan, multirun)
    except ConfigError as exc:  # refused before its run file: nothing of it stays
        remove_job_files(made)
        if not isinstance(exc, DirectoryHeld):  # the directory (and its log) is the other run's
            remove_hydra_outputs(output_dir, None)
        if not multirun:
            refuse(exc)
        # One job of a sweep refused: it fails alone (one line), the others run; the sweep says how many failed.
        print(f"higbench: error: {' '.join(str(exc).split())}", file=sys.stderr, flush=True)
        shared.failed += 1
        raise JobFailed(str(exc), written=False) from None
    except JobFailed as exc:
        if not exc.written:
            remove_job_files(made)
            remove_hydra_outputs(output_dir, None)
        if not multirun:
            refuse(exc, code=1)
        print(f"higbench: error: {exc}", file=sys.stderr, flush=True)
        shared.failed += 1
        raise
    except Exception:
        if not multirun:
            raise
        traceback.print_exc()  # this job's traceback now; the sweep goes on and says how many failed
        shared.failed += 1
        raise
    raise AssertionError("unreachable: refuse() exits")


def main(argv: list[str] | None = None) -> None:
    """Console-script entry: Hydra's app; its composition errors become one line (exit 2).

    Called with ``argv`` (from code: a notebook, a test), it leaves the process as it found it:
    ``sys.argv``, the SIGINT/SIGTERM handlers (a finished single run ignores them until the
    console script exits) and torch's thread count (where torch was loaded) are put back.
    """
    if argv is None:
        return _main(list(sys.argv[1:]))
    with _process_kept():
        return _main(list(argv))


@contextlib.contextmanager
def _process_kept():
    saved_argv = list(sys.argv)
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    torch = sys.modules.get("torch")
    threads = torch.get_num_threads() if torch is not None else None
    try:
        yield
    finally:
        sys.argv[:] = saved_argv
        for s, handler in handlers.items():
            if handler is not None:
                signal.signal(s, handler)
        if threads is not None:  # a run sets its own (``threads``)
            torch.set_num_threads(threads)


def _main(argv: list[str]) -> None:
    early = _refuse_early(argv)
    if early is not None:
        refuse(early)
    argv = _flags_first(argv)
    if {"-m", "--multirun"} & set(argv) and {"-c", "--cfg"} & set(argv):
        return _print_sweep_configs(argv)
    config_dir()  # registers the schema, resolvers and sweepers (the module's import did once; a test may have cleared them)
    # Hydra's documented switch: with it Hydra raises its composition errors instead of printing
    # a traceback hint and exiting 1, so they become one line, exit 2 (tests/reliability/test_bad_config.py)
    full_error = os.environ.get("HYDRA_FULL_ERROR")
    os.environ["HYDRA_FULL_ERROR"] = "1"
    with new_invocation():
        _run(argv, full_error)


def _run(argv: list[str], full_error: str | None) -> None:
    """Hydra's app until done (run again where a problem's own key needs ``++``); its ends as lines."""
    from hydra_plugins.higbench_joblist_sweeper.every_batch_sweeper import SweepFailed

    try:
        with output_never_fails():  # `higbench ... | head -3`: the output stops, the training goes on
            while argv is not None:
                argv = _run_app(argv)
    except RecursionError:
        value = given_value(argv, "hydra.run.dir") or "?"
        refuse(ConfigError("hydra.run.dir", value, "nested too deep (Python's recursion limit)"))
    except SweepFailed as exc:  # the sweeper ran every job, then raised the first failure
        _sweep_failed(exc.first, exc.failed, exc.jobs)
    except JobFailed as exc:
        _sweep_failed(exc)
    except KeyboardInterrupt:  # between a sweep's jobs, or before a run installed its handler
        print("\nhigbench: interrupted", file=sys.stderr)
        if invocation().sweep_dir is not None:  # a parallel sweep's parent: its workers may be gone before their line
            print(f"complete the sweep with: {sweep_resume_command(invocation().sweep_dir)}", file=sys.stderr)
        sys.exit(128 + int(signal.SIGINT))
    finally:
        if full_error is None:
            os.environ.pop("HYDRA_FULL_ERROR", None)
        else:
            os.environ["HYDRA_FULL_ERROR"] = full_error
        GlobalHydra.instance().clear()


def _run_app(argv: list[str]) -> list[str] | None:
    """Hydra's app on ``argv``; None when done, or the command line to run it again with."""
    invocation().job_started = False
    sys.argv = [sys.argv[0], *argv]
    overrides = [a for a in argv if not a.startswith("-") and ("=" in a or a.startswith("~"))]
    try:
        with quiet_broken_pipe():
            _hydra_main()
    except (HydraException, OmegaConfBaseException, ValueError) as exc:
        if invocation().job_started:
            _sweep_failed(exc)
            raise
        error = composition_error(exc, overrides)
        if not getattr(error, "addable", False):
            refuse(error)
        # Hydra refuses a key its struct config lacks; a key of the problem's own Config that its
        # YAML does not list is the user's to set, so the app runs again with ++key
        # (tests/test_custom_problem.py::test_a_base_config_key_its_yaml_does_not_list_can_be_set).
        # Each run again turns one more override into ++key: an error on a key already given
        # with ++ is refused, so the retries end (at most one per override).
        again = [f"++{a}" if a.partition("=")[0] == error.key else a for a in argv]
        if again == argv:
            refuse(error)
        GlobalHydra.instance().clear()
        return again
    return None


def _sweep_failed(exc: BaseException, failed: int | None = None, jobs: int | None = None) -> None:
    """A sweep with a failed job exits 1 and says how many failed (the others ran to their end)."""
    failed = invocation().failed if failed is None else failed
    jobs = invocation().jobs if jobs is None else jobs
    count = f"{failed} of {jobs} sweep jobs failed" if failed else "a sweep job failed"
    first = " ".join(str(exc).split())
    again = "resume=true with the same hydra.sweep.dir runs them again"
    print(f"higbench: error: {count} (the first: {first}); {again}", file=sys.stderr, flush=True)
    sys.exit(1)


# Hydra's wart: with -m, --cfg prints the sweep's primary config, not its jobs'
# (tests/test_cli.py::test_multirun_cfg_job_prints_each_jobs_config).
def _print_sweep_configs(argv: list[str]) -> None:
    """``higbench -m ... --cfg job``: print every job's config (Hydra allows one mode flag)."""
    from higbench.preflight import sweep_configs

    flag = next(i for i, a in enumerate(argv) if a in ("-c", "--cfg"))
    part = argv[flag + 1]
    if part not in ("job", "hydra", "all"):
        refuse(ConfigError("--cfg", part, "must be job, hydra or all"))
    overrides = [a for i, a in enumerate(argv) if not a.startswith("-") and i != flag + 1]
    try:
        shown = sweep_configs(overrides, part)
    except (HydraException, OmegaConfBaseException) as exc:
        refuse(composition_error(exc, overrides))
    with quiet_broken_pipe():
        for num, (job, text) in enumerate(shown):
            print(f"# job {num}: {' '.join(job)}\n{text}", flush=True)


# Hydra's flags (``higbench --hydra-help``): those taking a value, and those that do not.
_VALUE_FLAGS = ("-c", "--cfg", "-p", "--package", "-cp", "--config-path", "-cn", "--config-name", "-cd", "--config-dir")
_UNPICKLING_FLAGS = ("--experimental-rerun",)  # Hydra unpickles the file it names: never accepted
_PLAIN_FLAGS = ("-h", "--help", "--hydra-help", "--version", "--resolve", "-r", "--run", "-m", "--multirun", "-sc")
_PLAIN_FLAGS += ("--shell-completion", "-i", "--info")
_INFO_CHOICES = ("all", "config", "defaults", "defaults-tree", "plugins", "searchpath")


# Hydra's wart: its argparse takes the overrides as one positional group, so a flag after an
# override is a usage error (tests/test_cli.py::test_an_unknown_flag_is_one_line_not_argparse_usage
# also runs flags placed anywhere: the `higbench` fixture puts the tiny budget first).
def _flags_first(argv: list[str]) -> list[str]:
    """Hydra's flags (with their values) before the overrides: argparse takes the overrides
    as one group, so ``higbench seed=0 -m lr=1`` would otherwise be its usage text."""
    flags, overrides, i = [], [], 0
    while i < len(argv):
        arg = argv[i]
        takes = arg in _VALUE_FLAGS or (arg in ("-i", "--info") and i + 1 < len(argv) and argv[i + 1] in _INFO_CHOICES)
        (flags if arg.startswith("-") else overrides).extend(argv[i : i + 1 + takes])
        i += 1 + takes
    return [*flags, *overrides]


# Hydra's warts: argparse answers a bad flag with a multi-line usage text, and --experimental-rerun
# unpickles the file it names (tests/test_cli.py::test_an_unknown_flag_is_one_line_not_argparse_usage,
# tests/reliability/test_own_files_only.py::test_hydra_experimental_rerun_is_refused_before_the_pickle_is_read).
def _refuse_early(argv: list[str]) -> ConfigError | None:
    """Command lines Hydra's argparse would answer with its usage text: one line instead."""
    for i, arg in enumerate(argv):
        name = arg.split("=", 1)[0]
        if name in _UNPICKLING_FLAGS:  # the file would be unpickled (run as code) before any check
            value = arg.partition("=")[2] or (argv[i + 1] if i + 1 < len(argv) else "<missing>")
            why = "refused: Hydra would unpickle that file, which can run code; higbench reruns from resume=<run dir>"
            return ConfigError(name, value, why)
        if arg.startswith("-") and name not in (*_VALUE_FLAGS, *_PLAIN_FLAGS):
            return ConfigError("option", arg, "not an option of higbench (higbench --help lists them)")
        if arg in _VALUE_FLAGS and (i + 1 == len(argv) or argv[i + 1].startswith("-")):
            return ConfigError(arg, "<missing>", "needs a value (e.g. --cfg job)")
    return None


if __name__ == "__main__":
    main()
