"""Runs wanted as jobs: which of them exist, and running the missing ones as one multirun.

A job is a list of Hydra overrides (the figures declare theirs: ``higbench.figures.spec``;
the probe scripts write their own), perhaps continued from another job's run or with its
seed picked from a seed search.

Identity. A run is identified by its resolved config (what ``higbench`` composes with Hydra
for the same overrides) minus the keys that do not change its result: the results index's
``config_id`` (``higbench.results.index``: ``COSMETIC_KEYS`` dropped, ``init_from`` replaced
by the identity of the run it points at).

Reuse. The results index of the runs root (``outputs/`` by default, runs made by hand with
``higbench`` included) decides which runs exist: one per config by its rule
(``one_per_config``), done meaning ``DONE_STATUSES`` (completed or diverged: a diverged run
is a result). A run that stopped before its end (interrupted, failed, or killed: its file still
says running) and left a checkpoint continues from it (``resume=<its run dir>``, in place, for the
rest of its budget: a session cut off mid-run loses only the time since its last checkpoint); a
missing run, or one without a checkpoint, is run from the start. A run still going in another
process is refused by the resume and left alone.

Running. The jobs that can run now (a continued run waits for its parent, a searched seed for
its search) form one ``higbench -m`` multirun over their list (the job-list sweeper,
``hydra/sweeper=joblist``), longest first, on a Hydra launcher: joblib with ``--jobs``
workers locally, or any other (``--launcher slurm``, ...) with extra ``hydra.*`` overrides;
with ``submitit_local`` or ``submitit_slurm`` one submitit job array whose task i runs job i
of that list (``arrays``). Run files go to ``<runs root>/figures-runs/<time>/<job number>/run.h5``.

The ledger. The runs root is the ledger of its jobs (``ledger``): each job is claimed there by
the worker that runs it (``worker``), so a job held by a live worker is waited for instead of
run twice (two drivers on one root), a dead worker's job runs again (resumed from its
checkpoint where it left one), and a job refused for memory or failed repeatedly is final.
"""

from __future__ import annotations

import copy
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any, NamedTuple

import yaml

from higbench.errors import dotted_get
from higbench.errors import override_value as fmt  # the one value-to-override rule
from higbench.jobs import arrays
from higbench.jobs.arrays import LauncherError
from higbench.jobs.ledger import FINAL_STATUSES, Ledger
from higbench.results.index import DONE_STATUSES, FIGURE_RUNS_DIR, load_runs, one_per_config
from higbench.results.index import config_id as identity_of
from higbench.runfile.reader import RUN_FILE
from higbench.runner.checkpoint import checkpoint_path
from higbench.runner.rundir import RESUMABLE_STATUSES
from higbench.runner.threads import available_cores, idle_cores

# Overrides of every figure run that do not change its result (tests check they are cosmetic keys).
LAUNCH_OVERRIDES = ("progress=false", "threads=1")
PARALLEL_SECONDS = 30  # a round with less training than this runs on Hydra's basic launcher (no worker start-up)
PACKAGE_PARENT = Path(__file__).resolve().parents[2]  # the checkout (or site-packages) holding higbench


