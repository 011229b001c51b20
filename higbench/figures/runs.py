"""Which runs a figure needs, which of them exist, and running the missing ones.

Identity. A run is identified by its resolved config (what ``higbench`` composes with
Hydra for the same overrides) minus the keys that do not change its result: output
paths live in the Hydra node (not in the task config at all), and ``COSMETIC_KEYS``
(progress bar, torch threads, checkpoint interval, resume, memory cap) are dropped.
``init_from`` (a path) is replaced by the identity of the run it points at, so a
continued run keeps its identity wherever its parent's file lies.

Reuse. Every ``*.h5`` under the runs root (``outputs/`` by default, including runs made
by hand with ``higbench``) is indexed by identity; a run whose status is ``completed`` or
``diverged`` (a diverged run is a result) is reused. Missing, failed, interrupted and
still-running (or killed) runs are (re)run.

Running. The missing jobs of a figure are grouped into exact cartesian products
("boxes"); each box (cut into ``--jobs`` pieces to run side by side) is one
``python -m higbench.cli -m ...`` multirun, i.e. the same Hydra machinery and checks as
the CLI (``--launcher joblib``: one multirun per box on Hydra's joblib launcher instead).
Run files go to ``<runs root>/figures-runs/<figure>/<time>/<job number>/run.h5``.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import yaml

from higbench.figures.spec import Figure, Preset, Sweep
from higbench.runfile.reader import RUN_FILE, run_file_path

COSMETIC_KEYS = ("progress", "threads", "checkpoint_every", "resume", "memory_limit_mb")
DONE_STATUSES = ("completed", "diverged")
LAUNCH_OVERRIDES = ["progress=false", "threads=1"]
SPLIT_SECONDS = 30  # a box with less training than this runs in one process
REPO_ROOT = Path(__file__).resolve().parents[2]

try:
    _Loader = yaml.CSafeLoader
except AttributeError:  # pragma: no cover
    _Loader = yaml.SafeLoader


# -- overrides ------------------------------------------------------------------------------


def fmt(value: Any) -> str:
    """A Python value as a Hydra override value."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str) and any(c in value for c in " ,'\"[]{}()=:*?$\\"):
        return "'" + value.replace("\\", "\\\\").replace("'", "\\'") + "'"
    return str(value)


@dataclass
class Job:
    """One run a figure needs: its overrides (ordered) and, once known, its run file."""

    figure: str
    sweep: str
    overrides: dict[str, Any]  # everything but init_from, in order
    seed: int
    parent: Job | None = None  # init_from: this job starts from the parent's final weights
    search: list[Job] = field(default_factory=list)  # seed search: the seed is picked from these runs
    search_note: str = ""  # how the seed was picked
    identity: str | None = None
    config: dict | None = None  # resolved task config (init_from: the parent's path)
    path: Path | None = None  # the run file that satisfies it
    status: str = "missing"

    def override_list(self) -> list[str]:
        items = [f"{k}={fmt(v)}" for k, v in self.overrides.items()]
        if self.parent is not None:
            items.append(f"init_from={fmt(str(self.parent.path)) if self.parent.path else 'PENDING'}")
        return items

    @property
    def done(self) -> bool:
        return self.status in DONE_STATUSES

    def value(self, key: str, default: Any = None) -> Any:
        """A resolved config value by dotted key (``optimizer.lr``)."""
        node: Any = self.config or {}
        for part in key.split("."):
            if not isinstance(node, dict) or part not in node:
                return default
            node = node[part]
        return node


def expand(figure: Figure, preset: Preset) -> list[Job]:
    """The jobs of a figure at a preset, parents (init_from) resolved within the figure."""
    sweeps = figure.runs(preset)
    by_name: dict[str, list[Job]] = {}
    jobs: list[Job] = []
    for sweep in sweeps:
        mine = _sweep_jobs(figure.id, sweep, preset)
        if sweep.seed_search is not None:
            mine = _with_search(figure.id, sweep, mine, preset, jobs)
        if sweep.init_from is not None:
            parents = by_name.get(sweep.init_from)
            if not parents:
                raise ValueError(
                    f"{figure.id}: sweep {sweep.name!r} starts from {sweep.init_from!r}, which is not declared before it"
                )
            for job in mine:
                same_seed = [p for p in parents if p.seed == job.seed]
                job.parent = same_seed[0] if same_seed else parents[0]
        by_name[sweep.name] = mine
        jobs.extend(mine)
    return jobs


