"""What the probe scripts that train through the CLI share: their command-line options, their
runs launched through the one launcher and reuse rule (``higbench.jobs.run_missing``: a run
already under ``--root`` with the same identity is reused, a stopped one resumed), and the runs
read back (``scripts/probe_poisson_data.py``, ``scripts/probe_precision.py``)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from higbench.jobs import Job, parse_overrides, run_missing  # noqa: E402


def parser(description: str, name: str) -> argparse.ArgumentParser:
    """--jobs, --root (default outputs/probes/NAME), --out (docs/results/probes), --set, --report-only."""
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--jobs", type=int, default=2, help="runs at once, one thread each")
    p.add_argument("--root", type=Path, default=ROOT / "outputs" / "probes" / name)
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "probes")
    p.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="more overrides of every run (device=cuda)")
    p.add_argument("--report-only", action="store_true")
    return p


def parse(p: argparse.ArgumentParser, script: str, argv=None) -> argparse.Namespace:
    """The options; --report-only without runs under --root is an error (one line, exit 2)."""
    args = p.parse_args(argv)
    if args.report_only and not args.root.is_dir():
        p.error(f"--root {args.root}: no runs there to report on (train them first: python scripts/{script})")
    return args


def as_job(overrides: list[str], name: str, parent: Job | None = None) -> Job:
    """A probe run as a ``higbench.jobs.Job`` (``parent``: it starts from that run's final weights)."""
    values = parse_overrides(overrides)
    return Job("probe", f"{name}: {' '.join(overrides)}", values, int(values.get("seed", 0)), parent=parent)


def launch(jobs: list[Job], root: Path, n_jobs: int) -> None:
    """Run the jobs not done under ``root`` (``jobs.run_missing``); exit with the ones that still are not."""
    print(f"{time.strftime('%H:%M:%S')} {len(jobs)} runs under {root}", file=sys.stderr, flush=True)
    missing = run_missing(jobs, root, n_jobs=n_jobs, log=lambda text: print(text, file=sys.stderr, flush=True))
    if missing:
        raise SystemExit(f"{len(missing)} run(s) not done under {root}: {', '.join(j.sweep for j in missing)}")


def runs_under(root: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The index of the run files under ``root`` (the launcher's figures-runs/ included) and their curves."""
    from higbench.results.index import load_runs

    return load_runs(root, curves=True, figure_runs=True)