@dataclass
class Job:
    """One run a figure needs: its overrides (ordered) and, once known, its run file."""

    figure: str
    sweep: str
    overrides: dict[str, Any]  # everything but init_from, in order
    seed: int
    parent: Job | None = None  # init_from: this job starts from the parent's final weights
    search: list[Job] = field(default_factory=list)  # seed search: the seed is picked from these runs
    identity: str | None = None
    config: dict | None = None  # resolved task config (init_from: the parent's path)
    path: Path | None = None  # the run file that satisfies it
    status: str = "missing"
    resume_from: Path | None = None  # a stopped run of it with a checkpoint: launched as resume=
    clock_done: float = 0.0  # that run's training clock (seconds of its budget already spent)
    reason: str = ""  # why a job is final without a run that is done (the ledger's record: refused for memory, ...)

    def override_list(self) -> list[str]:
        """The job's overrides as ``key=value`` strings (``init_from``: its parent's run file)."""
        items = [f"{k}={fmt(v)}" for k, v in self.overrides.items()]
        if self.parent is not None:
            items.append(f"init_from={fmt(str(self.parent.path)) if self.parent.path else 'PENDING'}")
        return items

    def launch_overrides(self) -> list[str]:
        """What the multirun runs for this job: its overrides, or ``resume=`` its stopped run."""
        if self.resume_from is not None:
            return [f"resume={fmt(str(self.resume_from.parent))}"]
        return self.override_list()

    @property
    def done(self) -> bool:
        return self.status in DONE_STATUSES

    def value(self, key: str, default: Any = None) -> Any:
        """A resolved config value by dotted key (``optimizer.lr``)."""
        return dotted_get(self.config or {}, key, default)


def pick_seed(search: list[Job]) -> int:
    """The seed of the best stable search run (completed, final test loss finite and below its
    initial one; lowest final loss), else the first seed."""
    from higbench.runfile.reader import load_run

    stable = {}
    for job in search:
        if job.status != "completed" or job.path is None:
            continue
        try:
            loss = load_run(job.path)[1]["test_loss"].to_numpy(dtype=float)
        except Exception:  # noqa: BLE001 - an unreadable file is not a stable run
            continue
        if len(loss) >= 2 and loss[-1] == loss[-1] and loss[-1] < loss[0]:
            stable[job.seed] = float(loss[-1])
    return min(stable, key=stable.get) if stable else search[0].seed


@contextmanager
def hydra_conf():
    """Hydra's compose API on the CLI's config dir, for a batch of compositions (Hydra keeps the
    parsed YAML files as long); Hydra's global state is cleared before and after."""
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    from higbench.config import config_dir

    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3", job_name="higbench"):
        yield


def _is_group(key: str) -> bool:
    from higbench.config import config_dir

    return (Path(config_dir()) / key).is_dir()  # a config group (problem, optimizer), not a value


@cache
def _compose_groups(groups: tuple[str, ...]):
    """Hydra's composition for the config-group choices alone: the defaults list and its files."""
    from hydra import compose as hydra_compose

    return hydra_compose("config", overrides=list(groups))


@cache
def compose(overrides: tuple[str, ...]) -> dict:
    """The resolved config the CLI composes for these overrides (inside ``hydra_conf()``),
    serialised as in the run file (OmegaConf -> YAML -> dict).

    Jobs with the same group choices share that composition (most of Hydra's cost); their value
    overrides are then applied as Hydra applies them after composing (its override grammar,
    ``OmegaConf.update(..., merge=True)`` in struct mode). Overrides that add or delete keys are
    composed whole. tests/figures check both routes give the same config for the figures' jobs.
    """
    from hydra import compose as hydra_compose
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from omegaconf import OmegaConf

    parsed = OverridesParser.create().parse_overrides(list(overrides))
    if any(o.is_add() or o.is_force_add() or o.is_delete() or o.package is not None for o in parsed):
        cfg = hydra_compose("config", overrides=list(overrides))
    else:
        cfg = copy.deepcopy(_compose_groups(tuple(o.input_line for o in parsed if _is_group(o.key_or_group))))
        for o in (o for o in parsed if not _is_group(o.key_or_group)):
            OmegaConf.update(cfg, o.key_or_group, o.value(), merge=True)
    return yaml.load(OmegaConf.to_yaml(cfg, resolve=True), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))


class IndexedRun(NamedTuple):
    path: Path
    status: str
    clock: float  # training clock reached (s)


