"""The league's report: the machine it ran on (calibration, CPU share and load per problem and
hardware), the report folder (never another league's), and the scores of a root's tables,
written with the target setting they imply.

    report([root], out, manifest, tuning_seeds)   # league.txt, league.json, runs.csv, profile.png
    scoring_targets(runs, curves)                  # validation target, budget and gates per task
"""

from __future__ import annotations

import json
import math
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from higbench.league import tables
from higbench.league.files import read_json_files, safe_dir, write_text
from higbench.league.protocol import RERUN_ROLE, all_spaces, fail
from higbench.results import league, league_figures
from higbench.results.long_budget import format_long_budget

# -- the machine ------------------------------------------------------------------------------


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


hardware = tables.hardware


def machine(runs: pd.DataFrame) -> list[dict]:
    """Per problem and hardware, what the runs had of the machine: their CPU share (CPU seconds
    over wall seconds per thread; 1 = a core of their own), the 1-minute load average at their end,
    threads, revisions and when they trained. Values that are not what they should be (a file from
    elsewhere) are left out, never a crash."""
    if runs.empty:
        return []

    def column(group: pd.DataFrame, name: str) -> pd.Series:
        return group[name] if name in group else pd.Series(dtype=object)

    def number(group: pd.DataFrame, name: str) -> pd.Series:
        return pd.to_numeric(column(group, name), errors="coerce").dropna()

    groups = []
    where_all = runs["hardware"] if "hardware" in runs else hardware(runs)
    for (problem, where), group in runs.groupby([runs["problem.name"].astype(str), where_all], sort=True):
        share = number(group, "env.cpu_share")
        if "env.load_1min" in group:
            load = number(group, "env.load_1min")
        else:
            load = column(group, "env.load_at_finish").map(tables.load_1min).dropna()
        threads = number(group, "env.torch_threads").astype(int)
        when = [str(v) for v in (*column(group, "started").dropna(), *column(group, "finished").dropna())]
        groups.append({
            "problem": problem, "hardware": where, "runs": len(group),
            "cpu_share_median": round(float(share.median()), 3) if len(share) else None,
            "cpu_share_range": [round(float(share.min()), 3), round(float(share.max()), 3)] if len(share) else None,
            "load_1min_median": round(float(load.median()), 2) if len(load) else None,
            "threads_per_run": sorted({int(t) for t in threads}),
            "revisions": sorted(set(column(group, "env.git_revision").dropna().astype(str).str[:12])),
            "trained": [min(when), max(when)] if when else None,
        })  # fmt: skip
    return groups


def recorded_calibrations(roots: list[Path], out: Path) -> list[dict]:
    """The calibrations earlier league invocations wrote beside their runs (``ROOT/manifests/``,
    or a league.json they left under the root, as a run on another machine brings back), each
    with where it was read (the report's own ``out`` left out). Never through a link, never a FIFO;
    a file that is not a manifest is skipped with one line."""
    found = []
    for root in roots:
        manifests = sorted((root / "manifests").glob("*.json")) if safe_dir(root / "manifests") else []
        paths = [p for p in sorted({*manifests, *root.rglob("league.json")}) if not p.parent.resolve() == out.resolve()]
        for path, content in read_json_files(paths):
            entries = content.get("calibration") if isinstance(content, dict) else None
            if not isinstance(entries, list):
                if entries is not None:
                    print(f"[league] skipped {path}: its calibration is not a list", file=sys.stderr)
                continue
            found += [{**entry, "file": str(path.relative_to(root))} for entry in entries if isinstance(entry, dict)]
    return found


SPEED_CHANGE = 1.25  # one machine's sittings varied by up to 1.2x from their median in the CPU league
LATEST = 5  # calibrations compared with: the latest few, so that one noisy sitting neither hides nor raises a change


def speed_change(now: dict, earlier: list[dict]) -> str | None:
    """One line when this sitting's calibration (``now``) is more than ``SPEED_CHANGE`` times
    faster or slower than the median of the latest ``LATEST`` recorded under the roots
    (``earlier``), else None: the sign that the machine changed between sittings (the CPU
    league's second machine trained 1.5-3.3x faster than its first, same class, same code), so
    that a task trained across them compares times at unequal speed."""

    def matmul(entry: dict) -> float:
        value = entry.get("matmul_50x256_s")
        return float(value) if isinstance(value, int | float) and not isinstance(value, bool) and value > 0 else math.nan

    latest = sorted((str(e.get("when", "")), matmul(e)) for e in earlier if math.isfinite(matmul(e)))[-LATEST:]
    if not latest or not math.isfinite(matmul(now)):
        return None
    median = float(np.median([seconds for _, seconds in latest]))
    ratio = matmul(now) / median
    if 1 / SPEED_CHANGE <= ratio <= SPEED_CHANGE:
        return None
    return (f"this machine's calibration ({1e3 * matmul(now):.1f} ms) is {ratio:.2f}x the median of the latest {len(latest)} "
            f"recorded under the roots ({1e3 * median:.1f} ms, the last at {latest[-1][0]}): another machine, or the same "
            "under other load; a task trained across both compares times at unequal speed (league.txt's hardware line "
            "counts the machines that name themselves)")  # fmt: skip


