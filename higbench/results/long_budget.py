"""The long budget (``higbench-league --long``): the league's tuned settings, and the shipped
ones, trained far longer than the league's budget on a few seeds. It asks the paper's own
question (what HIG makes of about an hour of updates) against today's optimizers, and gets a
table of its own: another budget and fewer seeds than the league's, so it never enters the
league's scores. Every seed is shown; no ordering is claimed from it."""

from __future__ import annotations

import numpy as np
import pandas as pd

from higbench.results import stats
from higbench.results.league import LONG_PAPER_ROLE, LONG_ROLE, LONG_ROLES, SHIPPED_ROLES, one_run_per_identity

__all__ = ["LONG_PAPER_ROLE", "LONG_ROLE", "LONG_ROLES", "format_long_budget", "long_budget_table"]
LEAGUE_ROLES = {LONG_ROLE: ("confirm",), LONG_PAPER_ROLE: SHIPPED_ROLES}  # the same setting at the league's budget
COLUMNS = ("task", "setting", "seconds", "seeds", "median val", "median test", "league median test", "test per seed",
           "updates per seed")  # fmt: skip


def long_budget_table(runs: pd.DataFrame) -> pd.DataFrame:
    """Per task and setting ('hig' tuned, 'hig (paper)' shipped): the median training seconds,
    the seeds, the median final validation and test loss (diverged, or ended above the first
    evaluation, given ``league.with_first_losses``' columns: inf, the worst), and each
    seed's final test loss and updates, in seed order; the lowest median validation loss first.
    Beside them, the same setting's median final test loss at the league's budget (its
    confirmation runs on the task; NaN where there are none): what the longer budget bought."""
    if runs.empty or "league_role" not in runs:
        return pd.DataFrame(columns=list(COLUMNS))
    done = runs[runs["status"].isin(("completed", "diverged"))]
    long = one_run_per_identity(done[done["league_role"].isin(LONG_ROLES)])
    rows = []
    for (task, name, role), group in long.groupby(["task", "optimizer.name", "league_role"], sort=True):
        short = one_run_per_identity(
            done[(done["task"] == task) & (done["optimizer.name"] == name) & done["league_role"].isin(LEAGUE_ROLES[role])]
        )
        group = group.sort_values("seed")
        test, val = stats.scored_column(group, "final_test_loss"), stats.scored_column(group, "final_val_loss")
        rows.append({
            "task": task, "setting": name if role == LONG_ROLE else f"{name} (paper)",
            "seconds": float(np.median(group["train_time_s"].astype(float))), "seeds": len(group),
            "median val": float(np.median(val)), "median test": float(np.median(test)),
            "league median test": float(np.median(stats.scored_column(short, "final_test_loss"))) if len(short) else np.nan,
            "test per seed": ", ".join(f"{v:.3g}" for v in test),
            "updates per seed": ", ".join(str(int(s)) for s in group["steps"]),
        })  # fmt: skip
    if not rows:
        return pd.DataFrame(columns=list(COLUMNS))
    return pd.DataFrame(rows, columns=list(COLUMNS)).sort_values(["task", "median val"], kind="stable", ignore_index=True)


def format_long_budget(runs: pd.DataFrame) -> str | None:
    """The long-budget table as the report prints it; None without long-budget runs."""
    table = long_budget_table(runs)
    if table.empty:
        return None
    head = ("long budget (--long): tuned and shipped settings at a budget far above the league's, every seed; "
            "its own table (another budget, fewer seeds), no ordering claimed")  # fmt: skip
    with pd.option_context("display.width", 250, "display.max_columns", None, "display.max_colwidth", 80):
        return "\n".join([head, table.to_string(index=False, float_format="{:.3g}".format)])
