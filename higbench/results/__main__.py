"""`higbench-results` / `python -m higbench.results`: the runs under a root as a table.

higbench-results outputs                          # every run, one line each
higbench-results outputs/sweeps --problem oscillator --status completed
higbench-results outputs --best                   # best run per optimizer (table 2)
higbench-results outputs --csv runs.csv           # the full table (all columns)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

from higbench.results.index import DEFAULT_THRESHOLDS, best_runs, find_run_files, load_runs, threshold_column, under_figure_runs
from higbench.runfile.reader import RUN_FILE_GLOB

SUMMARY_COLUMNS = [
    "path",
    "problem.name",
    "problem.model",
    "optimizer.name",
    "status",
    "steps",
    "train_time_s",
    "final_test_loss",
    "best_test_loss",
    "overrides",
]


def _values(arg: list[str] | None) -> list[str]:
    """--optimizer adam,hig --optimizer sgd -> [adam, hig, sgd]."""
    return [v for a in arg or [] for v in a.split(",") if v]


def _column(df: pd.DataFrame, name: str, fallback: str) -> pd.Series:
    if name in df:
        return df[name].fillna(df[fallback]) if fallback in df else df[name]
    return df[fallback] if fallback in df else pd.Series([None] * len(df), index=df.index)


def _relative(paths: pd.Series, roots: list[Path]) -> pd.Series:
    """Paths shown relative to the (single) root directory, else as they are."""
    if len(roots) != 1 or not roots[0].is_dir():
        return paths
    root = str(roots[0]).rstrip("/") + "/"
    return paths.map(lambda p: p[len(root) :] if p.startswith(root) else p)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="higbench-results", description="Summarise the higbench run files under a directory.")
    p.add_argument("roots", nargs="*", default=["outputs"], help="directories or run files (default: outputs)")
    p.add_argument("--problem", action="append", help="keep these problems (comma-separated or repeated)")
    p.add_argument("--optimizer", action="append", help="keep these optimizers (comma-separated or repeated)")
    p.add_argument("--status", action="append", help="keep these statuses: completed, diverged, running, corrupt, ...")
    p.add_argument("--best", action="store_true", help="only the best completed run per (problem, optimizer) by --metric")
    p.add_argument("--metric", default="final_test_loss", help="what --best and the sort minimise (default: final_test_loss)")
    p.add_argument(
        "--by",
        help="grouping of --best, comma-separated (default: problem.name,problem.model,optimizer.name;"
        " problem.model only where runs have it)",
    )
    p.add_argument("--threshold", action="append", type=float, help="add a time_to_<t> column (repeatable)")
    p.add_argument("--columns", help="extra columns to show, comma-separated (e.g. optimizer.lr,batch_size,mean_update_s)")
    p.add_argument("--pattern", default=RUN_FILE_GLOB, help=f"run file name pattern (default: {RUN_FILE_GLOB})")
    p.add_argument(
        "--figure-runs", action="store_true", help="also list the runs `make figures` made (under figures-runs/; off by default)"
    )
    p.add_argument("--jobs", type=int, default=1, help="processes reading run files (for thousands of files)")
    p.add_argument("--csv", metavar="FILE", help="also write the full filtered table (all columns) to FILE")
    p.add_argument("--width", type=int, default=60, help="truncate the overrides column to this many characters (0: never)")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    roots = [Path(r) for r in args.roots]
    thresholds = tuple(args.threshold) if args.threshold else DEFAULT_THRESHOLDS
    try:
        df = load_runs(roots, thresholds=thresholds, pattern=args.pattern, jobs=args.jobs, figure_runs=args.figure_runs)
    except FileNotFoundError as exc:
        print(f"higbench-results: error: {exc}", file=sys.stderr)
        return 2
    total = len(df)
    if total:
        df = df.assign(
            **{
                "problem.name": _column(df, "problem.name", "problem"),
                "optimizer.name": _column(df, "optimizer.name", "optimizer"),
            }
        )
    for key, wanted in (
        ("problem.name", _values(args.problem)),
        ("optimizer.name", _values(args.optimizer)),
        ("status", _values(args.status)),
    ):
        if wanted and key in df:
            df = df[df[key].isin(wanted)]
    if args.best:
        by = (
            [k for k in args.by.split(",") if k]
            if args.by
            else [k for k in ("problem.name", "problem.model", "optimizer.name") if k in df]
        )
        try:
            df = best_runs(df, by=by, metric=args.metric, per_problem=not args.by) if len(df) else df  # --by: the whole grouping
        except KeyError as exc:
            print(f"higbench-results: error: {exc.args[0]}", file=sys.stderr)
            return 2
    elif args.metric in df:
        df = df.sort_values(["problem.name", "optimizer.name", args.metric], na_position="last")
    if args.csv:
        df.to_csv(args.csv, index=False)

    counts = df["status"].value_counts().to_dict() if len(df) else {}
    left_out = 0 if args.figure_runs else sum(under_figure_runs(p, roots) for p in find_run_files(roots, args.pattern))
    print(
        f"{len(df)} of {total} runs under {', '.join(map(str, roots))}"
        + (f" ({', '.join(f'{n} {s}' for s, n in counts.items())})" if counts else "")
        + (f"; {left_out} run(s) of `make figures` left out (--figure-runs)" if left_out else "")
    )
    if not len(df):
        return 0
    shown = (
        SUMMARY_COLUMNS
        + [threshold_column(t) for t in (args.threshold or [])]
        + [c for c in (args.columns or "").split(",") if c]
    )
    if args.best and args.metric not in shown:
        shown.insert(shown.index("final_test_loss"), args.metric)
    missing = [c for c in shown if c not in df.columns]
    if args.columns and any(c in missing for c in args.columns.split(",")):
        print(f"higbench-results: note: no column(s) {[c for c in args.columns.split(',') if c in missing]}", file=sys.stderr)
    table = df[[c for c in dict.fromkeys(shown) if c in df.columns]].copy()
    table["path"] = _relative(table["path"].astype(str), roots)
    if args.width and "overrides" in table:
        table["overrides"] = (
            table["overrides"].fillna("").map(lambda s: s if len(s) <= args.width else s[: args.width - 3] + "...")
        )
    with pd.option_context(
        "display.max_rows", None, "display.max_columns", None, "display.width", 250, "display.float_format", "{:.4g}".format
    ):
        print(table.to_string(index=False))
    errors = df[df["error"].fillna("") != ""] if "error" in df else df.iloc[0:0]
    for _, row in errors.iterrows():
        print(f"note: {row['path']}: {row['status']}: {row['error']}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
