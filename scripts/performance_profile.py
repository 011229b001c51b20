"""The performance profile over the paper's problems: six optimizer settings, three seeds each.

Per problem, every setting trains for the same training-clock budget (the problem's
``problem.league_seconds``), three seeds, paper settings otherwise (conf/problem_optimizer/).
Adam enters twice: at the paper's learning rate (its conf/problem_optimizer/<problem>_adam.yaml)
and re-tuned, i.e. the best of ``ADAM_GRID`` (multiples of the paper's rate) by seed 0's final
test loss at the same budget. The (problem, target) pairs are the problems' ``problem.targets``.
Then, per pair, each setting's time to the target is the median over its seeds (unsolved when
fewer than half reach it), and rho(tau) is the fraction of pairs a setting solves within tau
times the fastest (higbench.results.profile; AlgoPerf's scoring uses the same profile).

    python scripts/performance_profile.py                      # train (~45 min on 2 cores), then report
    python scripts/performance_profile.py --report-only        # re-read outputs/profile, train nothing
    python scripts/performance_profile.py --problems toy --seeds 0 --out outputs/profile-look   # a small look

Runs go through ``higbench.jobs.run_missing`` per stage (one job-list multirun, joblib
launcher, ``--jobs`` at once, one thread each) under ``outputs/profile/``; a run already there
with the same identity (resolved config) is reused, never overwritten. Writes ``profile.png``, ``profile.md`` (tables)
and ``profile.json`` (one row per run, the targets and the settings) to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from functools import cache
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from higbench.cards import problem_configs  # noqa: E402
from higbench.display import md_table, optimizer_name  # noqa: E402
from higbench.jobs import Job, composed_value, run_missing  # noqa: E402
from higbench.results.targets import for_problem, league_seconds  # noqa: E402

PROBLEMS = ("toy", "oscillator", "dipole", "poisson")  # the paper's problems; --problems takes any shipped one
ADAM_GRID = (0.1, 3.0, 10.0)  # re-tuning: these multiples of the paper's rate, besides the rate itself
FIXED = ("hig", "gn", "lbfgs", "lm")  # at their shipped settings (the paper's, where the paper has them)
SEEDS = (0, 1, 2)
EVALUATIONS = 30  # per run: the time-to-target resolution is the budget / 30


def budget_s(problem: str) -> float:
    """A run's training-clock budget: the problem's league budget (``problem.league_seconds``)."""
    return league_seconds(problem)


@cache
def paper_lr(problem: str, optimizer: str = "adam") -> float:
    """The learning rate ``higbench problem=P optimizer=O`` runs at (conf/problem_optimizer/)."""
    return float(composed_value("optimizer.lr", f"problem={problem}", f"optimizer={optimizer}"))


def job(problem: str, optimizer: str, seed: int, lr: float | None = None) -> Job:
    budget = budget_s(problem)
    overrides = {"problem": problem, "optimizer": optimizer, "seed": seed, "budget.seconds": budget,
                 "eval_every": float(f"{budget / EVALUATIONS:g}")}  # fmt: skip
    if lr is not None:
        overrides["optimizer.lr"] = lr
    return Job("profile", f"{problem}/{optimizer}", overrides, seed)


def adam_lrs(problem: str) -> list[float]:
    paper = paper_lr(problem)
    return [paper, *(float(f"{paper * m:.3g}") for m in ADAM_GRID)]


def first_stage(problems, seeds) -> list[Job]:
    """Every run that does not depend on the tuning: the fixed settings, Adam's grid at seed 0,
    and the paper-rate Adam at the other seeds."""
    jobs = []
    for p in problems:
        jobs += [job(p, opt, s) for opt in FIXED for s in seeds]
        jobs += [job(p, "adam", seeds[0], lr) for lr in adam_lrs(p)]
        jobs += [job(p, "adam", s, paper_lr(p)) for s in seeds[1:]]
    return jobs


def tuned_lr(runs: pd.DataFrame, problem: str, seed: int) -> float:
    """The grid's rate with the lowest final test loss at ``seed`` (a diverged run counts as inf)."""
    grid = runs[(runs["problem.name"] == problem) & (runs["optimizer.name"] == "adam") & (runs["seed"] == seed)]
    loss = grid["final_test_loss"].where(grid["status"] == "completed", math.inf).fillna(math.inf)
    if grid.empty:
        raise RuntimeError(f"no Adam grid runs of {problem} at seed {seed} to tune from")
    return float(grid.loc[loss.idxmin(), "optimizer.lr"])


def launch(jobs: list[Job], stage: str, n_jobs: int, root: Path) -> None:
    """Run the jobs not done under ``root`` (the one reuse rule: ``higbench.jobs.run_missing``)."""
    print(f"{stage}: {len(jobs)} runs", file=sys.stderr)
    for j in run_missing(jobs, root, n_jobs=n_jobs, log=lambda text: print(text, file=sys.stderr)):
        print(f"{stage}: {j.sweep} seed {j.seed}: not done ({j.status})", file=sys.stderr)


def label_settings(runs: pd.DataFrame, tuned: dict[str, float]) -> pd.Series:
    """HIG / GN / L-BFGS / Levenberg-Marquardt (display names) / Adam (paper η) / Adam (re-tuned η);
    other grid points: None."""

    def one(row: pd.Series) -> str | None:
        opt, problem = row["optimizer.name"], row["problem.name"]
        if opt != "adam":
            return optimizer_name(opt) if opt in FIXED else None
        lr = float(row["optimizer.lr"])
        if math.isclose(lr, tuned[problem], rel_tol=1e-6):
            return "Adam (re-tuned η)"  # also the paper's rate when that one won: the row says so
        return "Adam (paper η)" if math.isclose(lr, paper_lr(problem), rel_tol=1e-6) else None

    return runs.apply(one, axis=1)