# -- outputs ----------------------------------------------------------------------------------


PROTOCOL_KEYS = ("trials", "studies", "seeds", "seconds", "references", "target_seconds")  # per problem; another
# optimizer only adds rows


def check_out(out: Path, root: Path, protocol: dict, in_place: bool = False) -> None:
    """Before anything is created: ``--out`` is a folder (or absent), and if it holds a league's
    report, that league's (the same root, or ``in_place``: ``--out`` is itself a ``--root``, a
    published league extended or re-scored; the same protocol for every problem both name).
    Another league's output is never overwritten silently."""
    if os.path.lexists(out) and (os.path.islink(out) or not out.is_dir()):
        fail(f"--out {out}: {'a symbolic link' if os.path.islink(out) else 'an existing file'}; --out names a folder")
    if not out.is_dir() or not any(out.iterdir()):
        return
    manifest = next((c for _, c in read_json_files([out / "league.json"])), None)
    theirs = manifest.get("protocol") if isinstance(manifest, dict) else None
    if not isinstance(theirs, dict):
        fail(f"--out {out}: holds files but no league report of this command (league.json with a protocol); give another --out")
    if theirs.get("root") != protocol["root"] and not in_place:  # in place: a league extended or re-scored from its tables
        fail(f"--out {out}: holds the report of the league of another root ({theirs.get('root')}); give another --out")
    for problem, settings in (protocol.get("problems") or {}).items():
        old = (theirs.get("problems") or {}).get(problem)
        old = old if isinstance(old, dict) else {}
        diff = [f"{k} {old[k]} -> {settings[k]}" for k in PROTOCOL_KEYS if k in old and k in settings and old[k] != settings[k]]
        if diff:
            diff = ", ".join(diff)
            fail(f"--out {out}: holds a league of another protocol for {problem} ({diff}); give another --out or --root")


def write_report(out: Path, text: str, manifest: dict, scored: pd.DataFrame, reached: pd.DataFrame) -> None:
    """league.txt, league.json, runs.csv and the figures (every seed's final loss; the profile)
    into ``out`` (links refused)."""
    safe_dir(out, create=True)
    # drawn apart, then moved in: a link planted in out is replaced, not written through
    plots = out / f".plots-{os.getpid()}"
    shutil.rmtree(plots, ignore_errors=True)
    plots.mkdir()
    try:
        drawn, colours = [], {}
        if len(scored) and league.TEST_METRIC in scored:  # every seed's final loss per task and setting
            table = league.final_loss_table(scored)
            colours = league_figures.setting_colours(table)
            drawn.append(league_figures.plot_final_losses(table, plots, colours))
        if len(reached):  # the profile needs targets (a problem of your own may declare none)
            drawn.append(league_figures.plot_profile(reached, colours, plots))
        for path in drawn:
            os.replace(path, out / path.name)
    finally:
        shutil.rmtree(plots, ignore_errors=True)
    if len(scored):
        columns = ["task", "league_setting", "seed", "status", "final_val_loss", "final_test_loss", "steps", "train_time_s",
                   "config_id", "run", "hardware"]  # fmt: skip
        rows = scored[[c for c in columns if c in scored]].sort_values(["task", "league_setting", "seed"])
        write_text(out / "runs.csv", rows.to_csv(index=False))
    write_text(out / "league.txt", text)
    write_text(out / "league.json", json.dumps(manifest, indent=1, default=str) + "\n")


def found_targets(runs: pd.DataFrame, curves: pd.DataFrame) -> pd.DataFrame:
    """The target setting of the tables' reruns (``league.targets_from_reruns``; empty without)."""
    if "league_role" not in runs or not (runs["league_role"] == RERUN_ROLE).any():
        return league.no_targets()
    return league.targets_from_reruns(runs[runs["league_role"] == RERUN_ROLE], curves)


def scoring_targets(runs: pd.DataFrame, curves: pd.DataFrame) -> tuple[dict, dict, dict]:
    """(validation target per task, budget per task, held-out tasks per problem) from the tables'
    target-setting reruns, so a report from the tables alone scores as the league did. A task is
    judged within its problem's budget (its runs ran that long); empty without reruns."""
    found = found_targets(runs, curves).set_index("task")
    if found.empty:
        return {}, {}, {}
    reruns = runs[runs["league_role"] == RERUN_ROLE]
    problem_of = dict(zip(reruns["task"], reruns["problem.name"].astype(str), strict=False))
    budgets = {t: float(found["budget_s"].get(problem_of[t], found.loc[t, "budget_s"])) for t in found.index}
    held_out: dict[str, list[str]] = {}
    for task in found.index:
        if task != problem_of[task]:
            held_out.setdefault(problem_of[task], []).append(task)
    return {t: float(v) for t, v in found["target"].items()}, budgets, held_out


