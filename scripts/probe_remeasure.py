"""Measure again, from the committed results, the claims whose measurement this revision changed.

    python scripts/probe_remeasure.py                 # docs/results: rewrite those rows, redraw, then REPORT.md
    python scripts/probe_remeasure.py --dry-run       # print the new rows only
    python scripts/probe_remeasure.py --no-redraw     # the rows and REPORT.md, not the pictures

The run files behind docs/results are not committed; their plotted data are (<id>.csv: every
evaluation of a run up to 1,000 of them). ``higbench.figures.committed`` rebuilds the runs from
those files and the claim's own measurement code runs on them, as a fresh build would on the run
files. Where the plotted data count time only (oscillator runs evaluate by time), the update
counts come from the row that was measured on the run files (stated in the row). A claim whose
measurement needs more than the plotted data hold gets only the values that can be measured
added to its stored row (``EXTEND``). The figures drawn from curves alone are drawn again by this
revision's plotting code (``committed.redrawable()``; their plotted data come out the same). A fresh
`python -m higbench.figures` build measures every claim from its run files and replaces all of this.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from higbench.figures import registry
from higbench.figures.committed import extend, redraw, redrawable, remeasure, store
from higbench.figures.report import write_report
from higbench.paper.ablation import gn_small_tau_by_time

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"
# Claims whose measurement changed and which the plotted data hold entirely.
REMEASURE = ("toy-6", "poi-1", "poi-1a", "poi-3", "poi-3a", "poi-4", "poi-4a", "poi-5", "spd-2")
# Claims this revision adds (the paper's statements no row tested before), measured on the same data.
ADDED = (
    "toy-7",
    "osc-7",
    "poi-6",
    "dip-9",
    "cnn-3",
    "abl-5",
    "spd-6",
    "osc-9",
    "osc-10",
    "poi-7",
    "dip-10",
    "cnn-4",
    "spd-7",
    "spd-8",
)
# Claims measured on the update axis of runs that were evaluated by time: (figure, optimizer sweeps) whose update
# counts the stored row holds, by batch size (value names of the row).
BY_UPDATES = {"osc-5": ("fig2c", {("hig", "b_lo"): "hig_lo_updates", ("hig", "b_hi"): "hig_hi_updates"} | {
    ("gn", "b_lo"): "gn_lo_updates", ("gn", "b_hi"): "gn_hi_updates"})}  # fmt: skip
# Claims measured on runs evaluated by time that read one run's update count: (figure, sweep, optimizer, value name).
BY_RUN_UPDATES = {"osc-3": ("fig2b", "best", "hig", "hig_updates")}
# Claims that get values added: (the measurement's function for them, what they are).
EXTEND = {"abl-3": (gn_small_tau_by_time, "GN's smallest-τ run at half of its training time and at its end")}


def stored_row(out_dir: Path, claim) -> dict:
    info = json.loads((out_dir / f"{claim.figures[0]}.json").read_text())
    return next(c for c in info["claims"] if c["id"] == claim.id)


def update_counts(out_dir: Path, cid: str) -> dict[str, int]:
    """Run file -> updates made, from the stored row of ``cid`` (``BY_UPDATES``)."""
    fid, names = BY_UPDATES[cid]
    claim = registry.claims()[cid]
    values = stored_row(out_dir, claim)["values"]
    runs = json.loads((out_dir / f"{fid}.json").read_text())["runs"]
    counts = {}
    for (sweep, side), name in names.items():
        b = values[side]
        path = next(r["path"] for r in runs if r["sweep"] == sweep and f"batch_size={b}" in r["overrides"])
        counts[path] = int(values[name])
    return counts


def run_update_count(out_dir: Path, cid: str) -> dict[str, int]:
    """Run file -> updates made, for the one run ``BY_RUN_UPDATES`` names, from the stored row of ``cid``."""
    fid, sweep, optimizer, name = BY_RUN_UPDATES[cid]
    values = stored_row(out_dir, registry.claims()[cid])["values"]
    runs = json.loads((out_dir / f"{fid}.json").read_text())["runs"]
    path = next(r["path"] for r in runs if r["sweep"] == sweep and f"optimizer={optimizer}" in r["overrides"])
    return {path: int(values[name])}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=RESULTS, help="a results directory (default: docs/results)")
    p.add_argument("--dry-run", action="store_true", help="print the rows, write nothing")
    p.add_argument("--no-redraw", action="store_true", help="leave the pictures as they are")
    args = p.parse_args(argv)
    claims = registry.claims()
    rows = [remeasure(args.out, claims[cid]) for cid in REMEASURE + ADDED]
    rows += [remeasure(args.out, claims[cid], update_counts(args.out, cid)) for cid in BY_UPDATES]
    rows += [remeasure(args.out, claims[cid], run_update_count(args.out, cid)) for cid in BY_RUN_UPDATES]
    rows += [extend(args.out, claims[cid], fn, what) for cid, (fn, what) in EXTEND.items()]
    for row in rows:
        print(f"{row['id']}: {row['verdict']} ({row['rule_verdict']} by the rule): {row['measured']}")
        if not args.dry_run:
            store(args.out, row)
    if not args.dry_run and not args.no_redraw:
        for fid in redrawable():
            print(redraw(args.out, fid))
    if not args.dry_run:
        print(write_report(args.out, list(registry.figures())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
