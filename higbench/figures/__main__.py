"""`python -m higbench.figures` (`higbench-figures`): the paper's figures and tables from run files.

    python -m higbench.figures all --preset quick            # what `make figures` runs
    python -m higbench.figures fig1 fig2b --preset smoke
    python -m higbench.figures all --preset paper --plan     # runs needed/missing, cost; runs nothing
    python -m higbench.figures all --no-run                  # draw from the runs that exist
    python -m higbench.figures --list

Runs already under --runs-root with the same resolved config are reused; only missing
ones are run (Hydra multiruns of the `higbench` CLI, joblib launcher for parallel jobs).
Outputs in --out: <id>.png/.pdf + <id>.csv (plotted data) + <id>.json (preset, budgets,
runs), tables as <id>.md/.csv, and REPORT.md (the paper's claims against these runs).
"""

from __future__ import annotations

import argparse
import sys

from higbench.figures.spec import PRESETS

OPTIONS = [
    ("--runs-root", dict(default="outputs", help="where runs are looked for and written (default: outputs)")),
    ("--out", dict(default="figures", help="output directory (default: figures)")),
    ("--jobs", dict(type=int, help="runs trained at the same time (default: min(cores, 2)); one torch thread each")),
    (
        "--launcher",
        dict(
            default="auto",
            choices=("auto", "basic", "joblib"),
            help="Hydra launcher for missing runs "
            "(auto = basic: multiruns split n ways and run side by side; joblib: one multirun per grid on joblib workers)",
        ),
    ),
    ("--no-run", dict(action="store_true", help="run nothing; draw from the runs that exist")),
    ("--plan", dict(action="store_true", help="print runs needed/missing and their training seconds; run and draw nothing")),
    ("--no-bench", dict(action="store_true", help="tables 3-5: do not run scripts/bench_step.py; use its table or timing runs")),
    ("--no-report", dict(action="store_true", help="do not rewrite REPORT.md")),
    ("--list", dict(action="store_true", help="list the figures and exit")),
]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="higbench-figures", description=__doc__.split("\n\n")[0])
    p.add_argument("ids", nargs="*", default=["all"], help="figure/table ids (fig1 fig2b table2 ...) or 'all'")
    presets = ", ".join(f"{k} (falls back to {v})" if v else k for k, v in PRESETS.items())
    p.add_argument("--preset", default="quick", choices=PRESETS, help=f"budgets and grids: {presets}")
    for name, kw in OPTIONS:
        p.add_argument(name, **kw)
    args = p.parse_args(argv)
    from higbench.figures import build, registry

    if args.list:
        for fid, f in registry.figures().items():
            print(f"{fid:8s} {f.kind:6s} {f.title}")
        return 0
    try:
        registry.select(args.ids)
    except KeyError as exc:
        print(f"higbench-figures: error: {exc.args[0]}", file=sys.stderr)
        return 2
    if args.plan:
        rows = build.plan(args.ids, args.preset, args.runs_root)
        total, jobs = sum(r[3] for r in rows), args.jobs or 2
        print(f"{'figure':8s} {'runs':>5s} {'missing':>8s} {'train s':>9s}  (preset {args.preset}; shared runs counted once)")
        print("\n".join(f"{fid:8s} {n:5d} {miss:8d} {secs:9.0f}" for fid, n, miss, secs in rows))
        print(
            f"total training seconds missing: {total:.0f} (~{total / jobs / 60:.0f} min on {jobs} parallel jobs, plus "
            "start-up and evaluations)"
        )
        return 0
    result = build.build(
        args.ids,
        args.preset,
        args.runs_root,
        args.out,
        jobs=args.jobs,
        launcher=args.launcher,
        run=not args.no_run,
        report=not args.no_report,
        bench=not args.no_bench,
    )
    print(
        f"[figures] preset {args.preset}: {len(result.drawn)} drawn, {result.launched} run(s) launched, "
        f"{result.seconds:.1f} s; outputs in {args.out}/"
    )
    if result.missing:
        print("[figures] runs still missing (failed or not run): " + ", ".join(f"{k}: {v}" for k, v in result.missing.items()))
    for k, v in result.errors.items():
        print(f"[figures] {k}: {v}", file=sys.stderr)
    return 1 if result.errors else 0


if __name__ == "__main__":
    sys.exit(main())