def run_index(root: Path | None) -> dict[str, IndexedRun]:
    """The results index of a runs root, one run per config (``one_per_config``): identity -> its
    run. A view of ``load_runs(root, figure_runs=True)``, no status or duplicate rule of its own;
    read again after a launch, so that runs continued from new ones get their parent's identity."""
    if root is None or not Path(root).is_dir():
        return {}
    runs = one_per_config(load_runs(Path(root), figure_runs=True))
    clocks = runs.get("train_time_s", [math.nan] * len(runs))
    return {
        str(i): IndexedRun(Path(p).resolve(), str(s), float(c) if c == c else 0.0)
        for i, p, s, c in zip(runs["config_id"], runs["path"], runs["status"], clocks)
    }


def resumable(run: IndexedRun) -> bool:
    """A run stopped before its end that left a checkpoint (``resume=`` continues it)."""
    return run.status in RESUMABLE_STATUSES and checkpoint_path(run.path).is_file()


def resolve(jobs: Iterable[Job], index: dict[str, IndexedRun], compose: Callable[[tuple], dict] = compose) -> None:
    """Fill in each job's config and identity, and its run file if one is done (or the stopped
    run to resume); a job whose parent or seed search is not done yet is "waiting" (declaration
    order: those come first)."""
    with hydra_conf():
        for job in jobs:
            if (job.parent is not None and not job.parent.done) or not all(s.done for s in job.search):
                job.identity, job.path, job.status = None, None, "waiting"
                continue
            if job.search:
                job.seed = pick_seed(job.search)
                job.overrides["seed"] = job.seed
            job.config = dict(compose(tuple(job.override_list())))
            job.identity = identity_of(job.config, job.parent.identity if job.parent else None)
            run = index.get(job.identity)
            job.status, job.reason = (run.status if run else "missing"), ""
            job.path = run.path if run and job.done else None
            job.resume_from = run.path if run and resumable(run) else None
            job.clock_done = run.clock if job.resume_from else 0.0


@dataclass(frozen=True)
class Launcher:
    """Where a launch's jobs run.

    name: ``joblib`` (default; ``auto`` is the same: local workers, ``n_jobs`` = ``--jobs``),
    ``basic`` (one run after another in one process), ``submitit_local`` or ``submitit_slurm``
    (one submitit job array per round: ``higbench.jobs.arrays``), or any other launcher config
    of ``hydra/launcher`` (``slurm``: conf/hydra/launcher/slurm.yaml). overrides: extra
    ``hydra.*`` overrides for every multirun (``hydra.launcher.partition=gpu``); they do not
    change a run's identity. A submitit launcher's settings are checked here (``LauncherError``).
    """

    name: str = "joblib"
    overrides: tuple[str, ...] = ()

    def __post_init__(self):
        bad = [o for o in self.overrides if not o.split("=", 1)[0].lstrip("+~").startswith("hydra.")]
        if bad:
            raise LauncherError(f"{bad[0]}: only hydra.* overrides may be added to the figures' runs (others change the runs)")
        if self.array:
            arrays.submitit_parameters(self.name, self.settings())

    @property
    def array(self) -> bool:
        """Whether a round goes out as one submitit job array."""
        return self.name in arrays.SUBMITIT

    def settings(self) -> dict[str, Any]:
        """The ``hydra.launcher.*`` overrides as {key: value} (Hydra's grammar reads the values)."""
        mine = [o.lstrip("+") for o in self.overrides if o.lstrip("+").startswith("hydra.launcher.")]
        return {k.removeprefix("hydra.launcher."): v for k, v in parse_overrides(mine).items()}

    def args(self, n_runs: int, n_jobs: int, seconds: float) -> list[str]:
        """Hydra overrides choosing the launcher for a multirun of ``n_runs`` runs."""
        name = "joblib" if self.name == "auto" else self.name
        if name in ("joblib", "basic") or self.array:  # an array's tasks run one job each, in-process
            workers = min(n_jobs, n_runs)
            if name != "joblib" or workers <= 1 or seconds < PARALLEL_SECONDS:  # not worth starting workers
                return [o for o in self.overrides if not o.lstrip("+").startswith("hydra.launcher.")]
            return ["hydra/launcher=joblib", f"hydra.launcher.n_jobs={workers}", *self.overrides]
        return [f"hydra/launcher={name}", *self.overrides]

    def workers(self, n_runs: int, n_jobs: int) -> int:
        """How many of ``n_runs`` jobs run at once (for the time-left forecast)."""
        if self.array:
            return max(1, min(n_runs, int(self.settings().get("array_parallelism") or n_runs)))
        return max(1, min(n_runs, n_jobs if self.name in ("joblib", "auto") else 1))


