"""The worker side of a launch: each job claimed in the runs root's ledger before it runs.

Every job of a launch runs through the same entry point, the job-list multirun (a local
launcher runs the whole list; a job array's task runs one entry of it: ``array_task``); the
job-list sweeper wraps its task in ``ClaimedTask`` when the jobs file names a ledger. The
wrapped task claims the job (``Ledger.held``), skips it when a live worker holds it, when the
ledger says it is final, or when its run is already done (another worker finished it between
the driver's look and this claim), runs it, and records how it ended.
"""

from __future__ import annotations

import sys
from pathlib import Path

from higbench.jobs.ledger import Ledger, is_memory_refusal
from higbench.results.index import DONE_STATUSES
from higbench.runfile.reader import UnreadableRunFile, read_head


def run_status(run_file: str | Path | None) -> str | None:
    """The status a run file says (None: no file, or one that cannot be read)."""
    if not run_file:
        return None
    try:
        return read_head(run_file).status
    except UnreadableRunFile:
        return None


def _say(text: str) -> None:
    print(f"[ledger] {text}", file=sys.stderr, flush=True)


def run_claimed(task, cfg, root: str | Path, identity: str, run_file: str | Path):
    """Run ``task(cfg)`` as the job ``identity`` of the ledger of ``root``, its run file at
    ``run_file``; None without running it when it is not this worker's to run."""
    ledger = Ledger(root)
    with ledger.held(identity, run_file) as claim:
        if claim is None:
            holder = ledger.live_holder(identity)
            _say(f"{identity}: run by another worker ({holder.describe() if holder else 'just now'}); left to it")
            return None
        if (final := ledger.final(identity)) is not None:
            _say(f"{identity}: not run again ({final.get('status')}: {final.get('reason', '')[:200]})")
            return None
        for earlier in (ledger.record(identity).get("run"), run_file):  # the last attempt's run; the one to resume
            if earlier and run_status(earlier) in DONE_STATUSES:
                _say(f"{identity}: already done by another worker ({earlier})")
                return None
        try:
            result = task(cfg)
        except BaseException as exc:
            status = run_status(run_file) or ("refused" if is_memory_refusal(exc) else "failed")
            ledger.write_record(identity, status, run_file, reason=" ".join(str(exc).split()))
            raise
        ledger.write_record(identity, run_status(run_file) or "failed", run_file)
        return result


class ClaimedTask:
    """A multirun's task function with each job claimed first; ``entries[num]``: job ``num``'s
    (identity, run file). Picklable (a joblib worker receives it)."""

    def __init__(self, task, root: str, entries: list[tuple[str, str]]):
        self.task, self.root, self.entries = task, root, entries

    def __call__(self, cfg):
        from hydra.core.hydra_config import HydraConfig

        identity, run_file = self.entries[HydraConfig.get().job.num]
        return run_claimed(self.task, cfg, self.root, identity, run_file)


def array_task(command: list[str]) -> int:
    """One task of a submitit job array: the launch's job-list multirun command (``python -m
    higbench.cli -m ...``, what a local launch runs), narrowed to one job
    (``hydra.sweeper.only=<i>``); its exit code. Its output goes to the task's log."""
    import subprocess

    return subprocess.run(list(command), check=False).returncode