def _with_search(figure_id: str, sweep: Sweep, mine: list[Job], preset: Preset, jobs: list[Job]) -> list[Job]:
    """One main job per grid point (seed to be picked) after its seed-search jobs (added to ``jobs``)."""
    search = sweep.seed_search
    main: dict[tuple, Job] = {}
    searches: dict[tuple, list[Job]] = {}  # grid points with the same search share its runs
    for job in mine:
        key = tuple((k, fmt(v)) for k, v in job.overrides.items() if k != "seed")
        if key in main:
            continue
        main[key] = job
        base = {k: v for k, v in job.overrides.items() if not k.startswith("budget.") and k not in ("eval_unit", "eval_every")}
        base.update(search.overrides)
        skey = tuple((k, fmt(v)) for k, v in base.items() if k != "seed")
        if skey not in searches:
            searches[skey] = []
            for seed in search.seeds:
                ov = {**base, "seed": seed, **search.budget.overrides(preset)}
                searches[skey].append(Job(figure_id, f"{sweep.name}/search", ov, seed))
            jobs.extend(searches[skey])
        job.search = searches[skey]
    return list(main.values())


def pick_seed(search: list[Job]) -> tuple[int, str]:
    """(seed, note): the best stable search run (completed, final test loss finite and below
    its initial one; lowest final loss), else the first seed."""
    from higbench.runfile.reader import load_run

    stable, diverged = {}, 0
    for job in search:
        if job.status == "diverged":
            diverged += 1
        if job.status != "completed" or job.path is None:
            continue
        try:
            loss = load_run(job.path)[1]["test_loss"].to_numpy(dtype=float)
        except Exception:  # noqa: BLE001 - an unreadable file is not a stable run
            continue
        if len(loss) >= 2 and loss[-1] == loss[-1] and loss[-1] < loss[0]:
            stable[job.seed] = float(loss[-1])
    n = len(search)
    tally = f"{n} seeds searched: {diverged} diverged, {n - diverged - len(stable)} unstable (loss rose), {len(stable)} stable"
    if not stable:
        return search[0].seed, f"{tally}; no stable seed, seed {search[0].seed} used"
    seed = min(stable, key=stable.get)
    return seed, f"{tally}; best stable seed {seed}"


def _sweep_jobs(figure_id: str, sweep: Sweep, preset: Preset) -> list[Job]:
    import itertools

    problem = sweep.fixed.get("problem")
    keys = list(sweep.grid)
    out = []
    for combo in itertools.product(*(sweep.grid[k] for k in keys)):
        for seed in sweep.seeds:
            ov: dict[str, Any] = {}
            ov.update(sweep.fixed)
            ov.update(dict(zip(keys, combo)))
            ov["seed"] = seed
            ov.update(sweep.budget.overrides(preset))
            if problem is not None:
                for k, v in preset.problem_overrides(str(problem)).items():
                    ov.setdefault(k, v)
            out.append(Job(figure_id, sweep.name, ov, seed))
    return out


# -- identity -------------------------------------------------------------------------------


