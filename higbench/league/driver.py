"""The league: tune every optimizer the same way, confirm on fresh seeds and held-out variants, score.

    higbench-league --problems toy,oscillator --seconds 5 --trials 4      # a small league
    higbench-league --report-only --out docs/results/league               # re-read, train nothing
    higbench-league --problems poisson --set poisson/hig:device=cuda   # HIG on a GPU

Per-problem protocol: ``--trials 4,toy=16`` (4 trials, 16 on the toy) and likewise ``--seconds``;
``--set [SCOPE:]KEY=VALUE`` adds an override to every job (no SCOPE), or to those of a problem,
an optimizer or a ``problem/optimizer`` (SCOPE). The same flags re-read the runs with ``--report-only``.

Per problem (its config owns the budget ``problem.league_seconds``, the targets
``problem.targets`` and the held-out variants ``problem.held_out``; ``--seconds`` replaces the
budget for a short league):

1. tuning: ``--trials`` scrambled Sobol points of each optimizer's search space
   (conf/search/<optimizer>.yaml) on the tuning seed; the best by *validation* loss at the budget
   is the optimizer's setting (``choose``);
2. confirmation: that setting on ``--seeds`` fresh seeds, on the problem and on each held-out
   variant (never tuned on); the ``--paper`` optimizers also at their shipped settings
   (conf/problem_optimizer/: the paper's), as separate rows;
3. scores: ``higbench-results ROOT --league`` (test loss, read once here), written to
   ``--out`` with the manifest: every run's identity and role, the chosen settings, the
   hardware calibration and the machine's load.

Every run is an ordinary higbench run launched through ``higbench.jobs.launch`` into ``--root``;
a run already there (same identity) is reused, so a killed league resumes and a new optimizer adds
only its own runs.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import time
from pathlib import Path

import pandas as pd

from higbench.jobs import Job, resolve, run_index, run_missing
from higbench.results import league

ROOT = Path(__file__).resolve().parents[2]

EVALUATIONS = 25  # per run: the time-to-target resolution is budget / 25
DEFAULT_OPTIMIZERS = ("adam", "sgd", "rmsprop", "adagrad", "adadelta", "lbfgs", "lm", "gn", "hig",
                      "adamw", "muon", "soap", "shampoo", "sip")  # fmt: skip


def problem_config(problem: str) -> dict:
    """The composed problem node (targets, budget, variants) of ``problem``."""
    from higbench.jobs import compose, hydra_conf

    with hydra_conf():
        return compose((f"problem={problem}",))["problem"]


LEAGUE_KEYS = {"problem", "optimizer", "seed", "budget.seconds", "eval_every"}
EXTRA: list[tuple[str | None, str, str]] = []  # (scope, key, value) of --set; set by main


def extra_overrides(problem: str, optimizer: str) -> dict[str, str]:
    """The --set overrides for one (problem, optimizer): unscoped ones, and those scoped to the
    problem, the optimizer or ``problem/optimizer``; the narrower scope wins a key."""
    ranks = {None: 0, problem: 1, optimizer: 1, f"{problem}/{optimizer}": 2}
    chosen = sorted((ranks[scope], key, value) for scope, key, value in EXTRA if scope in ranks)
    return {key: value for _, key, value in chosen}


def base_overrides(problem: str, optimizer: str, seed: int, seconds: float) -> dict:
    extra = extra_overrides(problem, optimizer)
    return {"problem": problem, "optimizer": optimizer, "seed": seed, "budget.seconds": seconds,
            "eval_every": float(f"{seconds / EVALUATIONS:.3g}"), **extra}  # fmt: skip


def per_problem(text: str | None, flag: str, cast=float) -> dict[str | None, float]:
    """``'4,toy=16'`` -> {None: 4, 'toy': 16}: a bare value is every problem's, ``problem=value``
    one problem's. One line naming the flag on a bad item."""
    values: dict[str | None, float] = {}
    for item in filter(None, (text or "").split(",")):
        name, _, value = item.rpartition("=") if "=" in item else (None, "", item)
        try:
            values[name or None] = cast(value)
        except ValueError:
            raise SystemExit(f"league: error: {flag} {text}: {item!r} is not a number or problem=number") from None
    return values