def tuning_counts(runs: pd.DataFrame) -> str:
    """The league's tuning trials in the tables, per problem and optimizer (studies x trials when
    a tuning is whole; fewer while a piece is still under way). Only finished trials (completed or
    diverged) count as done; a trial a stopped sitting left unfinished is counted apart, as one the
    next sitting resumes."""
    from higbench.results.index import DONE_STATUSES

    tune = runs[runs["league_role"] == "tune"] if "league_role" in runs else runs.iloc[:0]
    if tune.empty:
        return "tuning: no league tuning trials in the tables yet"
    finished = tune["status"].isin(DONE_STATUSES) if "status" in tune else pd.Series(True, index=tune.index)
    lines = ["tuning trials in the tables (per optimizer: trials done; studies x trials when whole):"]
    for problem, group in tune[finished].groupby("problem.name", sort=True):
        counts = group.groupby("optimizer.name").size()
        lines.append(f"  {problem}: {len(group)} trials: " + ", ".join(f"{o} {n}" for o, n in counts.items()))
    for problem, group in tune[~finished].groupby("problem.name", sort=True):
        counts = group.groupby("optimizer.name").size()
        lines.append(
            f"  {problem}: {len(group)} unfinished (a stopped sitting's; resumed by the next): "
            + ", ".join(f"{o} {n}" for o, n in counts.items())
        )
    return "\n".join(lines)


def tuning_outcomes(runs: pd.DataFrame, curves: pd.DataFrame, targets: dict) -> str:
    """Per problem with a validation target, per optimizer: how many of its completed tuning
    trials reached the target, and the fastest (training clock at the first evaluation at or
    below it): how hard the target was to hit, the luck a tuning had. Empty without targets."""
    tune = runs[(runs["league_role"] == "tune") & (runs["status"] == "completed")] if "league_role" in runs else runs.iloc[:0]
    by_run = dict(tuple(curves.groupby("run", observed=True))) if len(curves) else {}
    lines = []
    for problem, group in tune.groupby("problem.name", sort=True):
        target = targets.get(problem)
        if target is None:
            continue
        seconds = [league.reach(by_run[r], target, "val_loss")[0] if r in by_run else math.inf for r in group["run"]]
        study = pd.to_numeric(group["seed"], errors="coerce") - league.TUNING_SEED_BASE if "seed" in group else 0
        found = pd.DataFrame({"optimizer": group["optimizer.name"].to_numpy(), "s": seconds,
                              "study": np.asarray(study, dtype=float) + np.zeros(len(group))})  # fmt: skip
        found["hit"] = np.isfinite(found["s"])
        per = found.groupby("optimizer").agg(n=("s", "size"), hit=("hit", "sum"), best=("s", "min"))
        per = per.sort_values(["hit", "best"], ascending=[False, True])
        parts = [f"{o} {int(r.hit)} of {int(r.n)}" + (f", {r.best:.3g} s" if r.hit else "") + _per_study(found, o)
                 for o, r in per.iterrows()]  # fmt: skip
        lines.append(f"  {problem} (validation target {target:.3g}): " + "; ".join(parts))
    if not lines:
        return ""
    head = (
        "tuning trials that reached the validation target (of the completed ones), and the fastest, in training-clock "
        "seconds (per study: each study's fastest, the setting one study alone would have chosen; inf: none reached it):"
    )
    return "\n".join([head, *lines])


def _per_study(found: pd.DataFrame, optimizer: str) -> str:
    """' (per study: 0.3, 1.2 s)': each study's fastest trial, when an optimizer had more than one
    study and some trial reached the target: the tuning luck one study alone would have had."""
    mine = found[found["optimizer"] == optimizer]
    best = mine.groupby("study")["s"].min()
    if len(best) < 2 or not np.isfinite(best).any():
        return ""
    return " (per study: " + ", ".join(f"{v:.3g}" for v in best) + " s)"


def report(roots: list[Path], out: Path, manifest: dict, tuning_seeds) -> str:
    """The scores of the roots' tables (``tables.read``: merged when several), written to ``out``."""
    runs, curves = tables.read(roots)
    spaces = all_spaces()
    try:
        targets, budgets, held_out = scoring_targets(runs, curves)
        under_way = league.confirmation_under_way(runs)
        frames = league.league_frames(runs, curves, spaces, tuning_seeds, under_way)
        text = league.format_league(runs, curves, spaces, tuning_seeds, targets, budgets, held_out, frames, under_way)
        long = format_long_budget(league.with_first_losses(runs, curves))
        outcomes = tuning_outcomes(runs, curves, targets)
        text = "\n\n".join([league.format_targets(found_targets(runs, curves)), tuning_counts(runs),
                             *([outcomes] if outcomes else []), text, *([long] if long else [])])  # fmt: skip
        scored, reached, _ = frames
    except ValueError as exc:
        fail(str(exc))
    manifest["machine"] = machine(runs)
    manifest["recorded_calibration"] = recorded_calibrations(roots, out)
    lines = ["machine: " + ", ".join(f"{k} {v}" for k, v in group.items()) for group in manifest["machine"]]
    text = "\n".join([*lines, text])
    write_report(out, text, manifest, scored, reached)
    return text