def as_launcher(launcher: str | Launcher, overrides: Sequence[str] = ()) -> Launcher:
    """A Launcher from a name and ``KEY=VALUE`` settings (``hydra.launcher.KEY=VALUE`` too)."""
    if isinstance(launcher, Launcher):
        return Launcher(launcher.name, (*launcher.overrides, *launcher_overrides(overrides))) if overrides else launcher
    return Launcher(str(launcher), tuple(launcher_overrides(overrides)))


def launcher_overrides(settings: Sequence[str]) -> list[str]:
    """``partition=gpu`` -> ``hydra.launcher.partition=gpu``; ``hydra.*`` overrides as given."""
    out = []
    for item in settings:
        key, eq, _ = str(item).partition("=")
        if not eq or not key.strip():
            raise LauncherError(f"{item}: a launcher setting is KEY=VALUE (partition=gpu, timeout_min=90)")
        out.append(item if key.lstrip("+~").startswith("hydra.") else f"hydra.launcher.{item}")
    return out


def multirun_command(
    jobs_file: Path, sweep_dir: Path, launcher_args: Sequence[str], subdir: str = "${hydra.job.num}"
) -> list[str]:
    """``higbench -m`` over the jobs of ``jobs_file`` (job-list sweeper), into ``sweep_dir``."""
    args = [sys.executable, "-m", "higbench.cli", "-m", "hydra/sweeper=joblist", f"hydra.sweeper.jobs_file={fmt(str(jobs_file))}"]
    args += [*LAUNCH_OVERRIDES, f"hydra.sweep.dir={fmt(str(sweep_dir))}", f"hydra.sweep.subdir={subdir}"]
    return args + list(launcher_args)


def job_seconds(job: Job) -> float:
    """Rough training seconds a job has left (its budget less what a stopped run of it spent;
    a budget in updates counts one second each)."""
    s = job.overrides.get("budget.seconds")
    if s is not None:
        return max(0.0, float(s) - job.clock_done)
    return float(job.overrides.get("budget.max_updates") or 1)


def training_text(jobs: Sequence[Job]) -> str:
    """What the jobs have left to train, as a line says it: seconds where budgets are seconds,
    updates where they are updates (their seconds are not known before they run)."""
    seconds = [job_seconds(j) for j in jobs if j.overrides.get("budget.seconds") is not None]
    updates = [int(j.overrides["budget.max_updates"]) for j in jobs
               if j.overrides.get("budget.seconds") is None and j.overrides.get("budget.max_updates") is not None]  # fmt: skip
    parts = [f"~{sum(seconds):.0f} s of training"] if seconds else []
    parts += [f"{sum(updates):,} updates"] if updates else []
    if len(seconds) + len(updates) < len(jobs):
        parts.append(f"{len(jobs) - len(seconds) - len(updates)} on the problem's default budget")
    return " and ".join(parts)


POLL_S = 2.0  # how often a driver looks at the ledger while its jobs run, or while it waits for others'