def parse_set(item: str) -> tuple[str | None, str, str]:
    """``'poisson/hig:device=cuda'`` -> ('poisson/hig', 'device', 'cuda'); ``'threads=1'`` -> (None, 'threads', '1')."""
    head, sep, value = item.partition("=")
    if not sep or not head.rpartition(":")[2]:
        raise SystemExit(f"league: error: --set {item}: expected [SCOPE:]KEY=VALUE")
    scope, _, key = head.rpartition(":")
    if key in LEAGUE_KEYS:
        raise SystemExit(f"league: error: --set {item}: {key} is the league's own (--problems, --optimizers, --seeds, --seconds)")
    return scope or None, key, value


def refusal(problem: str, optimizer: str, with_set: bool = True) -> str | None:
    """Why ``optimizer`` cannot run on ``problem`` (the CLI's one line: SIP without an inverse
    simulator, a package's missing extra), or None. ``with_set=False`` leaves the --set
    overrides out: re-reading runs trained on a GPU needs none here."""
    from higbench.config import validate
    from higbench.errors import ConfigError
    from higbench.jobs import compose, hydra_conf
    from higbench.preflight import composition_error

    overrides = [f"problem={problem}", f"optimizer={optimizer}"]
    overrides += [f"{k}={v}" for k, v in extra_overrides(problem, optimizer).items()] if with_set else []
    try:
        with hydra_conf():
            cfg = compose(tuple(overrides))
        validate(cfg)
    except ConfigError as exc:
        return str(exc)
    except Exception as exc:  # Hydra's composition errors (an unknown key in --set): the CLI's line
        return str(composition_error(exc, overrides))
    return None


def check_protocol(trials: dict, budgets: dict, problems: list[str], optimizers: list[str]) -> None:
    """Before any run: each per-problem count or budget, and each --set scope, names a shipped
    problem (or optimizer), and counts and budgets are positive. A typo in a scope would
    otherwise train on the wrong device without a word. Names outside this league's --problems
    pass: one set of flags serves each problem's command and the --report-only over all."""
    from higbench.config import config_dir

    shipped = {group: sorted(p.stem for p in (Path(config_dir()) / group).glob("*.yaml")) for group in ("problem", "optimizer")}
    problems, optimizers = sorted({*problems, *shipped["problem"]}), sorted({*optimizers, *shipped["optimizer"]})
    for flag, values in (("--trials", trials), ("--seconds", budgets)):
        for name, value in values.items():
            if name is not None and name not in problems:
                choices = ", ".join(problems)
                raise SystemExit(f"league: error: {flag} {name}={value:g}: no problem {name} (conf/problem/: {choices})")
            if not value > 0:
                raise SystemExit(f"league: error: {flag} {value:g}: must be positive")
    for scope, key, value in EXTRA:
        names = scope.split("/") if scope else []
        known = (
            not names
            or (len(names) == 1 and names[0] in problems + optimizers)
            or (len(names) == 2 and names[0] in problems and names[1] in optimizers)
        )
        if not known:
            why = "is not a problem, an optimizer or problem/optimizer (conf/problem/, conf/optimizer/)"
            raise SystemExit(f"league: error: --set {scope}:{key}={value}: {scope} {why}")


def check_set(problem: str, optimizers: list[str]) -> None:
    """A --set that makes an optimizer refuse a problem it runs without it is the user's value,
    not the optimizer's limit: one line naming it, before any run."""
    for optimizer in optimizers:
        extra = extra_overrides(problem, optimizer)
        if extra and refusal(problem, optimizer, with_set=False) is None and (why := refusal(problem, optimizer)):
            given = " ".join(f"{k}={v}" for k, v in extra.items())
            raise SystemExit(f"league: error: --set ({problem}, {optimizer}: {given}): {why}")


def variant_overrides(variant: str) -> dict:
    return dict(item.split("=", 1) for item in variant.split())


def tuning_jobs(problem: str, optimizer: str, trials: int, seconds: float) -> list[Job]:
    space = league.load_space(optimizer)
    jobs = []
    for i, trial in enumerate(league.sobol_trials(space, trials, seed=0)):
        for seed in league.TUNING_SEEDS:
            job = Job(
                "league", f"tune/{problem}/{optimizer}/{i}", {**base_overrides(problem, optimizer, seed, seconds), **trial}, seed
            )
            jobs.append(job)
    return jobs


