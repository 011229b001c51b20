"""The league: tune every optimizer the same way, confirm on fresh seeds and held-out variants, score.

examples:
  higbench-league --problems toy --optimizers adam,sgd,hig --trials 4 --seeds 5 --seconds 2
  higbench-league --problems toy,oscillator --plan                      # runs and hours, nothing run
  higbench-league --searchpath examples/heat/conf --problems heat --optimizers adam,sgd,hig \\
      --trials 3 --seeds 5 --seconds 2                                  # your own problem (PYTHONPATH=examples/heat)
  higbench-league --problems poisson --set poisson/hig:device=cuda      # HIG on a GPU
  higbench-league --launcher submitit_slurm --launcher-set partition=gpu --launcher-set timeout_min=60
  higbench-league --report-only --root runs-a --root runs-b             # merge two machines' tables, train nothing
  higbench-league --problems toy --root outputs/league --root docs/results/league/cpu \\
      --out docs/results/league/cpu                                     # add a piece to a published league

Per-problem protocol: ``--trials 4,toy=16`` (4 trials, 16 on the toy) and likewise ``--seconds``;
``--set [SCOPE:]KEY=VALUE`` adds an override to every job (no SCOPE), or to those of a problem,
an optimizer or a ``problem/optimizer`` (SCOPE). The same flags re-read the runs with ``--report-only``.

Per problem (its config owns the target-setting budget ``problem.target_seconds``, the
fallback budget ``problem.league_seconds``, the test-loss targets ``problem.targets`` and the
held-out variants ``problem.held_out``; ``--seconds`` replaces the budget for a short league):

0. target setting (AlgoPerf's way; ``--references``, default Adam and AdamW; ``''``: none): each
   reference is tuned as in 1 and confirmed as in 2 at ``problem.target_seconds``; per task the
   lowest median final validation loss of a reference is the *validation target*, and 3x that
   reference's median time to it is the league's budget per run (``league.targets_from_reruns``).
   Tuning then selects on time to the validation target (``league.choose_trial``) and the report
   scores time to it within the budget (``league.algoperf_table``). Without references the budget
   is ``problem.league_seconds`` and tuning reads the final validation loss;
1. tuning: ``--studies`` studies of ``--trials`` scrambled Sobol points of each optimizer's search
   space (conf/search/<optimizer>.yaml, or SEARCHPATH/search/<optimizer>.yaml for your own) on the
   study's tuning seed; the best trial by *validation* loss at the budget is the optimizer's
   setting (``choose``);
2. confirmation: that setting on ``--seeds`` fresh seeds, on the problem and on each held-out
   variant (never tuned on); the ``--paper`` optimizers also at their shipped settings, as separate
   rows: "(paper)" where conf/problem_optimizer/ holds the paper's, "(default)" where it holds none;
2b. long budget (``--long SECONDS``): the ``--long-optimizers``' chosen settings, and the shipped
   ones of those in ``--paper``, trained far longer on the first ``--long-seeds`` seeds: the
   paper's own question against today's optimizers, a table of its own (``results.long_budget``);
3. tables and scores: every league run's identity, role and per-evaluation curve go to
   ``ROOT/tables/`` (``higbench.league.tables``: what another machine's root is merged with); the
   scores (test loss, read once here) are computed from those tables and written to ``--out``
   (default ``ROOT/report``) with the manifest: every run's identity and role, the chosen
   settings, the hardware calibration and the machine's load.

Every run is an ordinary higbench run launched through ``higbench.jobs`` into ``--root``; a run
already there (same identity) is reused, so a killed league resumes and a new optimizer adds only
its own runs. A league too long for one sitting runs in pieces: ``--root NEW --root PUBLISHED``
reuses every run in the published tables and adds the new ones, and the report folder (``--out``)
holds the merged tables it scored, so it is the next piece's ``PUBLISHED`` and re-scores alone
(``--report-only --root OUT --out OUT``, byte for byte). Ctrl-C or SIGTERM stops a piece after its
running job closes its run; the runs done so far still go to the tables of the root and ``--out``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time
from pathlib import Path

import pandas as pd

from higbench.cards import league_optimizers
from higbench.errors import MissingExtra
from higbench.jobs import LAUNCH_OVERRIDES, Job, as_launcher, job_seconds, resolve, run_index, run_missing
from higbench.jobs.ledger import FINAL_STATUSES
from higbench.league import tables
from higbench.league.files import ROOT_FILE_ERRORS, safe_dir, write_text
from higbench.league.protocol import (  # noqa: F401  (re-exported: the league's names, one import away)
    EVALUATIONS,
    EXTRA,
    LEAGUE_KEYS,
    RERUN_ROLE,
    SEARCHPATH_ENV,
    TUNE_ROLES,
    LeagueError,
    all_spaces,
    base_overrides,
    check_long,
    check_protocol,
    check_set,
    config_names,
    confirmation_jobs,
    extra_overrides,
    fail,
    has_paper_settings,
    has_validation,
    long_budget_jobs,
    long_budgets,
    parse_set,
    per_problem,
    problem_config,
    refusal,
    search_folders,
    searchpath_of_set,
    set_value,
    space_of,
    study_and_trial,
    target_seconds_of,
    tuning_jobs,
    use_searchpath,
    variant_overrides,
)
from higbench.league.report import (  # noqa: F401  (re-exported)
    PROTOCOL_KEYS,
    calibration,
    check_out,
    found_targets,
    hardware,
    machine,
    recorded_calibrations,
    report,
    scoring_targets,
    speed_change,
    write_report,
)
from higbench.results import league
from higbench.results.league import LONG_ROLES

DEFAULT_OPTIMIZERS = league_optimizers()  # every optimizer whose card (conf/optimizer/) says league: true
LAUNCHERS = ("basic", "joblib", "submitit_local", "submitit_slurm", "slurm")  # slurm: conf/hydra/launcher/slurm.yaml


class Earlier:
    """The runs of earlier leagues (``--root`` after the first: their tables, e.g. a published
    league's): reused like the root's own runs, read from the tables, never rerun."""

    runs, curves = pd.DataFrame(), pd.DataFrame()

    @classmethod
    def read(cls, roots: list[Path]) -> None:
        cls.runs, cls.curves = tables.read(roots) if roots else (pd.DataFrame(), pd.DataFrame())

    @classmethod
    def index(cls) -> dict:
        """identity -> run (``jobs.IndexedRun``) of every earlier run that is done."""
        from higbench.jobs import IndexedRun
        from higbench.results.index import DONE_STATUSES

        done = cls.runs[cls.runs["status"].isin(DONE_STATUSES)] if len(cls.runs) else cls.runs
        return {str(r["identity"]): IndexedRun(Path(r["path"]), str(r["status"]), float(r["train_time_s"] or 0.0))
                for _, r in done.iterrows()}  # fmt: skip

    @classmethod
    def of(cls, paths: list[str]) -> tuple[pd.DataFrame, pd.DataFrame]:
        if cls.runs.empty or not paths:
            return pd.DataFrame(), pd.DataFrame()
        runs = cls.runs[cls.runs["path"].isin(paths)]
        return runs, cls.curves[cls.curves["path"].isin(paths)].assign(path=lambda c: c["path"].astype(str))


def done_runs(jobs: list[Job]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(runs, curves) of the jobs that are done: from their run files (``load_runs``), or from the
    earlier leagues' tables (``Earlier``); each run with its ``task`` and its job's name as ``trial``."""
    from higbench.results.index import load_runs

    done = [j for j in jobs if j.path is not None]
    if not done:
        return pd.DataFrame(), pd.DataFrame()
    on_disk = [j.path for j in done if Path(j.path).is_file()]
    parts = [load_runs(on_disk, curves=True)] if on_disk else []
    parts.append(Earlier.of([str(j.path) for j in done if not Path(j.path).is_file()]))
    parts = [p for p in parts if len(p[0])]
    if not parts:
        return pd.DataFrame(), pd.DataFrame()
    runs = pd.concat([p[0] for p in parts], ignore_index=True)
    curves = pd.concat([p[1] for p in parts], ignore_index=True)
    by_path = {str(Path(j.path)): j for j in done}
    runs = runs.assign(trial=runs["path"].map(lambda p: by_path[str(Path(p))].sweep))
    return runs.assign(task=runs.assign(league_job=runs["trial"]).apply(league.task_label, axis=1)), curves


def choose(jobs: list[Job], target: float | None = None) -> tuple[dict | None, str]:
    """(the tuned setting, the rule it was chosen by): the overrides of the trial that reaches the
    validation ``target`` first (``league.choose_trial``; without a target, the lowest final
    validation loss), over every study's trials, read from its run files; None when no trial
    completed."""
    runs, curves = done_runs(jobs)
    if runs.empty:
        return None, "no trial completed"
    best, rule = league.choose_trial(runs, curves, target)
    if best is None:
        return None, rule
    job = next(j for j in jobs if j.path is not None and str(Path(j.path)) == str(Path(best["path"])))
    space = space_of(str(job.overrides["optimizer"]))
    return {k: v for k, v in job.overrides.items() if k in space}, rule


def set_targets(reruns: list[Job]) -> pd.DataFrame:
    """Per task, the validation target and budget the references' reruns give
    (``league.targets_from_reruns``); empty when they gave none."""
    runs, curves = done_runs(reruns)
    if runs.empty:
        return league.no_targets()
    return league.targets_from_reruns(runs, curves)


def league_budget(targets: pd.DataFrame, problem: str) -> float | None:
    """The league's budget per run from the target setting: the problem's own task's budget,
    rounded up to a whole second (None: no target was set)."""
    row = targets[targets["task"] == problem]
    return float(math.ceil(row["budget_s"].iloc[0])) if len(row) else None


# -- running ----------------------------------------------------------------------------------


class Runner:
    """Launches a phase's jobs on the chosen launcher (``jobs.run_missing``: every done run is
    reused) and keeps the league's count: runs done of all the protocol's, time left."""

    def __init__(self, root: Path, n_jobs: int, launcher: str, overrides: list[str], progress):
        self.root, self.n_jobs, self.launcher, self.overrides, self.progress = root, n_jobs, launcher, overrides, progress
        self.done = 0
        self.left_seconds = 0.0

    def run(self, jobs: list[Job], phase: str) -> None:
        """Stops the league when some are still not done (interrupted, failed): a setting chosen
        from part of a tuning, or a next problem started after a Ctrl-C, is not what was asked for."""
        safe_dir(self.root / "figures-runs", create=True)  # a planted link there would carry the runs out of the root
        left = run_missing(
            jobs,
            self.root,
            n_jobs=self.n_jobs,
            launcher=self.launcher,
            launcher_overrides=self.overrides,
            log=_log,
            progress=False,
            known=Earlier.index(),
        )  # fmt: skip  (the league counts its own whole)
        self.count(jobs, left)
        if left:
            final = [j for j in left if j.status in FINAL_STATUSES]
            failed = [j for j in left if j.status == "failed"]
            if final:
                hint = (f"{len(final)} refused for good ({final[0].reason or final[0].status}): the ledger under "
                        f"{self.root / 'ledger'} keeps them from running again; delete their records there to retry")  # fmt: skip
            elif failed:
                hint = f"{len(failed)} failed: see the launch.log under {self.root / 'figures-runs'}"
            else:
                hint = "the same command continues them, reusing every run already done"
            fail_stop(f"league: {len(left)} {phase} run(s) not done ({hint})")

    def forgo(self, jobs: list[Job]) -> None:
        """Takes planned runs that will not be made out of the count: the confirmation and long
        runs of an optimizer whose tuning chose no setting (every trial diverged)."""
        self.progress.total -= len(jobs)
        self.left_seconds -= sum(job_seconds(j) for j in jobs)

    def count(self, jobs: list[Job], left: list[Job]) -> None:
        self.done += len(jobs) - len(left)
        self.left_seconds -= sum(float(j.overrides.get("budget.seconds") or 0) for j in jobs)
        self.progress.update(self.done, max(0.0, self.left_seconds) / max(1, self.n_jobs))


def check_launcher(launcher: str, overrides: list[str]) -> None:
    """A launcher setting submitit has not (a typo in --launcher-set): one line before any run."""
    from higbench.jobs.arrays import LauncherError, submitit_parameters

    try:
        spec = as_launcher(launcher, overrides)
        if spec.array:
            submitit_parameters(spec.name, spec.settings())
    except LauncherError as exc:
        fail(str(exc))


def fail_stop(text: str):
    raise SystemExit(text)


def _log(text: str) -> None:
    for prefix in ("[jobs]", "[figures]"):  # the launcher's lines, as the league's
        text = text.replace(prefix, "[league]", 1)
    print(text, file=sys.stderr)


def launcher_overrides(items: list[str]) -> list[str]:
    """``--launcher-set partition=gpu`` -> ``hydra.launcher.partition=gpu``."""
    out = []
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            fail(f"--launcher-set {item}: expected KEY=VALUE (partition=gpu, timeout_min=60, array_parallelism=32)")
        out.append(f"{key if key.startswith('hydra.') else 'hydra.launcher.' + key}={value}")
    return out


# -- the command ------------------------------------------------------------------------------


def parse_args(argv=None) -> argparse.Namespace:
    doc = __doc__.split("\n\nPer-problem")[0]
    p = argparse.ArgumentParser(prog="higbench-league", description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--problems", default="toy,oscillator", help="comma-separated (default: toy,oscillator)")
    p.add_argument("--optimizers", default=",".join(DEFAULT_OPTIMIZERS),
                   help="comma-separated; each needs a search space, conf/search/<name>.yaml (default: all shipped)")  # fmt: skip
    p.add_argument("--paper", default="hig,gn,adam",
                   help="optimizers also run at their shipped settings: 'NAME (paper)' rows, or 'NAME (default)' where "
                   "higbench has no paper settings for the problem (default: hig,gn,adam)")  # fmt: skip
    p.add_argument("--references", default="adam,adamw",
                   help="the target setting's reference optimizers, tuned and rerun at each problem's target_seconds: "
                   "they set the validation target and the budget (default: adam,adamw; '': none, the budget is "
                   "league_seconds and tuning reads the final validation loss)")  # fmt: skip
    p.add_argument("--trials", default="16", help="Sobol trials per study and (problem, optimizer), the same for every "
                   "optimizer; '4,toy=16': 16 on the toy (default: 16)")  # fmt: skip
    studies = "tuning studies, each its own trial points and tuning seed (default: 2)"
    p.add_argument("--studies", type=int, default=2, help=studies)
    p.add_argument("--seeds", type=int, default=5, help="confirmation seeds 0..N-1 (never a tuning seed; default: 5, the "
                   "fewest at which an order-statistics interval for the median beats [min, max]'s 75%% coverage")  # fmt: skip
    p.add_argument("--seconds", help="training-clock budget per run (default: each problem's league_seconds); "
                   "'toy=10': the toy's")  # fmt: skip
    p.add_argument("--set", action="append", default=[], metavar="[SCOPE:]KEY=VALUE",
                   help="an override for every job, or for those of one problem or optimizer (SCOPE); repeatable")  # fmt: skip
    p.add_argument("--searchpath", action="append", default=[], type=Path, metavar="DIR",
                   help="a folder of your own configs (DIR/problem/, DIR/optimizer/, DIR/search/ for search spaces), as "
                   "hydra.searchpath=[file://DIR]; the problem's module goes on PYTHONPATH; repeatable")  # fmt: skip
    p.add_argument("--long", metavar="SECONDS", help="also train the --long-optimizers' tuned settings (and the shipped "
                   "ones of those in --paper) for this long, on the first --long-seeds seeds, after a problem's "
                   "confirmation: a table of its own; 'oscillator=600,dipole=600': per problem (default: none)")  # fmt: skip
    p.add_argument("--long-optimizers", default="soap,muon,lm,adam,hig",
                   help="the optimizers of the long budget (default: soap,muon,lm,adam,hig)")  # fmt: skip
    p.add_argument("--long-seeds", type=int, default=3, help="seeds of the long budget (default: 3)")
    p.add_argument("--variants", type=int, default=None, help="at most this many held-out variants per problem (default: all)")
    p.add_argument("--root", type=Path, action="append", default=None,
                   help="where the runs and their tables go (and are reused from); default outputs/league in the "
                   "current folder; repeat: the first gets the new runs, the others are earlier leagues' tables "
                   "(a published league), whose done runs are reused, never rerun; with --report-only, merged")  # fmt: skip
    p.add_argument("--out", type=Path, default=None, help="league.txt, league.json, runs.csv, figures (default: ROOT/report)")
    p.add_argument("--jobs", type=int, default=1, help="runs at once on this machine (1: the budgets are not shared)")
    p.add_argument("--launcher", choices=LAUNCHERS, default=None,
                   help="Hydra launcher of the runs (default: basic with --jobs 1, else joblib); submitit_slurm submits each "
                   "phase as one job array")  # fmt: skip
    p.add_argument("--launcher-set", action="append", default=[], metavar="KEY=VALUE",
                   help="a hydra.launcher.KEY override: partition=gpu, timeout_min=60, gpus_per_node=1, "
                   "array_parallelism=32; repeatable")  # fmt: skip
    p.add_argument(
        "--targets-only",
        action="store_true",
        help="run the target setting only (the references' tuning and reruns): a league's first piece",
    )
    p.add_argument("--plan", action="store_true", help="print the runs, training hours and hardware per task; run nothing")
    only = "train nothing; score the tables under --root (no run files needed)"
    p.add_argument("--report-only", action="store_true", help=only)
    return p.parse_args(argv)


def references_of(args) -> list[str]:
    return [r for r in args.references.split(",") if r]


def protocol_of(args, root: Path, problems, optimizers, paper, trials, budgets, nodes) -> dict:
    """What makes a league this league (kept in league.json; ``check_out`` compares it)."""
    per = {}
    for problem in problems:
        if args.targets_only:  # what sets the targets; the league's own keys are the next piece's
            per[problem] = {"references": references_of(args), "target_seconds": target_seconds_of(problem, nodes[problem]),
                            "trials": trials.get(problem, trials.get(None)), "studies": args.studies}  # fmt: skip
            continue
        per[problem] = {
            "optimizers": optimizers, "paper": paper, "trials": trials.get(problem, trials.get(None)),
            "studies": args.studies, "seeds": args.seeds, "seconds": seconds_of(problem, budgets, nodes[problem]),
            "references": references_of(args), "target_seconds": target_seconds_of(problem, nodes[problem]),
            "set": {o: extra_overrides(problem, o) for o in optimizers},
        }  # fmt: skip
    return {"root": shown_path(root), "problems": per}


def run_path(path: Path, root: Path) -> str:
    """A run's path in the manifest: relative to the root it is in (an earlier league's: as shown)."""
    resolved = Path(path).resolve()
    return str(resolved.relative_to(root.resolve())) if resolved.is_relative_to(root.resolve()) else shown_path(Path(path))


def shown_path(path: Path) -> str:
    """A path as the report records it: relative to the current folder when inside it (a
    published report names no folder of the machine it ran on), else absolute."""
    resolved, here = path.resolve(), Path.cwd().resolve()
    return resolved.relative_to(here).as_posix() if resolved.is_relative_to(here) else str(resolved)


def seconds_of(problem: str, budgets: dict, node: dict) -> float | None:
    return budgets.get(problem, budgets.get(None)) or node.get("league_seconds")


def span(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min" if seconds < 7200 else f"{seconds / 3600:.1f} h"


def plan_text(planned: list[tuple[str, list[Job]]], n_jobs: int) -> str:
    """Runs, training hours and hardware per task, before anything runs."""
    lines, total_runs, total_s = [], 0, 0.0
    for problem, jobs in planned:
        seconds = sum(job_seconds(j) for j in jobs)
        devices = sorted({str(j.overrides.get("device", "cpu")) for j in jobs})
        launched = dict(o.split("=", 1) for o in LAUNCH_OVERRIDES)  # what every launched run gets unless --set says otherwise
        threads = sorted({str(j.overrides.get("threads", launched["threads"])) for j in jobs})
        tune = sum(j.sweep.startswith("tune/") for j in jobs)
        setting = sum(j.sweep.startswith(("target-tune/", f"{RERUN_ROLE}/")) for j in jobs)
        long = [j for j in jobs if j.sweep.split("/")[0] in LONG_ROLES]
        long_text = f", {len(long)} at the long budget ({span(sum(map(job_seconds, long)))})" if long else ""
        lines.append(f"[league] plan: {problem}: {len(jobs)} runs ({setting} target setting, {tune} tuning, "
                     f"{len(jobs) - tune - setting - len(long)} confirmation{long_text}), {span(seconds)} of training, hardware "
                     f"{'/'.join(devices)} threads={'/'.join(threads)}")  # fmt: skip
        total_runs += len(jobs)
        total_s += seconds
    lines.append(f"[league] plan: {total_runs} runs, {span(total_s)} of training (budgets x runs), about "
                 f"{span(total_s / max(1, n_jobs))} wall clock at --jobs {n_jobs} "
                 "(evaluations and start-up come on top; the league's runs counted at league_seconds or --seconds "
                 "until the target setting sets their budget)")  # fmt: skip
    return "\n".join(lines)


def main(argv=None) -> int:
    previous = signal.signal(signal.SIGTERM, stop_on_sigterm)
    try:
        return _main(argv)
    except KeyboardInterrupt as exc:  # its line is printed: what was kept, and how to continue
        return 128 + int(signal.SIGTERM if str(exc) == "SIGTERM" else signal.SIGINT)
    except LeagueError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    except ROOT_FILE_ERRORS as exc:
        print(f"league: error: {exc}", file=sys.stderr)
        return 2
    finally:
        signal.signal(signal.SIGTERM, previous)


def stop_on_sigterm(signum, frame):
    """A scheduler's SIGTERM stops the league as Ctrl-C does: the runs done so far go to the tables."""
    raise KeyboardInterrupt("SIGTERM")


def _main(argv=None) -> int:
    args = parse_args(argv)
    roots = args.root or [Path("outputs") / "league"]
    root = roots[0]
    out = args.out or root / "report"
    set_items, set_folders = searchpath_of_set(args.set)
    use_searchpath([*args.searchpath, *set_folders])
    problems = [p for p in args.problems.split(",") if p]
    optimizers = [o for o in args.optimizers.split(",") if o]
    paper = [o for o in args.paper.split(",") if o in optimizers]
    trials = per_problem(args.trials, "--trials", int)
    budgets = per_problem(args.seconds, "--seconds")
    longs = long_budgets(args)
    EXTRA[:] = [parse_set(item) for item in set_items]
    overrides = launcher_overrides(args.launcher_set)
    launcher = args.launcher or ("basic" if args.jobs == 1 else "joblib")
    check_launcher(launcher, overrides)
    for flag, value in (
        ("--studies", args.studies),
        ("--seeds", args.seeds),
        ("--jobs", args.jobs),
        ("--long-seeds", args.long_seeds),
    ):
        if value < 1:
            fail(f"{flag} {value}: must be at least 1")
    check_protocol(trials, budgets, problems, optimizers)
    check_long(args, longs, optimizers, problems)
    seeds = list(range(args.seeds))
    tuning_seeds = [league.tuning_seed(s) for s in range(args.studies)]
    if set(seeds) & set(tuning_seeds):
        fail(f"--seeds {args.seeds}: overlaps the tuning seeds {tuning_seeds}")
    for o in dict.fromkeys([*optimizers, *references_of(args)]):
        try:
            space_of(o)  # a missing or bad search space stops the league before any run
        except ValueError as exc:
            fail(str(exc))
    if args.report_only and not any(safe_dir(r / tables.TABLES_DIR) or safe_dir(r / "figures-runs") for r in roots):
        fail(f"--root {' '.join(map(str, roots))}: no league runs or tables there")
    nodes = {}
    for problem in problems:
        nodes[problem] = problem_config(problem)
        if not trials.get(problem, trials.get(None)):
            fail(f"--trials {args.trials}: no count for problem={problem}")
        if not seconds_of(problem, budgets, nodes[problem]):
            fail(f"problem={problem}: no problem.league_seconds; give --seconds")
        if not has_validation(problem, nodes[problem]):
            fail(f"problem={problem}: no validation set (problem.val_size is 0), and tuning reads the validation loss; "
                 f"give one in its YAML or --set {problem}:++problem.val_size=256")  # fmt: skip
        if not args.report_only:
            check_set(problem, optimizers)
    protocol = protocol_of(args, root, problems, optimizers, paper, trials, budgets, nodes)
    try:  # re-scoring needs no optimizer's package; training without one would drop it from the tables
        refused = {p: {o: why for o in optimizers if (why := refusal(p, o, with_set=False, extras=args.report_only))}
                   for p in problems}  # fmt: skip
    except MissingExtra as exc:
        fail(f"{exc} (or leave {exc.value} out of --optimizers)")
    if args.plan:
        planned = []
        Earlier.read([r for r in roots[1:] if safe_dir(r / tables.TABLES_DIR)])
        derived = scoring_targets(Earlier.runs, Earlier.curves)[1] if len(Earlier.runs) else {}
        for problem in problems:
            node, usable = nodes[problem], [o for o in optimizers if o not in refused[problem]]
            seconds, n = seconds_of(problem, budgets, node), trials.get(problem, trials.get(None))
            if problem not in budgets and None not in budgets and problem in derived:  # an earlier target setting's
                seconds = float(math.ceil(derived[problem]))
            variants = list(node.get("held_out") or [])[: args.variants]
            planned.append((problem, planned_jobs(args, problem, (seconds, n, variants, usable), paper, seeds, node)))
        print(plan_text(planned, args.jobs))
        return 0
    check_out(out, root, protocol, in_place=out.resolve() in [r.resolve() for r in roots])
    for folder in (root, root / "manifests", root / "figures-runs", root / "ledger") if not args.report_only else ():
        safe_dir(folder, create=True)  # a planted link: refused before work
    return run_league(args, roots, out, problems, optimizers, paper, trials, budgets, nodes, refused, seeds, tuning_seeds,
                      launcher, overrides, protocol, argv)  # fmt: skip


def rerun_seeds(seeds: list[int]) -> list[int]:
    """The target setting's reruns: the first ``MIN_TARGET_RERUNS`` confirmation seeds, whatever
    --seeds a piece uses, so that a problem's targets do not move with its seed count."""
    return list(seeds)[: league.MIN_TARGET_RERUNS]


def planned_target_jobs(problem, reference, n, studies, seeds, variants, node) -> list[Job]:
    """The target-setting jobs of one reference, as the plan counts them (its setting not yet known)."""
    seconds = target_seconds_of(problem, node)
    if not seconds:
        return []
    return [*tuning_jobs(problem, reference, n, seconds, studies, role="target-tune"),
            *confirmation_jobs(problem, reference, {}, rerun_seeds(seeds), seconds, variants, role=RERUN_ROLE)]  # fmt: skip


def target_setting(problem, references, n, studies, seeds, variants, node, phase) -> pd.DataFrame:
    """The references tuned and rerun at the problem's target-setting budget (``phase`` runs or
    finds them, and records them): targets per task from ``set_targets``."""
    seconds = target_seconds_of(problem, node)
    if not references or not seconds:
        return league.no_targets()
    tune = {r: tuning_jobs(problem, r, n, seconds, studies, role="target-tune") for r in references}
    flat = [j for jobs in tune.values() for j in jobs]
    phase([("target-tune", j) for j in flat], f"{problem} target-setting tuning")
    chosen = {r: choose(jobs)[0] for r, jobs in tune.items()}
    first = rerun_seeds(seeds)
    reruns = [j for r in references if chosen[r] is not None
              for j in confirmation_jobs(problem, r, chosen[r], first, seconds, variants, role=RERUN_ROLE)]  # fmt: skip
    phase([(RERUN_ROLE, j) for j in reruns], f"{problem} target-setting reruns")
    targets = set_targets(reruns)
    for _, row in targets.iterrows():
        print(f"[league] {row['task']}: validation target {row['target']:.3g} ({row['reference']}, median of "
              f"{row['reruns']} reruns at {seconds:g} s), budget {row['budget_s']:.3g} s", file=sys.stderr)  # fmt: skip
    return targets


def run_league(args, roots, out, problems, optimizers, paper, trials, budgets, nodes, refused, seeds, tuning_seeds,
               launcher, overrides, protocol, argv) -> int:  # fmt: skip
    from higbench.runner.progress import CountProgress

    root = roots[0]
    Earlier.read([] if args.report_only else [r for r in roots[1:] if safe_dir(r / tables.TABLES_DIR)])
    reading_runs = not args.report_only or (len(roots) == 1 and safe_dir(root / "figures-runs") is not None)
    manifest: dict = {"command": " ".join(["higbench-league", *(argv if argv is not None else sys.argv[1:])]),
                      "protocol": protocol, "searchpath": [str(f) for f in search_folders()],
                      "tuning_seeds": tuning_seeds, "confirmation_seeds": seeds, "evaluations_per_run": EVALUATIONS,
                      "problems": {}, "calibration": [] if args.report_only else [calibration()]}  # fmt: skip
    if not args.report_only and (change := speed_change(manifest["calibration"][0], recorded_calibrations(roots, out))):
        print(f"[league] {change}", file=sys.stderr)
    quiet = any(scope is None and key == "progress" and str(value).lower() == "false" for scope, key, value in EXTRA)
    all_jobs: list[tuple[str, Job]] = []
    plans = {}
    for problem in problems:
        node = nodes[problem]
        seconds, n = seconds_of(problem, budgets, node), trials.get(problem, trials.get(None))
        variants = list(node.get("held_out") or [])[: args.variants]
        usable = [o for o in optimizers if o not in refused[problem]]
        for o, why in refused[problem].items():
            print(f"[league] {problem}: {o} left out: {why}", file=sys.stderr)
        plans[problem] = (seconds, n, variants, usable)
    total, runner_seconds = protocol_size(args, plans, problems if reading_runs else [], paper, seeds, nodes)
    progress = CountProgress(not quiet and not args.report_only, "league", total)
    runner = Runner(root, args.jobs, launcher, overrides, progress)
    runner.left_seconds = runner_seconds
    progress.update(0, runner.left_seconds / args.jobs)

    def phase(role_jobs: list[tuple[str, Job]], name: str) -> None:
        """Runs (or, --report-only, finds) a phase's jobs, recorded first: a phase that stops
        (Ctrl-C, SIGTERM, a failed run) still hands the runs it finished to the tables."""
        all_jobs.extend(role_jobs)
        jobs = [j for _, j in role_jobs]
        if args.report_only:
            resolve(jobs, run_index(root))
        else:
            runner.run(jobs, name)

    stopped: BaseException | None = None
    try:
        for problem in problems if reading_runs else []:
            entry = manifest["problems"][problem] = {}  # filled as the phases go: a stopped sitting keeps what it found
            league_problem(args, problem, plans[problem], budgets, nodes[problem], paper, refused[problem], seeds, phase,
                           entry, runner.forgo)  # fmt: skip
    except (KeyboardInterrupt, SystemExit) as exc:  # SIGINT, SIGTERM (``stop_on_sigterm``), a phase not done
        stopped = exc
        manifest["stopped"] = str(exc) or type(exc).__name__
        if not args.report_only:  # the runs that finished while the phase was stopped
            resolve([j for _, j in all_jobs], {**Earlier.index(), **run_index(root)})
    finally:
        progress.close()
    publish(args, roots, out, manifest, all_jobs, tuning_seeds)
    if stopped is not None:
        done = sum(j.done for _, j in all_jobs)
        print(f"[league] stopped ({manifest['stopped']}): the {done} run(s) done so far are in the tables of {root} "
              f"and {out}; the same command continues, reusing them", file=sys.stderr)  # fmt: skip
        raise stopped
    return 0


def protocol_size(args, plans: dict, setting_problems: list[str], paper, seeds, nodes) -> tuple[int, float]:
    """(runs, training seconds) the progress line counts: ``planned_jobs`` of every problem, the
    target setting only of the problems it reads."""
    jobs = [j for p in plans for j in planned_jobs(args, p, plans[p], paper, seeds, nodes[p], setting=p in setting_problems)]
    return len(jobs), sum(job_seconds(j) for j in jobs)


def planned_jobs(args, problem: str, plan, paper, seeds, node: dict, setting: bool = True) -> list[Job]:
    """Every job of a problem's protocol, as --plan and the progress line count them (each tuned
    setting assumed found, written {}): the target setting (``setting``), tuning, confirmation,
    the shipped settings and the long budget."""
    seconds, n, variants, usable = plan
    refs = references_of(args) if setting else []
    jobs = [j for r in refs for j in planned_target_jobs(problem, r, n, args.studies, seeds, variants, node)]
    if args.targets_only:
        return jobs
    jobs += [j for o in usable for j in tuning_jobs(problem, o, n, seconds, args.studies)]
    jobs += [j for o in usable for j in confirmation_jobs(problem, o, {}, seeds, seconds, variants)]
    jobs += [j for o in paper if o in usable for j in confirmation_jobs(problem, o, None, seeds, seconds, variants)]
    return jobs + long_budget_jobs(args, long_budgets(args), problem, usable, paper, {o: {} for o in usable}, seeds)


def league_problem(args, problem: str, plan, budgets: dict, node: dict, paper, refused: dict, seeds, phase, entry: dict,
                   forgo=lambda jobs: None) -> None:  # fmt: skip
    """One problem's phases (``phase`` runs each): target setting, tuning, confirmation, the long
    budget. Fills its manifest ``entry`` as each phase ends (the chosen settings before their
    confirmation runs), so a sitting stopped in confirmation records what tuning chose. ``forgo``
    hears of the planned runs of an optimizer whose tuning chose nothing (the progress count)."""
    seconds, n, variants, usable = plan
    references, longs = references_of(args), long_budgets(args)
    given = problem in budgets or None in budgets  # --seconds: the user's budget, not the target setting's
    targets = target_setting(problem, references, n, args.studies, seeds, variants, node, phase)
    entry.update({"target_setting": targets.to_dict("records"), "references": references})
    if args.targets_only:
        return
    derived = league_budget(targets, problem)
    seconds = seconds if given or derived is None else derived
    if references and derived is None:
        print(f"[league] {problem}: the target setting gave no validation target; budget {seconds:g} s "
              "(--seconds or problem.league_seconds), tuning by the final validation loss", file=sys.stderr)  # fmt: skip
    target = targets.set_index("task")["target"].get(problem) if len(targets) else None
    tune = {o: tuning_jobs(problem, o, n, seconds, args.studies) for o in usable}
    flat = [j for jobs in tune.values() for j in jobs]
    phase([("tune", j) for j in flat], f"{problem} tuning")
    picks = {o: choose(jobs, target) for o, jobs in tune.items()}
    chosen = {o: pick[0] for o, pick in picks.items()}
    entry.update({"seconds": seconds, "budget_from": "--seconds" if given or derived is None else "target setting",
                  "trials": n, "studies": args.studies, "targets": node.get("targets"), "held_out": variants,
                  "set": {o: extra_overrides(problem, o) for o in usable}, "chosen": chosen,
                  "chosen_by": {o: pick[1] for o, pick in picks.items()}, "left_out": refused, "long": None})  # fmt: skip
    confirm = [j for o in usable if chosen[o] is not None
               for j in confirmation_jobs(problem, o, chosen[o], seeds, seconds, variants)]  # fmt: skip
    unset = {o: {} for o in usable if chosen[o] is None}
    forgo([j for o in unset for j in confirmation_jobs(problem, o, {}, seeds, seconds, variants)]
          + long_budget_jobs(args, longs, problem, list(unset), [], unset, seeds))  # fmt: skip
    confirm += [j for o in paper if o in usable for j in confirmation_jobs(problem, o, None, seeds, seconds, variants)]
    phase([(j.sweep.split("/")[0], j) for j in confirm], f"{problem} confirmation")
    long = long_budget_jobs(args, longs, problem, usable, paper, chosen, seeds)
    if long:
        entry["long"] = {"seconds": longs.get(problem, longs.get(None)), "seeds": args.long_seeds,
                         "optimizers": sorted({j.overrides["optimizer"] for j in long})}  # fmt: skip
        phase([(j.sweep.split("/")[0], j) for j in long], f"{problem} long budget")


def publish(args, roots: list[Path], out: Path, manifest: dict, all_jobs: list[tuple[str, Job]], tuning_seeds) -> None:
    """The manifest (beside the runs and with the tables), the root's tables, the report folder's
    merged tables and the report; a line naming the runs not done."""
    root = roots[0]
    if not args.report_only:
        manifest["calibration"].append(calibration())
    manifest["runs"] = [{"role": role, "job": j.sweep, "study": study_and_trial(j)[0], "trial": study_and_trial(j)[1],
                         "seed": j.seed, "identity": j.identity, "status": j.status,
                         "path": run_path(j.path, root) if j.path else None}
                        for role, j in all_jobs]  # fmt: skip
    if not args.report_only:  # kept beside the runs: a later --report-only, anywhere, reads it back
        stamp = time.strftime("%Y-%m-%dT%H-%M-%S") + f"-{os.getpid()}"
        text = json.dumps(manifest, indent=1, default=str) + "\n"
        write_text(safe_dir(root / "manifests", create=True) / f"{stamp}.json", text)
        write_text(safe_dir(safe_dir(out, create=True) / "manifests", create=True) / f"{stamp}.json", text)  # with the tables
    if safe_dir(root / "figures-runs"):
        tables.export(root, {e["identity"]: e for e in manifest["runs"] if e["identity"]})
    scored = [r for r in roots if safe_dir(r / tables.TABLES_DIR)]
    if scored and [r.resolve() for r in scored] != [out.resolve()]:  # the report folder holds what it scored:
        tables.write_merged(out, scored)  # --report-only --root OUT re-scores it alone, byte for byte
    print(report([out] if scored else roots, out, manifest, tuning_seeds))
    missing = [j for _, j in all_jobs if not j.done]
    if missing:
        print(f"[league] {len(missing)} run(s) not done: {', '.join(sorted({j.sweep for j in missing}))}", file=sys.stderr)
