"""What the probe scripts that train through the CLI share: their command-line options, one
job-list multirun of their runs, and the runs read back (``scripts/probe_poisson_data.py``,
``scripts/probe_precision.py``)."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]


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


def launch(jobs: list[list[str]], sweep_dir: Path, n_jobs: int, extra: list[str] = ()) -> None:
    """One multirun of ``jobs``, each with the ``extra`` overrides, through the job-list sweeper
    (never into an existing folder)."""
    if sweep_dir.exists():
        raise SystemExit(f"{sweep_dir} exists: its runs are kept; use --report-only or another --root")
    sweep_dir.parent.mkdir(parents=True, exist_ok=True)
    jobs_file = sweep_dir.with_suffix(".jobs.json")
    jobs_file.write_text(json.dumps([[*job, *extra] for job in jobs], indent=1))
    from higbench.jobs import multirun_command  # the figures' job-list multirun, one thread per run

    cmd = multirun_command(jobs_file, sweep_dir, ["hydra/launcher=joblib", f"hydra.launcher.n_jobs={n_jobs}"])
    print(f"{time.strftime('%H:%M:%S')} {len(jobs)} runs -> {sweep_dir}", file=sys.stderr, flush=True)
    subprocess.run(cmd, cwd=ROOT, check=True)


def runs_under(root: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The index of the run files under ``root`` and their curves."""
    from higbench.results.index import load_runs

    return load_runs(root, curves=True)