def launch(
    jobs: list[Job], runs_root: Path, *, n_jobs: int, launcher: str | Launcher = "joblib", log=print, progress: bool = True
) -> list[Path]:
    """Run the jobs once, longest first: those no live worker holds as one ``higbench -m``
    multirun over their list on a Hydra launcher, or as one submitit job array (``Launcher``, or
    the name of one), each job claimed in the ledger of ``runs_root`` first; then wait for the
    jobs other workers hold. Returns the run files written. With joblib at most ``n_jobs``
    training processes at once. Jobs the ledger says are final are not run. progress=False: no
    'N of M runs done' line (a caller that counts a larger whole, the league, prints its own)."""
    launcher = as_launcher(launcher)
    runs_root = Path(runs_root)
    ledger = Ledger(runs_root)
    claimed = bool(jobs) and all(j.identity for j in jobs)  # jobs resolved: each has its identity in the ledger
    held = _held_elsewhere(jobs, ledger, log) if claimed else []
    final = [j for j in jobs if claimed and j not in held and ledger.final(j.identity)]
    if final:
        log(f"[jobs] {len(final)} run(s) not run again: the ledger records them refused or failed repeatedly ({ledger.dir})")
    jobs = [j for j in jobs if j not in held and j not in final]
    watched = ledger if claimed and progress else None
    new = (
        _launch(jobs, runs_root, ledger if claimed else None, watched, n_jobs=n_jobs, launcher=launcher, log=log) if jobs else []
    )
    if claimed:
        wait_for_holders([j for j in [*jobs, *held] if not j.done], ledger, log)
    return new


def _launch(
    jobs: list[Job], runs_root: Path, ledger: Ledger | None, watched: Ledger | None, *, n_jobs: int, launcher: Launcher, log
) -> list[Path]:
    jobs = sorted(jobs, key=job_seconds, reverse=True)  # the longest start first: no idle core at the end
    sweep_dir = (runs_root / FIGURE_RUNS_DIR / f"{time.strftime('%Y-%m-%d_%H-%M-%S')}-{os.getpid()}").resolve()
    sweep_dir.mkdir(parents=True, exist_ok=False)
    jobs_file = sweep_dir / "jobs.json"
    jobs_file.write_text(json.dumps(jobs_listing(jobs, sweep_dir, runs_root if ledger else None), indent=1) + "\n")
    secs = sum(map(job_seconds, jobs))
    extra = launcher.args(len(jobs), n_jobs, secs)
    chosen = next((a.split("=", 1)[1] for a in extra if a.startswith("hydra/launcher=")), "basic")
    how = f"{launcher.name} array" if launcher.array else chosen
    figures = ", ".join(sorted({j.figure for j in jobs}))
    resumed = [j.resume_from for j in jobs if j.resume_from is not None]
    again = f", {len(resumed)} resumed in place" if resumed else ""
    log(f"[figures] running {len(jobs)} run(s) of {figures} ({how}{again}, {training_text(jobs)}) -> {sweep_dir}")
    t0 = time.perf_counter()
    with watching(jobs, watched, launcher.workers(len(jobs), n_jobs)):
        if launcher.array:
            status = _run_array(jobs_file, sweep_dir, len(jobs), launcher, extra)
        else:
            status = _run_multirun(jobs_file, sweep_dir, extra)
    new = sorted([*sweep_dir.rglob(RUN_FILE), *resumed])
    log(f"[figures] {len(new)}/{len(jobs)} run file(s) in {time.perf_counter() - t0:.0f} s ({status})")
    return new


def jobs_listing(jobs: Sequence[Job], sweep_dir: Path, ledger_root: Path | None) -> list | dict:
    """The jobs file of a launch: each job's overrides; with a ledger also its identity (claimed
    before it runs) and the run file it writes (its own job dir, or the stopped run it resumes)."""
    if ledger_root is None:
        return [j.launch_overrides() for j in jobs]
    entries = []
    for i, j in enumerate(jobs):
        run = j.resume_from if j.resume_from is not None else sweep_dir / str(i) / RUN_FILE
        entries.append({"overrides": j.launch_overrides(), "claim": j.identity, "run": str(run)})
    return {"ledger": str(Path(ledger_root).resolve()), "jobs": entries}


def _checkout_env() -> dict[str, str]:
    from higbench.runner.train import DRIVER_ENV  # the sweep stops when this driver is gone

    env = dict(os.environ)  # the checkout on the path: higbench and its hydra_plugins (the job-list sweeper)
    env["PYTHONPATH"] = os.pathsep.join([str(PACKAGE_PARENT), *filter(None, [env.get("PYTHONPATH")])])
    env[DRIVER_ENV] = str(os.getpid())
    return env


