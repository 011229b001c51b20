"""Hydra's basic sweeper, except that a failed job fails alone (what higbench runs where a
sweep would use Hydra's basic sweeper: ``higbench.preflight.Preflight.on_multirun_start``).

Hydra's basic sweeper raises a job's failure after the batch that held it, so with
``hydra.sweeper.max_batch_size`` the later batches never run. This one launches every batch,
notes the failed jobs, and raises ``SweepFailed`` (the first failure and how many) at the end.
Its keys are the basic sweeper's (``params``, ``max_batch_size``).
"""
import dataclasses
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


class FailureCountingLauncher:
    """A launcher whose failed jobs are noted and handed back as done, so the sweep goes on."""

    def __init__(self, launcher) -> None:
        self.launcher = launcher
        self.failures: list[BaseException] = []
        self.jobs = 0

    def launch(self, job_overrides, initial_job_idx: int) -> list[JobReturn]:
        returns = self.launcher.launch(job_overrides, initial_job_idx=initial_job_idx)
        self.jobs += len(returns)
        handed_back = []
        for r in returns:
            if r.status == JobStatus.FAILED:
                self.failures.append(r._return_value)  # the job's exception (JobReturn keeps it here)
                r = dataclasses.replace(r, status=JobStatus.COMPLETED, _return_value=None)
            handed_back.append(r)
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
        self.basic = basic_sweeper.BasicSweeper(self.max_batch_size, self.params)
        self.basic.setup(hydra_context=hydra_context, task_function=task_function, config=config)
        self.launcher = self.basic.launcher = FailureCountingLauncher(self.basic.launcher)

    def sweep(self, arguments: list[str]) -> Any:
        returns = self.basic.sweep(arguments)
        self.launcher.raise_failures()
        return returns
