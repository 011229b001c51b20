"""Hydra's basic sweeper, except that a failed job fails alone (what higbench runs where a
sweep would use Hydra's basic sweeper: ``higbench.preflight.Preflight.on_multirun_start``).

Hydra's basic sweeper raises a job's failure after the batch that held it, so with
``hydra.sweeper.max_batch_size`` the later batches never run. This one launches every batch,
notes the failed jobs, and raises ``SweepFailed`` (the first failure and how many) at the end.
Its keys are the basic sweeper's (``params``, ``max_batch_size``).

It also says how far the sweep is (``[sweep] 3 of 6 jobs done``, ``CountProgress``: per job
where the jobs run in this process, per batch where workers run them) and, at the end, whether
the machine was busy (``display.busy_summary`` over the jobs' run files).
"""

import dataclasses
import os
import sys
from pathlib import Path
from typing import Any

from hydra._internal.core_plugins import basic_sweeper
from hydra.core.utils import JobReturn, JobStatus
from hydra.plugins.sweeper import Sweeper

EVERY_BATCH_SWEEPER = "hydra_plugins.higbench_joblist_sweeper.every_batch_sweeper.EveryBatchSweeper"
HYDRA_BASIC_SWEEPER = "hydra._internal.core_plugins.basic_sweeper.BasicSweeper"


class SweepFailed(Exception):
    """Some jobs of a sweep failed; the others ran to their end. ``first``: the first failure."""

    def __init__(self, first: BaseException, failed: int, jobs: int):
        super().__init__(str(first))
        self.first, self.failed, self.jobs = first, failed, jobs


class SweepCount:
    """The sweep's jobs done and failed, counted in the sweep's own process."""

    def __init__(self, enabled: bool) -> None:
        self.enabled, self.pid = enabled, os.getpid()
        self.done = self.failed = 0
        self.progress = None

    def start(self, total: int) -> None:
        from higbench.runner.progress import CountProgress

        if self.progress is None:
            self.progress = CountProgress(self.enabled, "sweep", total, noun="jobs")
            self.progress.update(0)

    def update(self, done: int, failed: int) -> None:
        if self.progress is not None and (done, failed) != (self.done, self.failed):
            self.done, self.failed = done, failed
            self.progress.update(done, failed=failed)

    def close(self) -> None:
        if self.progress is not None:
            self.progress.close()


class CountingTask:
    """The task function, counting each job that ends in the sweep's process (Hydra's basic
    launcher runs them there; a worker process of joblib or SLURM counts nothing: its batch does)."""

    def __init__(self, task, count: SweepCount) -> None:
        self.task, self.count = task, count

    def __call__(self, config) -> Any:
        failed = False
        try:
            return self.task(config)
        except Exception:
            failed = True
            raise
        finally:
            if os.getpid() == self.count.pid:
                self.count.update(self.count.done + 1, self.count.failed + failed)


class FailureCountingLauncher:
    """A launcher whose failed jobs are noted and handed back as done, so the sweep goes on."""

    def __init__(self, launcher, count: SweepCount | None = None, total=None) -> None:
        self.launcher = launcher
        self.failures: list[BaseException] = []
        self.jobs = 0
        self.count, self.total = count, total  # total(): the sweep's job count, known once it is split into batches
        self.run_files: list[Path] = []

    def launch(self, job_overrides, initial_job_idx: int) -> list[JobReturn]:
        if self.count is not None:
            self.count.start(self.total() if self.total else len(job_overrides))
        returns = self.launcher.launch(job_overrides, initial_job_idx=initial_job_idx)
        self.jobs += len(returns)
        handed_back = []
        for r in returns:
            if r.status == JobStatus.FAILED:
                self.failures.append(r._return_value)  # the job's exception (JobReturn keeps it here)
                r = dataclasses.replace(r, status=JobStatus.COMPLETED, _return_value=None)
            job_dir = r.hydra_cfg.hydra.runtime.output_dir if r.hydra_cfg is not None else None
            if job_dir:  # the job's directory (working_dir is the sweep's, without chdir)
                self.run_files.append(Path(job_dir) / "run.h5")
            handed_back.append(r)
        if self.count is not None:
            self.count.update(self.jobs, len(self.failures))
        return handed_back

    def raise_failures(self) -> None:
        if self.failures:
            raise SweepFailed(self.failures[0], len(self.failures), self.jobs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.launcher, name)


class EveryBatchSweeper(Sweeper):
    """Hydra's basic sweeper, held rather than inherited: Hydra's plugin scan executes its
    module a second time, so a subclass of the first class object fails the basic sweeper's own
    ``super(BasicSweeper, self)``; the class is looked up when the sweep is set up."""

    def __init__(self, max_batch_size: int | None = None, params: dict | None = None) -> None:
        self.max_batch_size, self.params = max_batch_size, params
        self.basic = self.launcher = None

    def setup(self, *, hydra_context, task_function, config) -> None:
        self.count = SweepCount(bool(config.get("progress", True)))
        self.basic = basic_sweeper.BasicSweeper(self.max_batch_size, self.params)
        task = CountingTask(task_function, self.count)
        self.basic.setup(hydra_context=hydra_context, task_function=task, config=config)
        total = lambda: sum(len(batch) for batch in self.basic.overrides or [])  # noqa: E731
        self.launcher = self.basic.launcher = FailureCountingLauncher(self.basic.launcher, self.count, total)

    def sweep(self, arguments: list[str]) -> Any:
        try:
            returns = self.basic.sweep(arguments)
        finally:
            self.count.close()
        busy_line(self.launcher.run_files)
        self.launcher.raise_failures()
        return returns


def busy_line(run_files: list[Path]) -> None:
    """The sweep's closing line when its jobs had a busy machine (nothing otherwise)."""
    from higbench.display import busy_summary
    from higbench.results.index import cpu_uses

    busy = busy_summary(cpu_uses(run_files), noun="jobs")
    if busy:
        sys.stderr.write(f"[sweep] {busy}\n")
        sys.stderr.flush()