def choose(jobs: list[Job]) -> dict | None:
    """The tuned setting: the overrides of the trial with the lowest validation loss (median over
    tuning seeds), read from its run files; None when no trial completed."""
    from higbench.results.index import load_runs

    done = [j for j in jobs if j.path is not None]
    if not done:
        return None
    runs = load_runs([j.path for j in done])
    by_path = {str(Path(j.path)): j for j in done}
    runs = runs.assign(trial=runs["path"].map(lambda p: by_path[str(Path(p))].sweep))
    best = league.best_trial(runs)
    if best is None:
        return None
    job = by_path[str(Path(best["path"]))]
    space = league.load_space(str(job.overrides["optimizer"]))
    return {k: v for k, v in job.overrides.items() if k in space}


def confirmation_jobs(problem: str, optimizer: str, setting: dict | None, seeds, seconds: float, variants) -> list[Job]:
    """The setting (tuned, or the shipped one for ``setting=None``) on fresh seeds, on the problem
    and each held-out variant."""
    role = "paper" if setting is None else "confirm"
    jobs = []
    for variant in ["", *variants]:
        for seed in seeds:
            overrides = {**base_overrides(problem, optimizer, seed, seconds), **variant_overrides(variant), **(setting or {})}
            jobs.append(Job("league", f"{role}/{problem}/{variant or 'base'}/{optimizer}", overrides, seed))
    return jobs


def run_jobs(jobs: list[Job], root: Path, n_jobs: int, phase: str) -> None:
    """Launch the jobs not done under ``root`` (reusing every done one: ``jobs.run_missing``).
    Stops the league when some are still not done (interrupted, failed): a setting chosen from
    part of a tuning, or a next problem started after a Ctrl-C, is not what was asked for."""
    left = run_missing(jobs, root, n_jobs=n_jobs, launcher="basic" if n_jobs == 1 else "joblib", log=_log)
    if left:
        raise SystemExit(
            f"league: {len(left)} {phase} run(s) not done (interrupted or failed); "
            "the same command continues them, reusing every run already done"
        )


def _log(text: str) -> None:
    for prefix in ("[jobs]", "[figures]"):  # the launcher's lines, as the league's
        text = text.replace(prefix, "[league]", 1)
    print(text, file=sys.stderr)


