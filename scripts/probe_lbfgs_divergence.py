"""Probe: where do the league's L-BFGS runs on the oscillator diverge?

In the CPU league's oscillator tuning, L-BFGS (torch.optim.LBFGS, strong-Wolfe line search)
diverged on 23 of 32 trials, often from a low loss. This probe replays each diverged trial
with its recorded overrides (one thread, the same seed: a replay takes the same path) and
watches torch's line search from inside: for every line search, the update it belongs to,
its place in that update (iteration 1 is the first on the update's new mini-batch), and
every trial point's step length and loss. Torch's strong-Wolfe search does not back off a
trial point whose loss is non-finite (it extrapolates from it), and the runner's guarded
closure stops the run at the first non-finite loss, so the run's divergence is the first
non-finite trial point; the probe says where it was.

    python scripts/probe_lbfgs_divergence.py                # ~10 min on one core
    python scripts/probe_lbfgs_divergence.py --report-only  # re-read the csv

Writes ``lbfgs_divergence.csv`` (one row per replayed trial) to ``--out`` (default
docs/results/probes). The runs themselves go under ``--root`` (default outputs/probes/lbfgs),
in a new folder per invocation (a run directory is never reused). Each replay runs in a process
of its own, this script with ``--one``, because the watch patches torch in that process; the
probes' launcher (``probe_runs``) starts plain ``higbench`` jobs, which it could not patch.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

TABLE = Path("docs/results/league/cpu/tables/runs.csv.gz")


def diverged_trials(table: Path = TABLE) -> pd.DataFrame:
    """The oscillator's diverged L-BFGS tuning trials of the published league."""
    runs = pd.read_csv(table)
    chosen = (
        (runs["problem.name"] == "oscillator")
        & (runs["league_role"] == "tune")
        & (runs["optimizer.name"] == "lbfgs")
        & (runs["status"] == "diverged")
    )
    return runs[chosen].reset_index(drop=True)


def replay(overrides: list[str], run_dir: Path) -> dict:
    """Train one run in this process with torch's line search watched; what it saw, as a dict."""
    import torch.optim.lbfgs as lbfgs

    searches: list[dict] = []
    update = {"n": 0, "iteration": 0}
    plain_step, plain_search = lbfgs.LBFGS.step, lbfgs._strong_wolfe

    def step(self, closure):
        update["n"] += 1
        update["iteration"] = 0
        return plain_step(self, closure)

    def strong_wolfe(obj_func, x, t, d, f, g, gtd, *args, **kwargs):
        update["iteration"] += 1
        search = {"update": update["n"], "iteration": update["iteration"], "start_loss": float(f), "trials": []}
        searches.append(search)

        def watched(x_, t_, d_):
            search["trials"].append([float(t_), math.nan])  # a trial that raises stays non-finite
            f_new, g_new = obj_func(x_, t_, d_)
            search["trials"][-1][1] = float(f_new)
            return f_new, g_new

        return plain_search(watched, x, t, d, f, g, gtd, *args, **kwargs)

    lbfgs.LBFGS.step, lbfgs._strong_wolfe = step, strong_wolfe  # not restored: a process per replay
    from higbench.cli import main

    try:
        main([*overrides, f"hydra.run.dir={run_dir}"])
    except SystemExit:
        pass
    bad = next((s for s in searches if any(not math.isfinite(v) for _, v in s["trials"])), None)
    row = {"updates": update["n"], "line_searches": len(searches)}
    if bad is not None:
        before = searches[: searches.index(bad)]
        first_bad = next(i for i, (_, v) in enumerate(bad["trials"]) if not math.isfinite(v))
        row |= {
            "nonfinite_update": bad["update"],
            "nonfinite_iteration": bad["iteration"],
            "nonfinite_trial_point": first_bad + 1,
            "step_length": bad["trials"][first_bad][0],
            "loss_before": bad["start_loss"],
            "earlier_trial_points_all_finite": all(math.isfinite(v) for s in before for _, v in s["trials"]),
            "earlier_first_points_accepted": sum(len(s["trials"]) == 1 for s in before) / max(len(before), 1),
        }
    return row


def summary(df: pd.DataFrame) -> str:
    hit = df.dropna(subset=["nonfinite_update"])
    first = hit[(hit.nonfinite_iteration == 1) & (hit.nonfinite_trial_point == 1)]
    return "\n".join(
        [
            f"{len(df)} diverged trials replayed; {len(hit)} reached a non-finite trial point "
            f"(the replay diverged where the league's run did in {int(df.same_update.sum())})",
            f"at the first trial point of an update's first line search (a new mini-batch, step length lr): {len(first)}",
            f"at a later iteration of its update: {int((hit.nonfinite_iteration > 1).sum())}; "
            f"at a later trial point of its line search: {int((hit.nonfinite_trial_point > 1).sum())}",
            f"loss before the step: median {hit.loss_before.median():.3g} (range {hit.loss_before.min():.3g}-"
            f"{hit.loss_before.max():.3g}); every earlier trial point finite in {int(hit.earlier_trial_points_all_finite.sum())}",
        ]
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/results/probes")
    ap.add_argument("--root", default="outputs/probes/lbfgs")
    ap.add_argument("--report-only", action="store_true")
    ap.add_argument("--one", nargs="+", help=argparse.SUPPRESS)  # internal: replay one trial, print its row
    args = ap.parse_args()
    if args.one:
        print(json.dumps(replay(args.one[1:], Path(args.one[0]))))
        return
    csv = Path(args.out) / "lbfgs_divergence.csv"
    if not args.report_only:
        rows = []
        sitting = Path(args.root) / time.strftime("%Y-%m-%d_%H-%M-%S")
        for i, trial in diverged_trials().iterrows():
            overrides = trial.overrides.split()
            run_dir = sitting / f"study{int(trial.study)}-trial{int(trial.trial)}"
            done = subprocess.run(
                [sys.executable, __file__, "--one", str(run_dir), *overrides], capture_output=True, text=True, check=True
            )
            row = json.loads(done.stdout.strip().splitlines()[-1])
            row |= {"study": int(trial.study), "trial": int(trial.trial), "overrides": trial.overrides}
            row["league_updates"] = int(trial.steps)
            row["same_update"] = row.get("nonfinite_update") == trial.steps + 1  # the run counts completed updates
            rows.append(row)
            print(f"{i + 1}: {json.dumps(row)}", flush=True)
        csv.parent.mkdir(parents=True, exist_ok=True)
        pd.DataFrame(rows).to_csv(csv, index=False)
    print(summary(pd.read_csv(csv)))


if __name__ == "__main__":
    main()
