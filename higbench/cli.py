"""`higbench` console script: Hydra's app. Hydra composes the config, higbench trains, reports.

    higbench problem=oscillator optimizer=hig
    higbench -m problem=toy optimizer=adam,hig        # one run file per job
    higbench resume=outputs/runs/<date>/<run>         # continue an interrupted run

Bad input never gets as far as a run directory: ``higbench.checks.Checks``, a Hydra
callback, checks what would run before Hydra creates anything, and ``main`` turns Hydra's
own composition errors (an unknown key or config, an override that does not parse) into
the same one line, ``higbench: error: <key>=<value>: <why>``, exit code 2. The job checks
again (sweepers whose jobs cannot be listed in advance, e.g. Optuna); a job refused there
removes the files Hydra made for it and exits 2.

Existing runs are never overwritten: a ``hydra.run.dir`` that already holds a run file is
refused, and of two runs racing for one directory the second fails to create the file
("w-") and exits 2. The only way to write into an existing run file is ``resume=`` (see
``higbench.runner.checkpoint``). A run dir whose run recorded nothing
(``checkpoint.recorded_nothing``) is started again in place, its dead file moved aside. A
multirun into an existing sweep directory keeps every job that already has a run
(``resume=true`` resumes the interrupted and failed ones), and Hydra's files for such a
job go to ``.hydra/rerun-<time>`` (``_output_subdir``).

Exit codes: 0 completed or diverged (a diverged run is a result: its file says where and
why), 2 bad input, 128+signal for a run stopped by SIGINT/SIGTERM (its file is closed,
status ``interrupted``, resumable), 1 for anything else (the run file says ``failed``;
a file-system fault such as a full disk is one line, ``RunFileFault``).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import shlex
import signal
import sys
import time
from importlib import resources
from pathlib import Path

import hydra
from hydra.core.global_hydra import GlobalHydra
from hydra.core.hydra_config import HydraConfig
from hydra.errors import HydraException
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from higbench.checks import Checks, composition_error, precheck, resume_plan
from higbench.config import check_hydra_references, to_plain, validate
from higbench.errors import EXIT_BAD_INPUT, ConfigError, fail
from higbench.runfile.reader import RUN_FILE

__all__ = ["main", "config_dir", "Checks", "precheck", "check_hydra_references", "ConfigError", "EXIT_BAD_INPUT", "fail"]
RUN_FILE_NAME = RUN_FILE  # kept as a name for the callers


def config_dir() -> str:
    """conf/ of a checkout (or editable install), else the copy shipped in the wheel."""
    checkout = Path(__file__).resolve().parent.parent / "conf"
    if (checkout / "config.yaml").is_file():
        return str(checkout)
    return str(resources.files("higbench") / "conf")


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

    announce(cfg.get("progress", True), start_text(cfg))  # replaces the checks' transient line
    from higbench.runfile.writer import DiskFull, RunFileBusy, RunFileExists, RunFileFault, RunFileReadOnly
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
        if isinstance(exc, RunFileReadOnly):  # closing it (also at exit) would write, fail and crash HDF5
            print(f"higbench: error: {' '.join(str(exc).split())}", file=sys.stderr, flush=True)
            logging.shutdown()
            os._exit(1)
        if multirun:
            print(f"higbench: error: {' '.join(str(exc).split())}", file=sys.stderr, flush=True)
            return math.inf
        fail(exc, code=1)
    # The file is closed with its status: a stop signal now must not end the process with
    # 128+signal while the file says completed. Ignored while reporting (and, for a single
    # run, until exit); a sweep gets its handlers back for the next job.
    previous = {s: signal.signal(s, signal.SIG_IGN) for s in (signal.SIGINT, signal.SIGTERM)}
    for line in summary_lines(summary, cfg):  # through logging: the console and <run dir>/higbench.log
        log.info(line)
    if multirun:
        for s, handler in previous.items():
            signal.signal(s, handler)
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
        fail(composition_error(exc, overrides))
    finally:
        if full_error is None:
            os.environ.pop("HYDRA_FULL_ERROR", None)
        else:
            os.environ["HYDRA_FULL_ERROR"] = full_error
        GlobalHydra.instance().clear()


if __name__ == "__main__":
    main()
