"""Compare two output directories of `python -m higbench.figures` drawn from the same run files.

    python tests/figures/compare_outputs.py BEFORE AFTER

Checks: the same figure/table ids and output files; each table's CSV and markdown; each
figure's plotted data (<id>.csv); each sidecar's runs, budgets and notes; each claim's
measured value and verdict (and, reported separately, its explanation, cause, budget and
seeds); REPORT.md's table rows. Prints every difference; exit 1 if ids, files, tables,
plotted data, runs or claims' measured values/verdicts differ.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd


def sidecars(d: Path) -> dict[str, dict]:
    out = {}
    for p in sorted(d.glob("*.json")):
        info = json.loads(p.read_text())
        if isinstance(info, dict) and "id" in info:
            out[info["id"]] = info
    return out


def same_frame(a: pd.DataFrame, b: pd.DataFrame) -> str | None:
    if list(a.columns) != list(b.columns) or a.shape != b.shape:
        return f"columns/shape {list(a.columns)} {a.shape} vs {list(b.columns)} {b.shape}"
    for col in a.columns:
        x, y = a[col], b[col]
        if pd.api.types.is_numeric_dtype(x) and pd.api.types.is_numeric_dtype(y):
            if not np.allclose(x.to_numpy(float), y.to_numpy(float), rtol=1e-12, atol=0, equal_nan=True):
                return f"column {col!r} values differ"
        elif list(x.fillna("<nan>").astype(str)) != list(y.fillna("<nan>").astype(str)):
            return f"column {col!r} differs: {list(x.astype(str))[:6]} vs {list(y.astype(str))[:6]}"
    return None


def compare(before: Path, after: Path) -> tuple[list[str], list[str]]:
    errors, notes = [], []
    sa, sb = sidecars(before), sidecars(after)
    if list(sa) != list(sb):
        errors.append(f"ids: {sorted(sa)} vs {sorted(sb)}")
    fa = {p.name for p in before.iterdir()}
    fb = {p.name for p in after.iterdir()}
    if fa != fb:
        errors.append(f"files only before: {sorted(fa - fb)}, only after: {sorted(fb - fa)}")
    for fid in sorted(set(sa) & set(sb)):
        a, b = sa[fid], sb[fid]
        for key in ("title", "kind", "preset", "budgets", "notes"):
            if a.get(key) != b.get(key):
                (errors if key in ("kind", "preset", "budgets") else notes).append(
                    f"{fid}: {key}: {a.get(key)!r} vs {b.get(key)!r}"
                )
        runs = lambda info: [(r["sweep"], r["seed"], r["identity"], r["status"], r["path"]) for r in info["runs"]]  # noqa: E731
        if runs(a) != runs(b):
            errors.append(f"{fid}: runs differ")
        if ("error" in a) != ("error" in b):
            errors.append(f"{fid}: plot error before {'error' in a}, after {'error' in b}: {b.get('error', a.get('error'))}")
        if a.get("reference") != b.get("reference"):
            errors.append(f"{fid}: reference section differs")
        ca, cb = {c["id"]: c for c in a.get("claims", [])}, {c["id"]: c for c in b.get("claims", [])}
        if list(ca) != list(cb):
            errors.append(f"{fid}: claim ids {list(ca)} vs {list(cb)}")
        for cid in set(ca) & set(cb):
            for key in ("measured", "verdict", "figures", "statement", "paper"):
                if ca[cid].get(key) != cb[cid].get(key):
                    errors.append(f"{cid}: {key}: {ca[cid].get(key)!r} vs {cb[cid].get(key)!r}")
            for key in ("why", "cause", "budget", "seeds"):
                if ca[cid].get(key) != cb[cid].get(key):
                    notes.append(f"{cid}: {key}: {ca[cid].get(key)!r} vs {cb[cid].get(key)!r}")
        csv_a, csv_b = before / f"{fid}.csv", after / f"{fid}.csv"
        if csv_a.is_file() and csv_b.is_file():
            if a["kind"] == "table":
                why = same_frame(pd.read_csv(csv_a, index_col=0), pd.read_csv(csv_b, index_col=0))
            else:  # plotted points: the same rows, in any order
                da, db = (pd.read_csv(p).astype(str) for p in (csv_a, csv_b))
                why = same_frame(*(x.sort_values(list(x.columns)).reset_index(drop=True) for x in (da, db)))
                if not why and not da.equals(db):
                    notes.append(f"{fid}.csv: the same rows in another order")
            if why:
                errors.append(f"{fid}.csv: {why}")
        md_a, md_b = before / f"{fid}.md", after / f"{fid}.md"
        if md_a.is_file() and md_b.is_file() and md_a.read_text() != md_b.read_text():
            errors.append(f"{fid}.md differs")
    rows = lambda d: [ln for ln in (d / "REPORT.md").read_text().splitlines() if not ln.startswith("Generated")]  # noqa: E731
    if rows(before) != rows(after):
        diff = [f"  - {x}\n  + {y}" for x, y in zip(rows(before), rows(after)) if x != y]
        notes.append("REPORT.md lines differ:\n" + "\n".join(diff))
    return errors, notes


if __name__ == "__main__":
    errs, nts = compare(Path(sys.argv[1]), Path(sys.argv[2]))
    for n in nts:
        print("note:", n)
    for e in errs:
        print("DIFFERENCE:", e)
    print(f"{len(errs)} difference(s), {len(nts)} note(s)")
    sys.exit(1 if errs else 0)
