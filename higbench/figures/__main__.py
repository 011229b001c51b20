"""`python -m higbench.figures` (`higbench-figures`): the paper's figures and tables from run files.

    python -m higbench.figures all --preset quick            # what `make figures` runs
    python -m higbench.figures fig1 --preset quick           # one figure, its claims judged and printed (~8 min)
    python -m higbench.figures fig1 fig2b --preset smoke     # the plumbing check: no verdicts
    python -m higbench.figures all --preset paper --plan     # runs needed/missing, cost; runs nothing
    python -m higbench.figures all --no-run                  # draw from the runs that exist
    python -m higbench.figures --report-only --out docs/results   # REPORT.md from the data there, no runs
    python -m higbench.figures --list

Runs already under --runs-root with the same resolved config are reused (the results
index); only missing ones are run, as `higbench -m` multiruns on a Hydra launcher:
joblib with --jobs workers here, or e.g. `--launcher slurm --launcher-override
hydra.launcher.partition=gpu` on a cluster.
Outputs in --out: <id>.png/.pdf + <id>.csv (plotted data) + <id>.json (preset, budgets,
runs), tables as <id>.md/.csv, and REPORT.md (the paper's claims against these runs).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from higbench.figures.spec import PRESETS


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="higbench-figures", description=__doc__.split("\n\n")[0])
    arg = p.add_argument
    arg("ids", nargs="*", default=["all"], help="figure/table ids (fig1 fig2b table2 ...) or 'all'")
    arg(
        "--preset",
        default="quick",
        choices=PRESETS,
        help="budgets and grids: smoke (minutes, every code path), quick (scaled down), paper; a value a preset does not "
        "set is its fallback's (spec.PRESETS: smoke -> quick -> paper)",
    )
    arg("--runs-root", default="outputs", help="where runs are looked for and written (default: outputs)")
    arg("--out", default="figures", help="output directory (default: figures)")
    jobs_help = "joblib launcher: runs trained at the same time (default: min(cores, 2)); each run uses one torch thread"
    arg("--jobs", type=int, default=None, help=jobs_help)
    launcher_help = (
        "Hydra launcher of the missing runs' multiruns (higbench -m): joblib (default; local, --jobs workers), "
        "basic (one after another), or a hydra/launcher config: slurm, submitit_slurm, submitit_local"
    )
    arg("--launcher", default="joblib", metavar="NAME", help=launcher_help)
    override_help = "extra Hydra override for every multirun, e.g. hydra.launcher.partition=gpu (repeatable)"
    arg("--launcher-override", action="append", default=[], metavar="hydra.KEY=VALUE", help=override_help)
    arg("--no-run", action="store_true", help="run nothing; draw from the runs that exist")
    arg("--plan", action="store_true", help="print runs needed/missing and their training seconds; run and draw nothing")
    arg(
        "--no-bench",
        action="store_true",
        help="tables 3-5: do not run scripts/bench_step.py; use its existing table or timing runs",
    )
    arg("--no-report", action="store_true", help="do not rewrite REPORT.md")
    report_help = (
        "rewrite --out/REPORT.md from the claim rows stored there (<id>.json), judged by the current rules and causes; "
        "run and draw nothing"
    )
    arg("--report-only", action="store_true", help=report_help)
    arg("--list", action="store_true", help="list the figures and exit")
    return p


def print_plan(args: argparse.Namespace) -> None:
    from higbench.figures.build import plan

    total = 0.0
    print(f"{'figure':8s} {'runs':>5s} {'missing':>8s} {'train s':>9s}  (preset {args.preset}; shared runs counted once)")
    for fid, n, miss, secs in plan(args.ids, args.preset, args.runs_root):
        total += secs
        print(f"{fid:8s} {n:5d} {miss:8d} {secs:9.0f}")
    jobs = args.jobs or 2
    print(
        f"total training seconds missing: {total:.0f} (~{total / jobs / 60:.0f} min on {jobs} parallel jobs, plus "
        "start-up and evaluations)"
    )


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    from higbench.figures import registry

    if args.report_only:
        from higbench.claims.rules import ResultsFileError
        from higbench.figures.report import write_report

        if not Path(args.out).is_dir():
            print(f"higbench-figures: error: --out={args.out}: no such directory (nothing to report from)", file=sys.stderr)
            return 2
        try:
            print(f"[figures] {write_report(Path(args.out), list(registry.figures()))}")
        except ResultsFileError as exc:  # a FIFO, or malformed JSON, among the results files
            print(f"higbench-figures: error: {exc}", file=sys.stderr)
            return 2
        return 0
    if args.list:
        for fid, f in registry.figures().items():
            print(f"{fid:8s} {f.kind:6s} {f.title}")
        return 0
    try:
        registry.select(args.ids)
    except KeyError as exc:
        print(f"higbench-figures: error: {exc.args[0]}", file=sys.stderr)
        return 2
    from higbench.jobs import Launcher

    try:
        launcher = Launcher(args.launcher, tuple(args.launcher_override))
    except ValueError as exc:
        print(f"higbench-figures: error: --launcher-override {exc}", file=sys.stderr)
        return 2
    if args.plan:
        print_plan(args)
        return 0
    return run_build(args, launcher)


def claim_lines(out: Path, drawn: list[str]) -> list[str]:
    """The claims of the figures drawn, one line each (``toy-3 reproduced: HIG 5.4e-4, ...``),
    read back from their ``<id>.json``: what a build showed, without opening REPORT.md."""
    lines = []
    for fid in drawn:
        try:
            claims = json.loads((out / f"{fid}.json").read_text()).get("claims", [])
        except (OSError, ValueError):
            continue
        if claims and all(str(c["verdict"]).startswith("n/a") for c in claims):  # the smoke preset, missing runs
            lines.append(f"[figures] {fid}: its {len(claims)} claims n/a at these runs (why: {out}/REPORT.md)")
        elif claims:
            lines.append(f"[figures] {fid}: {len(claims)} claims of the paper, as these runs judge them (all: {out}/REPORT.md)")
            lines += [f"  {c['id']} {c['verdict']}: {c.get('paper', '')} | measured: {c.get('measured', '')}" for c in claims]
    return lines


def run_build(args: argparse.Namespace, launcher) -> int:
    from higbench.claims.rules import ResultsFileError
    from higbench.display import busy_summary
    from higbench.figures.build import build
    from higbench.results.index import cpu_uses

    try:
        result = build(
            args.ids,
            args.preset,
            args.runs_root,
            args.out,
            jobs=args.jobs,
            launcher=launcher,
            run=not args.no_run,
            report=not args.no_report,
            bench=not args.no_bench,
        )
    except ResultsFileError as exc:  # REPORT.md's inputs: a FIFO, or malformed JSON, among them
        print(f"higbench-figures: error: {exc}", file=sys.stderr)
        return 2
    print(
        f"[figures] preset {args.preset}: {len(result.drawn)} drawn, {result.launched} run(s) launched, "
        f"{result.seconds:.1f} s; outputs in {args.out}/"
    )
    for line in claim_lines(Path(args.out), result.drawn):
        print(line)
    busy = busy_summary(cpu_uses(result.run_files), noun="runs of this build")
    if busy:  # a busy machine: the figures' curves and verdicts are not an idle machine's
        print(f"[figures] {busy}")
    if result.missing:
        print("[figures] runs still missing (failed or not run): " + ", ".join(f"{k}: {v}" for k, v in result.missing.items()))
    for k, v in result.errors.items():
        print(f"[figures] {k}: {v}", file=sys.stderr)
    return 1 if result.errors else 0


if __name__ == "__main__":
    sys.exit(main())
