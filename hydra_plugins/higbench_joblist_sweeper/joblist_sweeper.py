"""``hydra/sweeper=joblist``: one multirun over an explicit list of jobs, in the given order.

Hydra's basic sweeper runs the cartesian product of its overrides; a set of runs that is not
a product (the missing runs of several figures) would need one multirun per product, each
waiting for the slowest of its runs while cores idle. This sweeper takes the jobs as a JSON
file, a list of override lists, and hands them to the configured launcher as one batch:

    higbench -m hydra/sweeper=joblist hydra.sweeper.jobs_file=jobs.json hydra/launcher=joblib

Overrides on the command line apply to every job (a job's own value wins). The launcher
starts jobs in list order, so a list sorted longest first keeps the workers busy to the end.

The file may also be ``{"ledger": <runs root>, "jobs": [{"overrides": [...], "claim":
<identity>, "run": <run file>}, ...]}`` (what ``higbench.jobs.launch`` writes): then each job
is claimed in the runs root's ledger before it runs, and left alone when a live worker holds it
(``higbench.jobs.worker``). ``hydra.sweeper.only=<i>`` runs the i-th job alone (a job array's task).
"""
# No "from __future__ import annotations": Hydra imports plugins outside sys.modules, where a
# dataclass with string annotations cannot be built.

import json
import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hydra.core.config_store import ConfigStore
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.plugins import Plugins
from hydra.plugins.sweeper import Sweeper
from omegaconf import OmegaConf

from hydra_plugins.higbench_joblist_sweeper.every_batch_sweeper import EveryBatchSweeper, FailureCountingLauncher


@dataclass
class JobListSweeperConf:
    _target_: str = "hydra_plugins.higbench_joblist_sweeper.joblist_sweeper.JobListSweeper"
    jobs_file: str = "???"  # JSON: [["key=value", ...], ...], one list of overrides per job
    only: int | None = None  # run the job of this index alone (a job array's task)


ConfigStore.instance().store(group="hydra/sweeper", name="joblist", node=JobListSweeperConf, provider="higbench")


def read_jobs(path: str | Path) -> list[list[str]]:
    """The job list of a jobs file, checked to be a list of lists of ``key=value`` strings."""
    return [e["overrides"] for e in read_entries(path)[1]]


def read_entries(path: str | Path) -> tuple[str | None, list[dict]]:
    """(the ledger's runs root or None, one dict per job: ``overrides``, and ``claim`` and
    ``run`` where the jobs are claimed), checked."""
    data = json.loads(_read_regular(Path(path)))
    root, entries = None, data
    if isinstance(data, dict):
        root, entries = data.get("ledger"), data.get("jobs")
        ok = (
            isinstance(root, str)
            and isinstance(entries, list)
            and all(isinstance(e, dict) and isinstance(e.get("claim"), str) and isinstance(e.get("run"), str) for e in entries)
        )
    else:
        ok = isinstance(entries, list)
        entries = [{"overrides": e} for e in entries] if ok else entries
    ok = ok and all(isinstance(e.get("overrides"), list) and all(isinstance(o, str) for o in e["overrides"]) for e in entries)
    if not ok:
        raise ValueError(
            f"hydra.sweeper.jobs_file={path}: must hold a JSON list of lists of override strings "
            "(or {ledger, jobs: [{overrides, claim, run}]})"
        )
    return root, entries


MAX_JOBS_FILE_BYTES = 64 << 20


def _read_regular(path: Path) -> str:
    """The text of ``path`` if it is a regular file (a FIFO would block the sweep forever)."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise ValueError(f"hydra.sweeper.jobs_file={path}: not a regular file")
        if st.st_size > MAX_JOBS_FILE_BYTES:
            raise ValueError(f"hydra.sweeper.jobs_file={path}: {st.st_size:,} bytes (at most {MAX_JOBS_FILE_BYTES:,})")
        return f.read(MAX_JOBS_FILE_BYTES + 1).decode()


def merge(common: list[str], job: list[str]) -> list[str]:
    """The common overrides, each replaced by the job's own value of the same key, then the job's."""
    own = {o.split("=", 1)[0] for o in job}
    return [o for o in common if o.split("=", 1)[0] not in own] + list(job)


class JobListSweeper(Sweeper):
    def __init__(self, jobs_file: str, only: int | None = None):
        self.jobs_file, self.only = jobs_file, only
        self.config = self.launcher = self.hydra_context = None
        self.root, self.entries = None, []

    def _read(self) -> None:
        self.root, self.entries = read_entries(self.jobs_file)
        if self.only is not None:
            if not 0 <= self.only < len(self.entries):
                raise ValueError(f"hydra.sweeper.only={self.only}: the jobs file holds {len(self.entries)} jobs")
            self.entries = [self.entries[self.only]]

    def setup(self, *, hydra_context, task_function, config) -> None:
        self.hydra_context, self.config = hydra_context, config
        self._read()
        if self.root is not None:  # each job claimed in the ledger first (imported only then: it reads run files)
            from higbench.jobs.worker import ClaimedTask

            task_function = ClaimedTask(task_function, self.root, [(e["claim"], e["run"]) for e in self.entries])
        self.launcher = FailureCountingLauncher(
            Plugins.instance().instantiate_launcher(hydra_context=hydra_context, task_function=task_function, config=config)
        )

    def sweep(self, arguments: list[str]) -> Any:
        parser = OverridesParser.create(config_loader=self.hydra_context.config_loader)
        swept = [o.input_line for o in parser.parse_overrides(arguments) if o.is_sweep_override()]
        if swept:
            raise ValueError(f"{swept[0]}: the joblist sweeper takes no sweep overrides (list the jobs in jobs_file)")
        batch = [merge(arguments, e["overrides"]) for e in self.entries]
        sweep_dir = Path(self.config.hydra.sweep.dir)
        sweep_dir.mkdir(parents=True, exist_ok=True)
        OmegaConf.save(self.config, sweep_dir / "multirun.yaml")
        self.validate_batch_is_legal(batch)
        results = self.launcher.launch(batch, initial_job_idx=0)
        self.launcher.raise_failures()  # SweepFailed: the first failure, and how many
        return [results]


def register() -> None:
    """Make higbench's sweepers known to Hydra where its plugin scan cannot see this package (an
    editable install hides namespace packages from ``pkgutil``); importing this module has
    stored the job-list sweeper's config (``hydra/sweeper=joblist``)."""
    Plugins.instance().register(JobListSweeper)
    Plugins.instance().register(EveryBatchSweeper)