def _run_multirun(jobs_file: Path, sweep_dir: Path, extra: list[str]) -> str:
    with open(sweep_dir / "launch.log", "w") as out:
        cmd = multirun_command(jobs_file, sweep_dir, extra)
        out.write(" ".join(cmd) + "\n\n")
        out.flush()
        proc = run_to_end(cmd, stdout=out, stderr=subprocess.STDOUT, env=_checkout_env())
    return "ok" if proc.returncode == 0 else f"exit code {proc.returncode}, see {sweep_dir / 'launch.log'}"


def run_to_end(cmd: list[str], **kwargs) -> subprocess.Popen:
    """``subprocess.run`` for a multirun, except when the driver is stopped: its job then gets
    time to close its runs (``close_on_interrupt``) rather than a kill after 0.25 s."""
    proc = start_job(cmd, **kwargs)
    try:
        proc.wait()
    except KeyboardInterrupt:
        close_on_interrupt(proc)
        raise
    return proc


def start_job(cmd: list[str], **kwargs) -> subprocess.Popen:
    """The job in a process group of its own, so that the driver alone decides when it stops, and
    the stop reaches the launcher's workers too (joblib's), not only the sweep's parent. The job
    gets SIGINT's default even where the driver has it ignored (``_sigint_not_ignored``)."""
    with _sigint_not_ignored():
        return subprocess.Popen(cmd, start_new_session=True, **kwargs)


@contextmanager
def _sigint_not_ignored():
    """A shell that starts the driver in the background ignores SIGINT for it, and an ignored signal
    stays ignored across exec (a caught one is reset to its default). A job started so missed the
    SIGINT of ``close_on_interrupt`` until its run set its own handler: a stop sent while the sweep
    was starting was lost, and its first run killed after ``CLOSE_S`` without closing its file.
    Catching SIGINT around the start gives the job the default; only the main thread may."""
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN or threading.current_thread() is not threading.main_thread():
        yield
        return
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)


CLOSE_S = 60.0  # how long a stopped driver waits for its runs to write their last rows and checkpoint


def close_on_interrupt(proc: subprocess.Popen) -> None:
    """The driver was stopped (Ctrl-C or SIGTERM): the job's whole group gets one SIGINT, as Ctrl-C
    gives a terminal's foreground group, so every running run stops after its update and closes its
    run file (resumable) and no launcher starts another; what still runs after ``CLOSE_S`` is killed."""
    _signal_group(proc, signal.SIGINT)
    try:
        proc.wait(timeout=CLOSE_S)
    except subprocess.TimeoutExpired:
        _signal_group(proc, signal.SIGKILL)
        proc.wait()


def _signal_group(proc: subprocess.Popen, signum: int) -> None:
    try:
        os.killpg(proc.pid, signum)
    except ProcessLookupError:  # the job and its workers are gone already
        pass


def _run_array(jobs_file: Path, sweep_dir: Path, n: int, launcher: Launcher, extra: list[str]) -> str:
    """The jobs as one submitit job array; task i runs job i of the jobs file; waits for all."""
    ex = arrays.executor(launcher.name, sweep_dir / "submitit", launcher.settings())
    commands = [multirun_command(jobs_file, sweep_dir, [*extra, f"hydra.sweeper.only={i}"], subdir=str(i)) for i in range(n)]
    saved = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = _checkout_env()["PYTHONPATH"]  # the tasks' environment is the submitting one
    try:
        tasks = arrays.submit_array(ex, commands)
    finally:
        os.environ.pop("PYTHONPATH") if saved is None else os.environ.__setitem__("PYTHONPATH", saved)
    (sweep_dir / "launch.log").write_text(f"submitit array {tasks[0].job_id.split('_')[0]} of {n} task(s)\n" if tasks else "")
    while not all(t.done() for t in tasks):
        pause(POLL_S)
    failed = sum(1 for t in tasks if t.exception() is not None or t.result() != 0)
    return "ok" if not failed else f"{failed} task(s) failed, see {sweep_dir / 'submitit'}"


