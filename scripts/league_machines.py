"""Which machine trained which of a league's runs, and how fast each machine trained them.

    python scripts/league_machines.py docs/results/league/cpu --machine-change 2026-11-30T04:32:04+0000 \
        --out docs/results/league/machines.txt

A league's tables label every run's hardware by class ("CPU, 2 cores"), and two machines of one
class can differ in speed. Given the time a new machine took over (its boot), this splits the runs
and the calibrations that the sittings recorded in their manifests (``ROOT/manifests/``) into
before and after, and prints:

* the calibrations on each side (one fixed benchmark per sitting start and end);
* how many runs each phase (``league_role``) of each problem trained on each side;
* for every setting trained on both sides (same overrides but seed, budget and evaluation
  interval), its median updates per second of training clock on each side and their ratio,
  summarised per problem and optimizer (each setting with ``--every-setting``, with the revisions
  beside: the same training code on the same problem, so the ratio is the machines');
* per problem and optimizer, how many tuning trials ran on each side: a tuning that straddles
  the change compared trials at unequal speed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from higbench.league import driver  # noqa: E402
from higbench.league.files import read_json_files  # noqa: E402

NOT_THE_SETTING = ("seed=", "budget.seconds=", "eval_every=", "progress=", "threads=")  # same setting, another run


def setting_key(overrides: str) -> str:
    """A run's overrides without those that differ between runs of one setting."""
    return " ".join(sorted(t for t in str(overrides).split() if not t.startswith(NOT_THE_SETTING)))


def side(when: pd.Series, change: pd.Timestamp) -> pd.Series:
    """'before' / 'after' the machine change, per timestamp."""
    return (pd.to_datetime(when, utc=True, format="ISO8601") >= change).map({False: "before", True: "after"})


def rates_across_the_change(runs: pd.DataFrame, change: pd.Timestamp) -> pd.DataFrame:
    """Per (problem, optimizer, setting) with completed runs on both sides: median updates per
    training-clock second on each side, run counts, the ratio after/before and the revisions."""
    done = runs[(runs["status"] == "completed") & (pd.to_numeric(runs["train_time_s"], errors="coerce") > 0)].copy()
    done["rate"] = done["steps"] / done["train_time_s"]
    done["side"] = side(done["started"], change)
    done["setting"] = done["overrides"].map(setting_key)
    keys = ["problem.name", "optimizer.name", "setting"]

    def revisions(column: pd.Series) -> str:
        return ",".join(sorted(set(column.astype(str).str[:8])))

    per = done.groupby([*keys, "side"]).agg(rate=("rate", "median"), runs=("rate", "size"),
                                             revision=("env.git_revision", revisions))  # fmt: skip
    wide = per.unstack("side").dropna()
    if wide.empty:
        return pd.DataFrame(columns=[*keys, "before", "after", "ratio", "runs before", "runs after", "revisions"])
    out = pd.DataFrame({
        "before": wide[("rate", "before")], "after": wide[("rate", "after")],
        "runs before": wide[("runs", "before")].astype(int), "runs after": wide[("runs", "after")].astype(int),
        "revisions": wide[("revision", "before")] + " | " + wide[("revision", "after")],
    })  # fmt: skip
    out["ratio"] = out["after"] / out["before"]
    return out.reset_index().sort_values(["problem.name", "ratio"])


def calibrations(root: Path, change: pd.Timestamp) -> pd.DataFrame:
    """Every calibration the root's manifests recorded (each once), with its side."""
    rows = []
    paths = sorted((root / "manifests").glob("*.json"))
    for _, manifest in read_json_files(paths):
        for c in manifest.get("calibration", []) if isinstance(manifest, dict) else []:
            rows.append({"when": c.get("when"), "matmul_ms": 1e3 * c.get("matmul_50x256_s", float("nan")),
                         "svd_ms": 1e3 * c.get("svd_256_f64_s", float("nan"))})  # fmt: skip
    table = pd.DataFrame(rows, columns=["when", "matmul_ms", "svd_ms"]).drop_duplicates()
    table["side"] = side(table["when"], change)
    return table