def identity_of(config: dict, parent_identity: str | None = None) -> str:
    """The identity hash of a resolved task config (cosmetic keys dropped)."""
    c = {k: v for k, v in config.items() if k not in COSMETIC_KEYS}
    if c.get("init_from"):
        c["init_from"] = {"run": parent_identity or f"path:{c['init_from']}"}
    text = json.dumps(c, sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def _conf_fingerprint(conf_dir: Path) -> str:
    h = hashlib.sha1()
    for p in sorted(conf_dir.rglob("*.yaml")):
        h.update(str(p.relative_to(conf_dir)).encode())
        h.update(p.read_bytes())
    return h.hexdigest()


class Composer:
    """Hydra's compose API on the CLI's config dir, with a cache keyed by conf/ contents."""

    def __init__(self, cache_file: Path | None):
        from higbench.cli import config_dir

        self.conf_dir = Path(config_dir())
        self.fingerprint = _conf_fingerprint(self.conf_dir)
        self.cache_file = cache_file
        self.cache: dict[str, dict] = {}
        self.dirty = False
        if cache_file is not None and cache_file.is_file():
            try:
                stored = json.loads(cache_file.read_text())
                if stored.get("fingerprint") == self.fingerprint:
                    self.cache = stored.get("configs", {})
            except ValueError:
                pass
        self._ctx = None

    def compose(self, overrides: list[str]) -> dict:
        key = json.dumps(overrides)
        if key in self.cache:
            return self.cache[key]
        from hydra import compose, initialize_config_dir
        from omegaconf import OmegaConf

        if self._ctx is None:
            from hydra.core.global_hydra import GlobalHydra

            GlobalHydra.instance().clear()
            self._ctx = initialize_config_dir(config_dir=str(self.conf_dir), version_base="1.3", job_name="higbench")
            self._ctx.__enter__()
        cfg = compose("config", overrides=overrides)
        # The same serialisation as the run file's config attribute (OmegaConf -> YAML).
        resolved = yaml.load(OmegaConf.to_yaml(cfg, resolve=True), Loader=_Loader)
        self.cache[key] = resolved
        self.dirty = True
        return resolved

    def close(self) -> None:
        if self._ctx is not None:
            self._ctx.__exit__(None, None, None)
            self._ctx = None
        if self.dirty and self.cache_file is not None:
            self.cache_file.parent.mkdir(parents=True, exist_ok=True)
            tmp = self.cache_file.with_suffix(f".tmp{os.getpid()}")
            tmp.write_text(json.dumps({"fingerprint": self.fingerprint, "configs": self.cache}))
            tmp.replace(self.cache_file)
            self.dirty = False


# -- the index of existing runs -------------------------------------------------------------


@dataclass
class IndexedRun:
    path: Path
    status: str
    config: dict
    mtime: float
    identity: str | None = None


@dataclass
class RunIndex:
    """Every run file under a root, by identity (the newest done run wins)."""

    root: Path
    runs: dict[Path, IndexedRun] = field(default_factory=dict)

    @classmethod
    def scan(cls, root: Path) -> RunIndex:
        index = cls(Path(root))
        if not index.root.is_dir():
            return index
        for path in sorted(index.root.rglob("*.h5")):
            run = _read_head(path)
            if run is not None:
                index.runs[path.resolve()] = run
        for run in index.runs.values():
            index._identity(run, set())
        return index

    def _identity(self, run: IndexedRun, seen: set) -> str:
        if run.identity is None:
            parent_id = None
            src = run.config.get("init_from")
            if src:
                parent = self.runs.get(_run_file(src).resolve())
                if parent is not None and parent.path not in seen:
                    parent_id = self._identity(parent, seen | {run.path})
            run.identity = identity_of(run.config, parent_id)
        return run.identity

    def add(self, path: Path) -> None:
        run = _read_head(path)
        if run is not None:
            self.runs[path.resolve()] = run
            self._identity(run, set())

    def find(self, identity: str) -> IndexedRun | None:
        """The newest done run with this identity, else the newest run of any status."""
        matches = [r for r in self.runs.values() if r.identity == identity]
        if not matches:
            return None
        done = [r for r in matches if r.status in DONE_STATUSES]
        return max(done or matches, key=lambda r: r.mtime)


def _run_file(path: str) -> Path:
    return run_file_path(path)


def _read_head(path: Path) -> IndexedRun | None:
    if not path.is_file():  # a FIFO or device named *.h5 would block the open forever
        return None
    try:
        with h5py.File(path, "r", locking=False) as f:
            attrs = f.attrs
            if "config" not in attrs:
                return None
            status = attrs.get("status", "running")
            config = attrs["config"]
        status = status.decode() if isinstance(status, bytes) else str(status)
        config = config.decode() if isinstance(config, bytes) else str(config)
        cfg = yaml.load(config, Loader=_Loader) or {}
        return IndexedRun(path.resolve(), status, cfg, path.stat().st_mtime)
    except Exception:  # noqa: BLE001 - half-written or foreign files are not runs
        return None


def resolve(jobs: Iterable[Job], composer: Composer, index: RunIndex) -> None:
    """Fill in each job's config and identity, and its run file if one is done."""
    for job in jobs:  # parents and search runs come first (expand keeps declaration order)
        if job.parent is not None and not job.parent.done:
            job.identity, job.path, job.status = None, None, "waiting"
            continue
        if job.search:
            if not all(s.done for s in job.search):
                job.identity, job.path, job.status = None, None, "waiting"
                continue
            job.seed, job.search_note = pick_seed(job.search)
            job.overrides["seed"] = job.seed
        config = dict(composer.compose(job.override_list()))
        job.config = config
        job.identity = identity_of(config, job.parent.identity if job.parent else None)
        run = index.find(job.identity)
        if run is None:
            job.path, job.status = None, "missing"
        else:
            job.path, job.status = run.path, run.status
            if run.status not in DONE_STATUSES:
                job.path = None


# -- grouping missing jobs into Hydra multiruns ---------------------------------------------


def boxes(jobs: list[Job]) -> list[tuple[list[Job], dict[str, list]]]:
    """Exact cover of the jobs by cartesian products of override values.

    Jobs with the same override keys are merged greedily: two boxes that agree on every
    key but one become one box with the union of that key's values. Returns
    (jobs, {key: [values]}) per box; every job is in exactly one box and no box holds a
    combination that is not a job.
    """
    groups: dict[tuple, list[Job]] = {}
    for job in jobs:
        groups.setdefault(tuple(_job_items(job)), []).append(job)
    out = []
    for keys, members in groups.items():
        cells = [({k: [v] for k, v in _job_items(j).items()}, [j]) for j in members]
        merged = True
        while merged:
            merged = False
            for key in keys:
                i = 0
                while i < len(cells):
                    j = i + 1
                    while j < len(cells):
                        a, b = cells[i][0], cells[j][0]
                        if all(_same(a[k], b[k]) for k in keys if k != key):
                            union = a[key] + [v for v in b[key] if not any(_eq(v, w) for w in a[key])]
                            cells[i] = ({**a, key: union}, cells[i][1] + cells[j][1])
                            del cells[j]
                            merged = True
                        else:
                            j += 1
                    i += 1
        out.extend((js, box) for box, js in cells)
    return out


def _job_items(job: Job) -> dict[str, Any]:
    items = dict(job.overrides)
    if job.parent is not None:
        items["init_from"] = str(job.parent.path)
    return items


def _eq(a, b) -> bool:
    return type(a) is type(b) and a == b


def _same(xs: list, ys: list) -> bool:
    return len(xs) == len(ys) and all(any(_eq(x, y) for y in ys) for x in xs)


def box_command(box: dict[str, list], sweep_dir: Path, n_jobs: int, launcher: str) -> list[str]:
    args = [sys.executable, "-m", "higbench.cli", "-m"]
    for key, values in box.items():
        args.append(f"{key}={','.join(fmt(v) for v in values)}")
    args += LAUNCHER_ARGS(sweep_dir)
    if launcher == "joblib":
        args += ["hydra/launcher=joblib", f"hydra.launcher.n_jobs={n_jobs}"]
    return args


def LAUNCHER_ARGS(sweep_dir: Path) -> list[str]:  # noqa: N802
    return [*LAUNCH_OVERRIDES, f"hydra.sweep.dir={fmt(str(sweep_dir))}", "hydra.sweep.subdir=${hydra.job.num}"]


def split(members: list[Job], box: dict[str, list], n: int) -> list[tuple[list[Job], dict[str, list]]]:
    """A box cut into up to n boxes along its longest axis (each still an exact product)."""
    key = max(box, key=lambda k: len(box[k]))
    values = box[key]
    parts = min(n, len(values))
    if parts <= 1:
        return [(members, box)]
    out = []
    for i in range(parts):
        chunk = values[i::parts]
        sub = [j for j in members if any(_eq(_job_items(j)[key], v) for v in chunk)]
        out.append((sub, {**box, key: chunk}))
    return out


def job_seconds(job: Job) -> float:
    """Rough training seconds of a job (its budget; updates count as one second each)."""
    s = job.overrides.get("budget.seconds")
    if s is not None:
        return float(s)
    return float(job.overrides.get("budget.max_updates") or 1)


def launch(
    jobs: list[Job],
    runs_root: Path,
    *,
    n_jobs: int,
    launcher: str,
    log=print,
) -> list[Path]:
    """Run the jobs: one Hydra multirun per box; returns the run files written.

    launcher "basic" (default, "auto"): each box is split along its longest axis into up to
    ``n_jobs`` smaller products, and these multiruns (Hydra's basic launcher: jobs one
    after the other in the CLI process) run ``n_jobs`` at a time. Every job then runs in a
    process whose CLI pre-check has already imported and warmed up torch, as a single run
    does. launcher "joblib": one multirun per box with ``hydra/launcher=joblib`` and
    ``n_jobs`` workers (the first job of each fresh worker pays torch's lazy imports,
    seconds, inside its training clock). At most ``n_jobs`` training processes at once.
    """
    plans = []
    by_figure: dict[str, list[Job]] = {}
    for job in jobs:
        by_figure.setdefault(job.figure, []).append(job)
    for figure_id, fjobs in by_figure.items():
        for members, box in boxes(fjobs):
            if launcher == "joblib" and len(members) > 1 and n_jobs > 1:
                plans.append((figure_id, members, box, "joblib", min(n_jobs, len(members)), len(plans)))
                continue
            # Short boxes (a few updates per run) are not worth a second process start.
            ways = n_jobs if sum(map(job_seconds, members)) >= SPLIT_SECONDS else 1
            for sub_members, sub_box in split(members, box, ways):
                plans.append((figure_id, sub_members, sub_box, "basic", 1, len(plans)))

    def run_box(plan) -> list[Path]:
        figure_id, members, box, which, k, number = plan
        stamp = time.strftime("%Y-%m-%d_%H-%M-%S") + f"-{os.getpid()}-{number}"
        sweep_dir = (runs_root / "figures-runs" / figure_id / stamp).resolve()
        sweep_dir.mkdir(parents=True, exist_ok=False)
        cmd = box_command(box, sweep_dir, k, which)
        secs = sum(map(job_seconds, members))
        how = f"{which} x{k}" if which == "joblib" else which
        log(f"[figures] {figure_id}: running {len(members)} run(s) ({how}, ~{secs:.0f} s of training) -> {sweep_dir}")
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([str(REPO_ROOT), *filter(None, [env.get("PYTHONPATH")])])
        t0 = time.perf_counter()
        with open(sweep_dir / "launch.log", "w") as out:
            out.write(" ".join(cmd) + "\n\n")
            out.flush()
            proc = subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, env=env)
        new = sorted(sweep_dir.rglob(RUN_FILE))
        status = "ok" if proc.returncode == 0 else f"exit code {proc.returncode}, see {sweep_dir / 'launch.log'}"
        log(f"[figures] {figure_id}: {len(new)}/{len(members)} run file(s) in {time.perf_counter() - t0:.0f} s ({status})")
        return new

    written: list[Path] = []
    single = [p for p in plans if p[4] == 1]
    wide = [p for p in plans if p[4] > 1]
    if single:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=max(1, n_jobs)) as pool:
            for new in pool.map(run_box, single):
                written.extend(new)
    for plan in wide:
        written.extend(run_box(plan))
    return written