def calibration() -> dict:
    """One fixed benchmark, so that tables from different machines can be read side by side:
    the best of 5 timings of 50 float32 256x256 matrix products and one float64 256x256 SVD,
    on one thread; with the load average at the time."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    gen = torch.Generator().manual_seed(0)
    a = torch.randn(256, 256, generator=gen)
    m = torch.randn(256, 256, generator=gen, dtype=torch.float64)
    matmul, svd = [], []
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(50):
            a @ a
        matmul.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        torch.linalg.svd(m)
        svd.append(time.perf_counter() - t0)
    torch.set_num_threads(threads)
    return {"when": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "matmul_50x256_s": min(matmul), "svd_256_f64_s": min(svd),
            "loadavg": list(os.getloadavg()), "cpu_count": os.cpu_count()}  # fmt: skip


def hardware(runs: pd.DataFrame) -> pd.Series:
    """Per run, what it trained on: the GPU's name, else 'CPU, N cores' (the machine's count)."""
    gpu = runs.get("env.device_name", pd.Series("", index=runs.index)).fillna("").astype(str)
    cores = pd.to_numeric(runs.get("env.cpu_count"), errors="coerce").fillna(0).astype(int)
    on_gpu = runs.get("env.device", pd.Series("cpu", index=runs.index)).astype(str).str.startswith("cuda")
    return gpu.where(on_gpu, "CPU, " + cores.astype(str) + " cores")


def machine(runs: pd.DataFrame) -> list[dict]:
    """Per problem and hardware, what the runs had of the machine: their CPU share (CPU seconds
    over wall seconds per thread; 1 = a core of their own), the load average at their end,
    threads, revisions and when they trained."""
    if runs.empty:
        return []

    def column(group: pd.DataFrame, name: str) -> pd.Series:
        return group[name] if name in group else pd.Series(dtype=object)

    groups = []
    for (problem, where), group in runs.groupby([runs["problem.name"], hardware(runs)], sort=True):
        share = pd.to_numeric(column(group, "env.cpu_share"), errors="coerce").dropna()
        load = column(group, "env.load_at_finish").dropna().map(lambda v: float(v[0]))
        threads = pd.to_numeric(column(group, "env.torch_threads"), errors="coerce").dropna().astype(int)
        groups.append({
            "problem": problem, "hardware": where, "runs": len(group),
            "cpu_share_median": round(float(share.median()), 3) if len(share) else None,
            "cpu_share_range": [round(float(share.min()), 3), round(float(share.max()), 3)] if len(share) else None,
            "load_1min_median": round(float(load.median()), 2) if len(load) else None,
            "threads_per_run": sorted({int(t) for t in threads}),
            "revisions": sorted(set(column(group, "env.git_revision").dropna().astype(str).str[:12])),
            "trained": [str(group["started"].min()), str(group["finished"].max())] if "started" in group else None,
        })  # fmt: skip
    return groups


def recorded_calibrations(root: Path, out: Path) -> list[dict]:
    """The calibrations earlier league invocations wrote beside their runs (``ROOT/manifests/``,
    or a league.json they left under the root, as a run on another machine brings back), each
    with where it was read (the report's own ``out`` left out)."""
    found = []
    for path in sorted([*root.glob("manifests/*.json"), *root.rglob("league.json")]):
        if path.resolve().is_relative_to(out.resolve()):
            continue
        try:
            entries = json.loads(path.read_text()).get("calibration") or []
        except (OSError, ValueError, AttributeError):
            continue
        found += [{**entry, "file": str(path.relative_to(root))} for entry in entries if isinstance(entry, dict)]
    return found


def report(root: Path, out: Path, manifest: dict) -> str:
    from higbench.results.__main__ import main as results_main
    from higbench.results.index import load_runs

    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        results_main([str(root), "--league"])
    text = buffer.getvalue()
    out.mkdir(parents=True, exist_ok=True)
    runs, curves = load_runs(root, curves=True, figure_runs=True)
    scored, reached, _ = league.league_frames(runs, curves, league.all_spaces())
    manifest["machine"] = machine(runs)
    manifest["recorded_calibration"] = recorded_calibrations(root, out)
    lines = ["machine: " + ", ".join(f"{k} {v}" for k, v in group.items()) for group in manifest["machine"]]
    text = "\n".join([*lines, text])
    if len(scored):
        league.plot_league(reached, league.interval_table(scored, reached), out)
        identities = scored[["task", "league_setting", "seed", "status", "final_val_loss", "final_test_loss", "steps",
                             "train_time_s", "config_id", "path"]].assign(hardware=hardware(scored))  # fmt: skip
        identities["path"] = identities["path"].map(lambda p: str(Path(p).resolve().relative_to(root.resolve())))
        identities.sort_values(["task", "league_setting", "seed"]).to_csv(out / "runs.csv", index=False)
    (out / "league.txt").write_text(text)  # after the machine line
    (out / "league.json").write_text(json.dumps(manifest, indent=1, default=str) + "\n")
    return text


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--problems", default="toy,oscillator", help="comma-separated (default: toy,oscillator)")
    p.add_argument(
        "--optimizers", default=",".join(DEFAULT_OPTIMIZERS), help="comma-separated; each needs conf/search/<name>.yaml"
    )
    p.add_argument("--paper", default="hig,gn,adam", help="optimizers also run at their shipped (paper) settings")
    p.add_argument("--trials", default="6", help="Sobol trials per (problem, optimizer), the same for every optimizer; "
                   "'4,toy=16': 16 on the toy")  # fmt: skip
    p.add_argument("--seeds", type=int, default=3, help="confirmation seeds 0..N-1 (never a tuning seed)")
    p.add_argument("--seconds", help="training-clock budget per run (default: each problem's league_seconds); "
                   "'toy=10': the toy's")  # fmt: skip
    p.add_argument("--set", action="append", default=[], metavar="[SCOPE:]KEY=VALUE",
                   help="an override for every job, or for those of one problem or optimizer (SCOPE); repeatable")  # fmt: skip
    p.add_argument("--variants", type=int, default=None, help="at most this many held-out variants per problem (default: all)")
    p.add_argument("--root", type=Path, default=ROOT / "outputs" / "league", help="where the runs go (and are reused from)")
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "league", help="league.txt and league.json")
    p.add_argument("--jobs", type=int, default=1, help="runs at once (1: the budgets are not shared)")
    p.add_argument("--report-only", action="store_true", help="train nothing; score the runs under --root")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    problems = [p for p in args.problems.split(",") if p]
    optimizers = [o for o in args.optimizers.split(",") if o]
    paper = [o for o in args.paper.split(",") if o in optimizers]
    trials = per_problem(args.trials, "--trials", int)
    budgets = per_problem(args.seconds, "--seconds")
    EXTRA[:] = [parse_set(item) for item in args.set]
    check_protocol(trials, budgets, problems, optimizers)
    seeds = list(range(args.seeds))
    if set(seeds) & set(league.TUNING_SEEDS):
        raise SystemExit(f"league: error: --seeds {args.seeds}: overlaps the tuning seeds {league.TUNING_SEEDS}")
    for o in optimizers:
        league.load_space(o)  # a missing or bad search space stops the league before any run
    args.root.mkdir(parents=True, exist_ok=True)
    manifest: dict = {"command": " ".join(["higbench-league", *(argv if argv is not None else sys.argv[1:])]),
                      "tuning_seeds": list(league.TUNING_SEEDS), "confirmation_seeds": seeds,
                      "problems": {}, "calibration": [calibration()]}  # fmt: skip
    all_jobs: list[tuple[str, Job]] = []
    for problem in problems:
        node = problem_config(problem)
        seconds = budgets.get(problem, budgets.get(None)) or node.get("league_seconds")
        n_trials = trials.get(problem, trials.get(None))
        if not n_trials:
            raise SystemExit(f"league: error: --trials {args.trials}: no count for problem={problem}")
        if not seconds:
            raise SystemExit(f"league: error: problem={problem}: no problem.league_seconds; give --seconds")
        variants = list(node.get("held_out") or [])[: args.variants]
        if not args.report_only:
            check_set(problem, optimizers)
        refused = {o: why for o in optimizers if (why := refusal(problem, o, with_set=False))}
        for o, why in refused.items():
            print(f"[league] {problem}: {o} left out: {why}", file=sys.stderr)
        usable = [o for o in optimizers if o not in refused]
        tune = {o: tuning_jobs(problem, o, n_trials, seconds) for o in usable}
        if not args.report_only:
            run_jobs([j for jobs in tune.values() for j in jobs], args.root, args.jobs, f"{problem} tuning")
        else:
            resolve([j for jobs in tune.values() for j in jobs], run_index(args.root))
        chosen = {o: choose(jobs) for o, jobs in tune.items()}
        confirm = [
            j for o in usable if chosen[o] is not None for j in confirmation_jobs(problem, o, chosen[o], seeds, seconds, variants)
        ]
        confirm += [j for o in paper if o in usable for j in confirmation_jobs(problem, o, None, seeds, seconds, variants)]
        if not args.report_only:
            run_jobs(confirm, args.root, args.jobs, f"{problem} confirmation")
        else:
            resolve(confirm, run_index(args.root))
        manifest["problems"][problem] = {"seconds": seconds, "trials": n_trials, "targets": node.get("targets"),
                                         "held_out": variants, "set": {o: extra_overrides(problem, o) for o in usable},
                                         "chosen": chosen, "left_out": refused}  # fmt: skip
        all_jobs += [("tune", j) for jobs in tune.values() for j in jobs] + [(j.sweep.split("/")[0], j) for j in confirm]
    manifest["calibration"].append(calibration())
    manifest["runs"] = [{"role": role, "job": j.sweep, "seed": j.seed, "identity": j.identity, "status": j.status,
                         "path": str(Path(j.path).relative_to(args.root.resolve())) if j.path else None}
                        for role, j in all_jobs]  # fmt: skip
    if not args.report_only:  # kept beside the runs: a later --report-only, anywhere, reads it back
        (args.root / "manifests").mkdir(exist_ok=True)
        stamp = time.strftime("%Y-%m-%dT%H-%M-%S") + f"-{os.getpid()}"
        (args.root / "manifests" / f"{stamp}.json").write_text(json.dumps(manifest, indent=1, default=str) + "\n")
    print(report(args.root, args.out, manifest))
    missing = [j for _, j in all_jobs if not j.done]
    if missing:
        print(f"[league] {len(missing)} run(s) not done: {', '.join(sorted({j.sweep for j in missing}))}", file=sys.stderr)
    return 0
