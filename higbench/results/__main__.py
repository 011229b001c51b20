"""`higbench-results` / `python -m higbench.results`: the runs under a root as a table.

higbench-results outputs                          # every run, one line each
higbench-results outputs/sweeps --problem oscillator --status completed
higbench-results outputs --best                   # best setting per setup (lr and batch size selected), median over seeds
higbench-results outputs --best-seed              # the best single run per setup instead (table 2's selection)
higbench-results outputs --csv runs.csv           # the full table (all columns)
higbench-results outputs/sweeps/X --plot curves.png   # median and band over seeds per setting
higbench-results outputs/sweeps/X --profile profile.png --targets poisson=10,1 toy=1e-3
higbench-results outputs --optimizer hig --spectrum spectrum.png   # singular values of J over training
higbench-results outputs/league --league          # integrated score, IQMs with intervals, P(HIG improves)
"""

from __future__ import annotations

import argparse
import difflib
import sys
from pathlib import Path

import pandas as pd

from higbench.display import BUSY_SHARE, busy_load
from higbench.errors import quiet_broken_pipe
from higbench.results import targets as problem_targets
from higbench.results.index import (
    DONE_STATUSES,
    best_runs,
    best_settings,
    find_run_files,
    load_runs,
    one_per_config,
    threshold_column,
    under_figure_runs,
)
from higbench.results.profile import (
    BEST_OVER,
    all_targets,
    budget_labels,
    format_table,
    parse_targets,
    performance_profile,
    setting_labels,
    time_to_target,
)
from higbench.runfile.reader import RUN_FILE_GLOB