def report(root: Path, change: pd.Timestamp, every_setting: bool = False) -> str:
    runs, _ = driver.tables.read([root])
    lines = [f"machine change at {change.isoformat()}: runs that started before it are 'before', the rest 'after'", ""]
    cal = calibrations(root, change)
    lines.append("calibration (best of 5: 50 float32 256x256 matmuls; one float64 256x256 SVD), per sitting start and end:")
    for name, group in cal.groupby("side", sort=False):
        lines.append(f"  {name}: {len(group)} calibrations, matmul median {group['matmul_ms'].median():.1f} ms "
                     f"({group['matmul_ms'].min():.1f}-{group['matmul_ms'].max():.1f}), SVD median "
                     f"{group['svd_ms'].median():.1f} ms ({group['svd_ms'].min():.1f}-{group['svd_ms'].max():.1f})")  # fmt: skip
    lines += ["", "runs per problem and phase on each side:"]
    phases = runs.groupby(["problem.name", "league_role", side(runs["started"], change)]).size().unstack(fill_value=0)
    lines += ["  " + line for line in phases.to_string().splitlines()]
    rates = rates_across_the_change(runs, change)
    lines += ["", f"settings trained on both sides: {len(rates)}; the ratio of their median updates per second of training "
              f"clock, after / before: median {rates['ratio'].median():.2f}, range {rates['ratio'].min():.2f}-"
              f"{rates['ratio'].max():.2f}; per problem and optimizer (settings: median ratio, range):"]  # fmt: skip
    for (problem, optimizer), group in rates.groupby(["problem.name", "optimizer.name"]):
        lines.append(f"  {problem} {optimizer}: {len(group)} setting(s), {group['ratio'].median():.2f} "
                     f"({group['ratio'].min():.2f}-{group['ratio'].max():.2f})")  # fmt: skip
    if every_setting:
        lines += ["", "every setting on both sides (updates per second; revisions before | after):"]
        with pd.option_context("display.width", 250, "display.max_colwidth", 90):
            table = rates.round({"before": 1, "after": 1, "ratio": 2}).to_string(index=False)
        lines += ["  " + line for line in table.splitlines()]
    lines += ["", "tuning trials per problem and optimizer on each side (a tuning on both sides compared trials at "
              "unequal speed):"]  # fmt: skip
    tune = runs[runs["league_role"] == "tune"]
    trials = tune.groupby(["problem.name", "optimizer.name", side(tune["started"], change)]).size().unstack(fill_value=0)
    both = trials[(trials > 0).all(axis=1)] if trials.shape[1] == 2 else trials.iloc[0:0]
    for problem, group in trials.groupby(level=0):
        cells = [f"{opt} {int(row.get('before', 0))}/{int(row.get('after', 0))}" for (_, opt), row in group.iterrows()]
        lines.append(f"  {problem} (before/after): " + ", ".join(cells))
    lines.append(f"  on both sides: {', '.join(f'{p} {o}' for p, o in both.index) or 'none'}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", type=Path, help="a league root with tables/ and manifests/")
    parser.add_argument("--machine-change", required=True, help="when the new machine took over (ISO time)")
    parser.add_argument("--every-setting", action="store_true", help="also print each setting's rates")
    parser.add_argument("--out", type=Path, help="write the text here (default: print it)")
    args = parser.parse_args(argv)
    try:
        change = pd.Timestamp(args.machine_change)
    except ValueError:
        parser.error(f"--machine-change={args.machine_change!r}: not an ISO time")
    change = change.tz_localize("UTC") if change.tzinfo is None else change.tz_convert("UTC")
    if not (args.root / "tables").is_dir():
        parser.error(f"root={args.root}: no league tables there (tables/runs.csv.gz); give a league root")
    text = report(args.root, change, args.every_setting)
    if args.out:
        args.out.write_text(text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
