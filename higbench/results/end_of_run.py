"""What a run says when it ends, read back from its closed run file: the lines the CLI logs
(status, updates, final test loss, time to the problem's targets, a busy machine, the file)
and what to do next with a diverged run.

    summary_lines(summary, cfg, label)   # the loop's summary, the run's config, a sweep job's prefix
"""

from __future__ import annotations

import math

from omegaconf import DictConfig

from higbench.display import busy_note
from higbench.results.index import read_run_summary, threshold_column
from higbench.results.targets import for_problem


def summary_lines(summary, cfg: DictConfig, label: str = "") -> list[str]:
    """The end-of-run lines, read back from the closed run file (the numbers the index shows);
    ``summary``: the loop's (status, steps, wall_time, final_test_loss, reason, path, tables);
    ``label``: a sweep job's prefix."""
    head = f"{label}{summary.status}: {cfg.problem.name}/{cfg.optimizer.name} {summary.steps} updates in {summary.wall_time:.1f}s"
    thresholds = for_problem(cfg)  # the problem's targets (problem.targets), as the index times them
    row, _ = read_run_summary(summary.path, thresholds=thresholds, tables=summary.tables)  # never raises
    if "final_test_loss" not in row:  # an unreadable file: say what the loop knew
        row["final_test_loss"] = summary.final_test_loss
    final = row.get("final_test_loss", math.nan)
    at = f" (last evaluated at step {row['final_step']})" if "final_step" in row and row["final_step"] != summary.steps else ""
    lines = [f"{head}, final test loss {final:.4e}{at}" + (f" ({summary.reason})" if summary.reason else "")]
    if summary.status == "diverged":
        lines.append(f"{label}{diverged_hint(cfg)}")
    times = []
    for t in thresholds:
        value = row.get(threshold_column(t), math.nan)
        times.append(f"{t:.0e}: " + (f"{value:.1f}s" if math.isfinite(value) else "not reached"))
    if times:
        lines.append(f"{label}time to test loss " + ", ".join(times))
    else:  # a problem of one's own may set none
        lines.append(f"{label}time to test loss: the problem sets no targets (give some with problem.targets=[1e-2,1e-3])")
    busy = busy_note(row.get("env.cpu_share"), row.get("env.load_at_finish"))
    if busy:  # a busy machine: the numbers above are not an idle machine's (the README's)
        lines.append(f"{label}{busy}")
    lines.append(f"{label}run file: {summary.path}")
    return lines


def diverged_hint(cfg: DictConfig) -> str:
    """What a researcher does next with a diverged run (the figures' own rule for GN)."""
    if cfg.optimizer.name == "gn":
        return (
            "Gauss-Newton diverges for many seeds at the paper's settings; the figures search seeds "
            "and report the stable ones (on the oscillator seed 7 is stable: seed=7), see docs/results"
        )
    return "a diverged run is a result (its file says where and why); a smaller optimizer.lr or another seed may train"