CONDITIONING_SHOWN = ("cond_kept_median", "sv_dropped_mean")  # of spectrum.CONDITIONING_COLUMNS
MAX_PANELS = 24  # --spectrum: more runs are left out with a note (filter with --problem/--optimizer)
SUMMARY_COLUMNS = [
    "path",
    "problem.name",
    "problem.model",
    "optimizer.name",
    "status",
    "budget",
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
    p.add_argument(
        "--best",
        action="store_true",
        help="the best setting per (problem, setup, budget): the lowest median --metric over its seeds, with the"
        " number of seeds and their range (see --by)",
    )
    p.add_argument(
        "--best-seed",
        action="store_true",
        help="with or without --best: the best single completed run per (problem, setup, budget) instead",
    )
    p.add_argument("--metric", default="final_test_loss", help="what --best and the sort minimise (default: final_test_loss)")
    p.add_argument(
        "--by",
        help="grouping of --best, comma-separated (default: per problem, every key that changes a result except"
        f" {' and '.join(BEST_OVER)}, which --best selects over: column setup)",
    )
    p.add_argument("--threshold", action="append", type=float, help="add a time_to_<t> column (repeatable)")
    p.add_argument("--columns", help="extra columns to show, comma-separated (e.g. optimizer.lr,batch_size,mean_update_s)")
    p.add_argument("--pattern", default=RUN_FILE_GLOB, help=f"run file name pattern (default: {RUN_FILE_GLOB})")
    p.add_argument(
        "--figure-runs",
        action="store_true",
        help="also list the runs `make figures` and `higbench-league` launched (under figures-runs/; off by default)",
    )
    p.add_argument("--jobs", type=int, default=1, help="processes reading run files (for thousands of files)")
    p.add_argument("--csv", metavar="FILE", help="also write the full filtered table (all columns) to FILE")
    p.add_argument("--width", type=int, default=60, help="truncate the overrides column to this many characters (0: never)")
    p.add_argument("--plot", metavar="FILE", help="draw test loss against training clock: median and band over seeds per setting")
    p.add_argument("--profile", metavar="FILE", help="print time to target per setting and draw the performance profile")
    p.add_argument(
        "--spectrum",
        metavar="FILE",
        help=f"draw the singular values of each GN/HIG/LM step against updates, one panel per run (at most {MAX_PANELS})",
    )
    p.add_argument(
        "--league",
        action="store_true",
        help="the league (higbench-league): performance profiles in seconds and updates with the integrated score,"
        " IQMs with 95%% bootstrap intervals per task, P(HIG improves); tuning-seed runs left out",
    )
    p.add_argument(
        "--targets",
        nargs="+",
        metavar="PROBLEM=LOSS,...",
        help="target test losses per problem for --plot/--profile (default: the problem config's problem.targets)",
    )
    p.add_argument(
        "--setting",
        help="config columns that make an optimizer setting, comma-separated (default: every key that changes a"
        " result; not the seed, budget, evaluation schedule, threads, progress, tensorboard, ...)",
    )
    return p.parse_args(argv)


def _known(kind: str, df: pd.DataFrame, column: str) -> set[str]:
    """Names a filter value may take: those in the runs and the shipped configs of that group."""
    from higbench.config import config_dir

    shipped = {p.stem for p in (Path(config_dir()) / kind).glob("*.yaml")}
    return shipped | (set(df[column].dropna().astype(str)) if column in df else set())


def _check_filters(args: argparse.Namespace, df: pd.DataFrame) -> str | None:
    """An error line for a --problem/--optimizer value no run or config knows (with a suggestion)."""
    for flag, kind, column in (("problem", "problem", "problem.name"), ("optimizer", "optimizer", "optimizer.name")):
        values = _values(getattr(args, flag))
        known = _known(kind, df, column) if values else set()
        for value in values:
            if value not in known:
                close = difflib.get_close_matches(value, sorted(known), n=1)
                hint = f"did you mean {close[0]}?" if close else f"known: {', '.join(sorted(known))}"
                return f"--{flag} {value}: no such {kind}; {hint}"
    return None


def _time_columns(df: pd.DataFrame, most: int = 3) -> list[str]:
    """The time_to_<t> columns some run reached: the lowest ``most`` thresholds, highest first."""
    reached = [c for c in df.columns if c.startswith("time_to_") and pd.to_numeric(df[c], errors="coerce").notna().any()]
    return sorted(sorted(reached, key=lambda c: float(c[len("time_to_") :]))[:most], key=lambda c: -float(c[len("time_to_") :]))


def _load(args: argparse.Namespace, roots: list[Path], thresholds: tuple[float, ...] | None, curves: bool = False):
    return load_runs(
        roots, curves=curves, thresholds=thresholds, pattern=args.pattern, jobs=args.jobs, figure_runs=args.figure_runs
    )


def _with_names(df: pd.DataFrame, args: argparse.Namespace) -> pd.DataFrame:
    """problem.name/optimizer.name filled from the root attributes, plus ``budget`` and ``setting``."""
    if not len(df):
        return df.assign(budget=pd.Series(dtype=object), setting=pd.Series(dtype=object))
    df = df.assign(
        **{
            "problem.name": _column(df, "problem.name", "problem"),
            "optimizer.name": _column(df, "optimizer.name", "optimizer"),
        }
    )
    keys = [k for k in (args.setting or "").split(",") if k]
    missing = [k for k in keys if k not in df]
    if missing:
        raise KeyError(f"--setting {args.setting}: no column(s) {missing} in the runs table")
    return df.assign(budget=budget_labels(df), setting=setting_labels(df, keys or None))


def _problem_variant(name: str) -> dict[str, object] | None:
    """A shipped problem config that is another problem with other keys (``dipole_cnn``: the
    dipole with ``problem.model=cnn``) as {column: value}; None for any other name."""
    import yaml

    from higbench.config import config_dir

    path = Path(config_dir()) / "problem" / f"{name}.yaml"
    if not path.is_file():
        return None
    conf = yaml.safe_load(path.read_text()) or {}
    bases = [d for d in conf.get("defaults", []) if isinstance(d, str) and d != "_self_"]
    keys = {f"problem.{k}": v for k, v in (conf.get("problem") or {}).items() if k != "name" and not isinstance(v, dict)}
    return {"problem.name": bases[0], **keys} if len(bases) == 1 and keys else None


def _filter(df: pd.DataFrame, args: argparse.Namespace) -> pd.DataFrame:
    problems = _values(args.problem)
    variants = [v for v in map(_problem_variant, problems) if v]
    if variants and len(df):  # --problem dipole_cnn: its runs are problem.name dipole with problem.model cnn
        match = pd.Series(False, index=df.index)
        for name in problems:
            wanted = _problem_variant(name) or {"problem.name": name}
            hit = pd.Series(True, index=df.index)
            for column, value in wanted.items():
                hit &= df[column].astype(str) == str(value) if column in df else False
            match |= hit
        df, problems = df[match], []
    for key, wanted in (
        ("problem.name", problems),
        ("optimizer.name", _values(args.optimizer)),
        ("status", _values(args.status)),
    ):
        if wanted and key in df:
            df = df[df[key].isin(wanted)]
    return df


def _best(df: pd.DataFrame, args: argparse.Namespace) -> pd.DataFrame:
    """The best setting per setup, at equal budget, judged by the median over its seeds
    (``index.best_settings``; --best-seed: the best single run, ``index.best_runs``). A setup
    is every key that changes a result except those --best selects over (``BEST_OVER``: the
    learning rate and the batch size), so GN at gamma=0.01 never sits beside HIG at gamma=1,
    nor an amsgrad run beside plain Adam (column ``setup``). The budget is always one of the
    group keys, so a 30 s run never competes with a 5 s one (a note says when budgets were
    mixed). --by: the whole grouping."""
    if args.by:
        by = [k for k in args.by.split(",") if k]
    else:
        df = df.assign(setup=setting_labels(df, leave_out=BEST_OVER))
        by = [k for k in ("problem.name", "setup") if k in df]
    if "budget" not in by:
        by.append("budget")
    if len(df) and df.groupby("problem.name")["budget"].nunique().max() > 1:
        print("note: runs with different budgets: the best is chosen per budget (column budget)", file=sys.stderr)
    if not len(df):
        return df
    choose = best_runs if args.best_seed else best_settings
    return choose(df, by=by, metric=args.metric, per_problem=not args.by)  # --by: the whole grouping


def _targets(args: argparse.Namespace, df: pd.DataFrame) -> dict[str, list[float]]:
    # --targets, else the problem configs' (problem.targets: the runs' stored ones, else the shipped ones)
    targets = parse_targets(args.targets) if args.targets else problem_targets.of_runs(df)
    unknown = sorted(set(targets) - set(df["problem.name"].dropna())) if len(df) else []
    if unknown and args.targets:
        print(f"note: --targets: no runs of {', '.join(unknown)} here", file=sys.stderr)
    return targets


def _comparable(runs: pd.DataFrame, targets: dict[str, list[float]], args: argparse.Namespace) -> pd.DataFrame:
    """The runs --plot and --profile compare: one per configuration (a run found twice, e.g.
    a sweep directory inside another, or a job run again, counts once), done runs only; a
    note on stderr says what was left out and why."""
    notes = []
    done = runs[runs["status"].isin(DONE_STATUSES)]
    not_done = runs["status"][~runs["status"].isin(DONE_STATUSES)].value_counts()
    if len(not_done):
        counts = ", ".join(f"{n} {s}" for s, n in not_done.items())
        notes.append(f"{counts} run(s) left out: not results (resume interrupted ones with resume=<run dir>)")
    unique = one_per_config(done) if "config_id" in done and done["config_id"].notna().all() else done
    if len(unique) < len(done):
        notes.append(
            f"{len(done) - len(unique)} duplicate run(s) left out: same configuration and seed as another run"
            " (the newest counts once; a sweep directory inside another?)"
        )
    why = "no --targets {}=..." if args.targets else "its config has no problem.targets (give --targets {}=...)"
    for problem, n in unique["problem.name"].value_counts().sort_index().items():
        if problem not in targets:
            notes.append(f"{problem}: {n} run(s) in the plot but not in the table: {why.format(problem)}")
    for line in notes:
        print(f"note: {line}", file=sys.stderr)
    return unique


def _plots(args: argparse.Namespace, roots: list[Path], df: pd.DataFrame) -> int:
    """--plot and --profile: the time-to-target table, then the figures."""
    from higbench.results.plot import plot_curves, plot_profile, profile_taus

    targets = _targets(args, df)
    runs, curves = _load(args, roots, all_targets(targets), curves=True)
    runs = _comparable(_filter(_with_names(runs, args), args), targets, args)
    if not targets:
        print("note: no targets: no problem here has problem.targets in its config (give --targets)", file=sys.stderr)
    times = time_to_target(runs, targets)
    horizons = times.drop_duplicates("problem").set_index("problem")["horizon_s"] if len(times) else {}
    print(
        "\ntime to target (training clock, median over seeds; '- (k/n)': fewer than half of n seeds"
        " reached it"
        + "".join(f"; {p}: mixed budgets, only the first {h:g} s count" for p, h in dict(horizons).items() if h != float("inf"))
        + ")"
    )
    print(format_table(times, with_ratio=bool(args.profile)))
    if args.plot:
        print(f"curves: {plot_curves(runs, curves, args.plot)}")
    if args.profile and len(times):
        pairs = len(times[["problem", "target"]].drop_duplicates())
        taus = profile_taus(times)
        rho = performance_profile(times, taus)
        for name in rho.columns:
            at = {t: float(performance_profile(times, [t])[name].iloc[0]) for t in (1.0, 2.0, 4.0)}
            print(f"rho {name}: " + ", ".join(f"tau={t:g}: {v:.2f}" for t, v in at.items()))
        print(f"profile: {plot_profile(rho, args.profile, pairs)}")
    return 0


def _league(args: argparse.Namespace, roots: list[Path]) -> int:
    """--league: the scores of the runs (targets from their problem configs)."""
    from higbench.results.league import all_spaces, format_league

    args.figure_runs = True  # the league's runs are launched as the figures' are (higbench.jobs.launch)
    runs, curves = _load(args, roots, None, curves=True)
    runs = _filter(_with_names(runs, args), args)
    print(format_league(runs, curves, all_spaces()))
    return 0


def _spectrum(args: argparse.Namespace, df: pd.DataFrame, roots: list[Path]) -> int:
    """--spectrum: one panel per selected run that recorded a spectrum; exit 2 if none did."""
    from higbench.results.plot import plot_spectrum
    from higbench.results.spectrum import read_spectrum

    order = [c for c in ("problem.name", "setting", "path") if c in df]
    spectra = []
    for _, row in (df.sort_values(order) if len(df) else df).iterrows():
        try:
            run = read_spectrum(row["path"])
        except (OSError, ValueError) as exc:  # corrupt, refused (UnreadableRunFile is an OSError), half-written
            print(f"note: --spectrum: {row['path']}: left out ({exc})", file=sys.stderr)
            continue
        if run is not None:
            path = _relative(pd.Series([str(row["path"])]), roots).iloc[0]
            spectra.append((f"{row['problem.name']} {row['setting']}: {path}", run))
    if not spectra:
        why = f"none of the {len(df)} selected runs recorded a spectrum"
        why += " (GN, HIG and LM runs record one; other optimizers and older files do not)"
        print(f"higbench-results: error: --spectrum {args.spectrum}: {why}", file=sys.stderr)
        return 2
    if len(spectra) > MAX_PANELS:
        print(f"note: --spectrum: {len(spectra)} runs; the first {MAX_PANELS} drawn (narrow with --problem/--optimizer)")
    print(f"spectrum: {plot_spectrum(spectra[:MAX_PANELS], args.spectrum)}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``higbench-results``; piped into ``head``, it stops quietly when the reader leaves."""
    with quiet_broken_pipe():
        return _main(argv)


def _main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    roots = [Path(r) for r in args.roots]
    thresholds = tuple(args.threshold) if args.threshold else None  # None: each run's problem's targets
    try:
        df = _with_names(_load(args, roots, thresholds), args)
        total = len(df)
        error = _check_filters(args, df)
        if error:
            print(f"higbench-results: error: {error}", file=sys.stderr)
            return 2
        df = _filter(df, args)
        if args.spectrum:
            _summary_line(df, total, roots, args)
            code = _spectrum(args, df, roots)
            if code or not (args.plot or args.profile):
                return code
        if args.league:
            return _league(args, roots)
        if args.plot or args.profile:
            if not args.spectrum:
                _summary_line(df, total, roots, args)
            return _plots(args, roots, df)
        if args.best or args.best_seed:
            runs, df = df, _best(df, args)
        elif args.metric in df:
            df = df.sort_values(["problem.name", "optimizer.name", "budget", args.metric], na_position="last")
    except (FileNotFoundError, KeyError, ValueError) as exc:
        print(f"higbench-results: error: {exc.args[0] if isinstance(exc, KeyError) else exc}", file=sys.stderr)
        return 2
    if args.csv:
        df.to_csv(args.csv, index=False)
    if args.best and not args.best_seed:
        _summary_line(runs, total, roots, args)
        print(f"{len(df)} best setting(s), one per (problem, setup, budget): the lowest median {args.metric} over its seeds")
        if len(df):
            _print_settings(df, args)
        return 0
    _summary_line(df, total, roots, args)
    if not len(df):
        return 0
    _print_table(df, roots, args)
    return 0


def _summary_line(df: pd.DataFrame, total: int, roots: list[Path], args: argparse.Namespace) -> None:
    counts = df["status"].value_counts().to_dict() if len(df) else {}
    left_out = 0 if args.figure_runs else sum(under_figure_runs(p, roots) for p in find_run_files(roots, args.pattern))
    print(
        f"{len(df)} of {total} runs under {', '.join(map(str, roots))}"
        + (f" ({', '.join(f'{n} {s}' for s, n in counts.items())})" if counts else "")
        + (
            f"; {left_out} run(s) launched by `make figures` or `higbench-league` left out (under figures-runs/; --figure-runs)"
            if left_out
            else ""
        )
    )


FIRST_LINE = (
    "the first line, 'N of M runs under ROOT': the runs kept by --problem/--optimizer/--status of the M run files"
    " found, by status"
)
# What each column of the tables means: printed under a table for the columns it shows.
LEGEND = {
    "status": "completed (its budget ran out), diverged (loss NaN/inf), interrupted, failed, running or corrupt",
    "setup": "every key that changes a result except the learning rate and the batch size, which --best selects over",
    "setting": "the setup with the chosen learning rate and batch size: the runs of one setting are its seeds",
    "budget": "the run's budget: training-clock seconds and/or updates",
    "steps": "updates made within the budget",
    "train_time_s": "training clock at the end, seconds (evaluations left out)",
    "final_test_loss": "test loss at the last evaluation",
    "best_test_loss": "lowest test loss at any evaluation",
    "overrides": "the command-line overrides of the run",
    "seeds": "completed and diverged runs of the setting: the median and range are over these (a diverged seed as inf)",
    "diverged_seeds": "seeds whose loss turned NaN/inf: counted in the median as the worst value (inf)",
    "runs_not_completed": "the setting's other runs (interrupted, failed, running): not in the median",
    "busy": f"under {BUSY_SHARE} of a core (the run's CPU share, with the load at its end): its update count and loss"
    " are not what an idle machine gives",
    "busy_seeds": f"seeds that had under {BUSY_SHARE} of a core: their update counts and losses are not an idle machine's",
    "cond_kept_median": "median over updates of the condition number of the part of J the step inverts"
    " (largest over smallest kept singular value)",
    "cond_kept_max": "largest over updates of that condition number",
    "sv_dropped_mean": "mean over updates of the singular values the truncation dropped",
}


def _legend(columns: list[str], metric: str) -> list[str]:
    """One line per column shown that does not explain itself."""
    lines = []
    for column in columns:
        base, _, stat = column.rpartition("_")
        if column in LEGEND:
            text = LEGEND[column]
        elif column.startswith("time_to_"):
            text = f"training clock (s) when the test loss first fell to {column[len('time_to_') :]} or below (NaN: never)"
        elif base == metric and stat in ("median", "min", "max"):
            what = {"median": "median", "min": "least", "max": "greatest"}[stat]
            text = f"{what} {metric} over the seeds ({LEGEND.get(metric, metric)})"
        else:
            continue
        lines.append(f"  {column}: {text}")
    return lines


def _print_settings(df: pd.DataFrame, args: argparse.Namespace) -> None:
    """--best: one row per best setting, then the legend of its columns."""
    m = args.metric
    shown = ["problem.name", "optimizer.name", "setup", "setting", "optimizer.lr", "batch_size", "budget", "seeds"]
    shown += [f"{m}_median", f"{m}_min", f"{m}_max"]
    optional = ["diverged_seeds", "runs_not_completed", "busy_seeds"]  # shown where some row has one
    shown += [c for c in optional if c in df and pd.to_numeric(df[c], errors="coerce").fillna(0).gt(0).any()]
    times = [threshold_column(t) for t in args.threshold] if args.threshold else _time_columns(df)
    conditioning = [c for c in CONDITIONING_SHOWN if c in df and pd.to_numeric(df[c], errors="coerce").notna().any()]
    shown += ["steps", "train_time_s", *times, *conditioning, *[c for c in (args.columns or "").split(",") if c]]
    table = df[[c for c in dict.fromkeys(shown) if c in df.columns]]
    with pd.option_context(
        "display.max_rows", None, "display.max_columns", None, "display.width", 250, "display.float_format", "{:.4g}".format
    ):
        print(table.to_string(index=False))
    print("columns (steps, train_time_s and the times: medians over the seeds):")
    print("\n".join(_legend(list(table.columns), m)))
    print(f"  ({FIRST_LINE})")


def _busy_marker(df: pd.DataFrame) -> pd.Series | None:
    """'0.33 (load 12)' for runs that had under BUSY_SHARE of a core, '' for the rest; None when none did."""
    if "env.cpu_share" not in df:
        return None
    share = pd.to_numeric(df["env.cpu_share"], errors="coerce")
    busy = share < BUSY_SHARE
    if not busy.any():
        return None
    load = df["env.load_at_finish"].map(busy_load) if "env.load_at_finish" in df else pd.Series(None, index=df.index)
    text = [f"{s:.2f}" + (f" (load {x:.0f})" if x is not None and x == x else "") for s, x in zip(share, load)]
    return pd.Series(text, index=df.index).where(busy, "")


def _print_table(df: pd.DataFrame, roots: list[Path], args: argparse.Namespace) -> None:
    times = [threshold_column(t) for t in args.threshold] if args.threshold else _time_columns(df)
    # GN/HIG/LM runs: how ill-conditioned their steps were (shown when some run recorded it)
    conditioning = [c for c in CONDITIONING_SHOWN if c in df and pd.to_numeric(df[c], errors="coerce").notna().any()]
    summary = [*SUMMARY_COLUMNS]
    if "setup" in df:  # --best: what each row is the best of
        summary.insert(summary.index("optimizer.name") + 1, "setup")
    shown = summary + times + conditioning + [c for c in (args.columns or "").split(",") if c]
    if args.best and args.metric not in shown:
        shown.insert(shown.index("final_test_loss"), args.metric)
    missing = [c for c in shown if c not in df.columns]
    if args.columns and any(c in missing for c in args.columns.split(",")):
        print(f"higbench-results: note: no column(s) {[c for c in args.columns.split(',') if c in missing]}", file=sys.stderr)
    table = df[[c for c in dict.fromkeys(shown) if c in df.columns]].copy()
    busy = _busy_marker(df)
    if busy is not None:  # a marker on runs of a busy machine
        table.insert(table.columns.get_loc("status") + 1 if "status" in table else len(table.columns), "busy", busy)
    table["path"] = _relative(table["path"].astype(str), roots)
    if args.width and "overrides" in table:
        table["overrides"] = (
            table["overrides"].fillna("").map(lambda s: s if len(s) <= args.width else s[: args.width - 3] + "...")
        )
    with pd.option_context(
        "display.max_rows", None, "display.max_columns", None, "display.width", 250, "display.float_format", "{:.4g}".format
    ):
        print(table.to_string(index=False))
    legend = _legend(list(table.columns), args.metric)
    if legend:
        print("columns:\n" + "\n".join(legend))
        print(f"  ({FIRST_LINE})")
    errors = df[df["error"].fillna("") != ""] if "error" in df else df.iloc[0:0]
    for _, row in errors.iterrows():
        print(f"note: {row['path']}: {row['status']}: {row['error']}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