def expand_paper_adam(runs: pd.DataFrame, tuned: dict[str, float]) -> pd.DataFrame:
    """Where re-tuning kept the paper's rate, the same runs also stand as 'Adam (paper η)'."""
    same = [p for p, lr in tuned.items() if math.isclose(lr, paper_lr(p), rel_tol=1e-6)]
    twins = runs[(runs["setting"] == "Adam (re-tuned η)") & runs["problem.name"].isin(same)]
    return pd.concat([runs, twins.assign(setting="Adam (paper η)")], ignore_index=True)


def made(runs: pd.DataFrame) -> str:
    """When, where and how the runs were made, from their run files."""
    revisions = ", ".join(sorted(set(runs["env.git_revision"].dropna().astype(str).str[:7])))
    threads = "/".join(map(str, sorted(set(runs["env.torch_threads"].dropna().astype(int)))))
    return (f"Runs trained {runs['started'].min()} to {runs['finished'].max()} on {runs['env.cpu_count'].max()} CPU "
            f"cores, {threads} thread(s) per run, revision {revisions}")  # fmt: skip


def rho_table(df: pd.DataFrame) -> str:
    rows = [[str(i), *(f"{v:.2f}" for v in r)] for i, r in zip(df.index, df.to_numpy())]
    return "\n".join(md_table(["setting", *map(str, df.columns)], rows))


def report(root: Path, out: Path, problems, seeds) -> None:
    from higbench.results.index import load_runs
    from higbench.results.plot import plot_profile, profile_taus
    from higbench.results.profile import all_targets, format_table, performance_profile, time_to_target

    targets = {p: list(for_problem(p)) for p in problems}
    runs = load_runs(root, thresholds=all_targets(targets))
    runs = runs[runs["problem.name"].isin(problems) & runs["seed"].isin(seeds)]
    tuned = {p: tuned_lr(runs, p, seeds[0]) for p in problems}
    runs = expand_paper_adam(runs.assign(setting=label_settings(runs, tuned)).dropna(subset=["setting"]), tuned)
    times = time_to_target(runs, targets)
    taus = profile_taus(times)
    rho = performance_profile(times, taus)
    pairs = len(times[["problem", "target"]].drop_duplicates())
    out.mkdir(parents=True, exist_ok=True)
    plot_profile(rho, out / "profile.png", pairs)
    at = performance_profile(times, [1.0, 2.0, 4.0, 10.0])
    load = os.getloadavg()
    lines = [
        f"Performance profile over {pairs} (problem, target) pairs, {len(runs)} runs "
        f"({', '.join(f'{p} {budget_s(p):g} s' for p in problems)} of training clock per run; seeds {list(seeds)}; "
        f"re-tuned Adam η: {', '.join(f'{p} {tuned[p]:g}' for p in problems)}). {made(runs)}; report made "
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load {load[0]:.1f}.",
        "",
        "rho(tau): fraction of pairs solved within tau times the fastest setting's time",
        "",
        rho_table(at.T.rename(columns=lambda t: f"tau={t:g}")),
        "",
        "Time to target (training clock, median over seeds; '-' unsolved: fewer than half the seeds reached it)",
        "",
        format_table(times),
    ]
    (out / "profile.md").write_text("\n".join(lines) + "\n")
    keep = ["problem.name", "setting", "seed", "optimizer.lr", "batch_size", "status", "steps", "train_time_s",
            "final_test_loss", "best_test_loss"]  # fmt: skip
    cols = [c for c in runs.columns if c.startswith("time_to_")]
    data = {"targets": targets, "budget_s": {p: budget_s(p) for p in problems}, "tuned_adam_lr": tuned,
            "rho": at.to_dict(), "runs": json.loads(runs[keep + cols].to_json(orient="records"))}  # fmt: skip
    (out / "profile.json").write_text(json.dumps(data, indent=1) + "\n")
    print("\n".join(lines))
    print(f"wrote {out / 'profile.png'}, profile.md, profile.json", file=sys.stderr)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description="Performance profile over the paper's problems (see docstring).")
    parser.add_argument("--problems", nargs="+", default=list(PROBLEMS), choices=problem_configs())
    parser.add_argument("--seeds", nargs="+", type=int, default=list(SEEDS))
    parser.add_argument("--jobs", type=int, default=2, help="runs at once, one thread each (default 2)")
    parser.add_argument("--root", type=Path, default=ROOT / "outputs" / "profile", help="where the runs go")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "profile")
    parser.add_argument("--report-only", action="store_true", help="read the runs under --root, train nothing")
    args = parser.parse_args(argv)
    if args.report_only and not args.root.is_dir():
        parser.error(f"--root {args.root}: no runs there to report on (train them first: python scripts/performance_profile.py)")
    problems, seeds = tuple(args.problems), tuple(args.seeds)
    if not args.report_only:
        launch(first_stage(problems, seeds), "fixed", args.jobs, args.root)
        from higbench.results.index import load_runs

        runs = load_runs(args.root)
        tuned = {p: tuned_lr(runs, p, seeds[0]) for p in problems}
        print(f"re-tuned Adam: {tuned}", file=sys.stderr)
        launch([job(p, "adam", s, tuned[p]) for p in problems for s in seeds[1:]], "tuned", args.jobs, args.root)
    report(args.root, args.out, problems, seeds)


if __name__ == "__main__":
    main()