@contextmanager
def watching(jobs: Sequence[Job], ledger: Ledger | None, workers: int):
    """'N of M runs done (K failed), about T left' while the block runs (``CountProgress``),
    from the ledger's records of the jobs; T: the budgets left, shared among the workers."""
    from higbench.runner.progress import CountProgress

    enabled = ledger is not None and any(str(j.overrides.get("progress", True)).lower() != "false" for j in jobs)
    progress = CountProgress(enabled, "jobs", len(jobs))
    if not progress.enabled:
        yield
        return
    before = {j.identity: ledger.record(j.identity).get("finished") for j in jobs}
    stop = threading.Event()

    shown = [(0, 0)]

    def look() -> None:
        ended = {j.identity: r for j in jobs if (r := ledger.record(j.identity)).get("finished") != before[j.identity]}
        failed = sum(1 for r in ended.values() if r.get("status") not in DONE_STATUSES)
        if (len(ended), failed) == shown[0]:
            return  # a line when something ended, not one per look
        shown[0] = (len(ended), failed)
        left = [j for j in jobs if j.identity not in ended]
        progress.update(len(ended), sum(map(job_seconds, left)) / max(1, min(workers, len(left))), failed)

    def watch() -> None:
        while not stop.wait(POLL_S):
            look()

    progress.update(0, sum(map(job_seconds, jobs)) / max(1, min(workers, len(jobs))))
    thread = threading.Thread(target=watch, name="jobs-progress", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()
        look()
        progress.close()


def _held_elsewhere(jobs: Sequence[Job], ledger: Ledger, log) -> list[Job]:
    """The jobs a live worker holds now (another driver's, or one a killed driver left running)."""
    held = [j for j in jobs if ledger.live_holder(j.identity) is not None]
    if held:
        log(f"[jobs] {len(held)} run(s) are being run by other workers (ledger: {ledger.dir}); waited for, not run again")
    return held


def pause(seconds: float) -> None:
    """A driver's wait between two looks at its jobs (one name: tests replace it)."""
    time.sleep(seconds)


def wait_for_holders(jobs: Sequence[Job], ledger: Ledger, log, poll_s: float | None = None) -> None:
    """Until no live worker holds any of the jobs (a dead worker's claim no longer counts)."""
    said = 0
    while held := [j for j in jobs if ledger.live_holder(j.identity) is not None]:
        if len(held) != said:
            log(f"[jobs] waiting for {len(held)} run(s) held by other workers (ledger: {ledger.dir})")
            said = len(held)
        pause(POLL_S if poll_s is None else poll_s)


def composed_value(key: str, *overrides: str) -> Any:
    """One value of the config the CLI composes for ``overrides``: ``composed_value("optimizer.lr",
    "problem=poisson", "optimizer=adam")`` is the pair's default (conf/problem_optimizer/: the
    paper's rate), read where the CLI reads it instead of typed again."""
    with hydra_conf():
        return dotted_get(compose(tuple(overrides)), key)


def parse_overrides(overrides: Sequence[str]) -> dict[str, Any]:
    """``["seed=7", "problem.hidden=[64,128,64]"]`` -> ``{"seed": 7, "problem.hidden": [64, 128, 64]}``:
    values as Hydra's override grammar reads them (what ``Job.overrides`` holds)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    return {o.key_or_group: o.value() for o in OverridesParser.create().parse_overrides(list(overrides))}


# Launchers whose runs train on this machine: their budgets in seconds are only equal when each
# run has a core to itself.
LOCAL_LAUNCHERS = ("basic", "joblib", "auto", "submitit_local")


def busy_cores() -> float:
    """Cores of this process in use right now (``runner.threads.idle_cores``: /proc/stat over
    0.2 s; the 1-minute load average would still count a driver's own runs that just ended)."""
    idle = idle_cores()
    return 0.0 if idle is None else max(0.0, available_cores() - idle)


def busy_machine(n_runs: int, busy: float | None = None, cores: int | None = None) -> str | None:
    """One line when ``n_runs`` runs at once would share this process's cores with work already
    running, else None: their budgets in seconds then buy less than on an idle machine."""
    cores = cores or available_cores()
    busy = busy_cores() if busy is None else busy
    if busy + n_runs <= cores + 0.25:
        return None
    return (f"[jobs] busy machine: {busy:.1f} of {cores} cores in use before {n_runs} run(s) at once start: the runs "
            "will share cores, so a budget in seconds buys less than on an idle machine (each run records its CPU "
            "share, env/cpu_share)")  # fmt: skip


def run_missing(
    jobs: Sequence[Job],
    runs_root: Path,
    *,
    n_jobs: int = 1,
    launcher: str | Launcher = "joblib",  # with n_jobs=1 the same as basic
    launcher_overrides: Sequence[str] = (),
    log=print,
    progress: bool = True,
    known: Mapping[str, IndexedRun] | None = None,
) -> list[Job]:
    """The one reuse rule for a set of jobs (the figures' rounds, the league, the bench scripts):
    resolve them against the runs root's index, launch those not done (a stopped run with a
    checkpoint resumes in place; one a live worker holds is waited for, not run again), and
    resolve them again. Returns the jobs still not done; those the ledger says are final
    (refused for memory, or failed ``MAX_FAILURES`` times in a row) among them have that
    ``status`` and its ``reason``, and are not launched again.

    launcher: ``basic``, ``joblib`` (``n_jobs`` workers), ``submitit_local``, ``submitit_slurm``
    (one job array per call) or a ``Launcher``; launcher_overrides: its settings as
    ``KEY=VALUE`` (``partition=gpu``, ``timeout_min=90``, or ``hydra.launcher.KEY=VALUE``),
    checked before anything runs (``LauncherError``: one line naming the key). known: runs done
    elsewhere (identity -> run; a league's earlier tables): reused like the root's own, never rerun;
    a run of the root itself takes precedence."""
    launcher = as_launcher(launcher, launcher_overrides)
    runs_root = Path(runs_root)
    ledger = Ledger(runs_root)
    launched: set[str] = set()
    resolve(jobs, {**(known or {}), **run_index(runs_root)})
    mark_final(jobs, ledger)
    todo = [j for j in jobs if launchable(j)]
    elsewhere = " or in the earlier tables" if known else ""
    log(f"[jobs] {sum(j.done for j in jobs)} of {len(jobs)} run(s) already done under {runs_root}{elsewhere}")
    at_once = 1 if launcher.name == "basic" else min(n_jobs, len(todo))
    if todo and launcher.name in LOCAL_LAUNCHERS and (busy := busy_machine(at_once)):
        log(busy)
    while todo:  # a job once per call; again only if it was another worker's, and that worker died
        held = {j.identity for j in todo if j.identity and ledger.live_holder(j.identity) is not None}
        launch(todo, runs_root, n_jobs=n_jobs, launcher=launcher, log=log, progress=progress)
        launched.update(j.identity for j in todo if j.identity not in held)
        resolve(jobs, {**(known or {}), **run_index(runs_root)})
        mark_final(jobs, ledger)
        todo = [j for j in jobs if launchable(j) and j.identity not in launched]
    return [j for j in jobs if not j.done]


def launchable(job: Job) -> bool:
    return not job.done and job.status not in ("waiting", *FINAL_STATUSES) and not job.reason


def mark_final(jobs: Sequence[Job], ledger: Ledger) -> None:
    """Jobs not done whose ledger record is final: their status and reason from it."""
    for j in jobs:
        if not j.done and j.identity and (rec := ledger.final(j.identity)) is not None:
            j.status, j.reason = str(rec.get("status")), str(rec.get("reason") or "failed repeatedly")
