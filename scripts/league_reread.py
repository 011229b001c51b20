"""Re-read a published league's runs.csv (final losses only) with the league's statistics.

    python scripts/league_reread.py docs/results/league/runs.csv --out docs/results/league

Writes ``reread.txt`` (per task: the leader by median, every seed, the order-statistics interval
for the median with its coverage, P(leader < X), the exact one-sided Mann-Whitney p-value and its
Holm correction over the task's comparisons; then the aggregate across tasks) and
``final_losses.png`` (every seed per setting and task). A runs.csv carries no curves, so nothing
about time to a target can be re-scored from it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from higbench.results import league, league_figures  # noqa: E402


def toy_constant_loss() -> float:
    """The toy's test loss of the best constant prediction (the mean target): the level at which
    a row is flagged as a constant predictor. The toy's test targets do not depend on gamma."""
    import torch
    from omegaconf import OmegaConf

    from higbench.jobs import compose, hydra_conf
    from higbench.problems.toy import Toy

    with hydra_conf():
        cfg = OmegaConf.create(compose(("problem=toy",))["problem"])
    targets = Toy(cfg, torch.float64, "cpu", 0).test.targets
    return float(0.5 * ((targets - targets.mean(0)) ** 2).sum(1).mean())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs_csv", type=Path)
    parser.add_argument("--out", type=Path, required=True, help="folder for reread.txt and final_losses.png")
    args = parser.parse_args(argv)
    if not args.runs_csv.is_file():
        parser.exit(2, f"league_reread: error: runs_csv={args.runs_csv}: no such file\n")
    scored = league.runs_csv_frame(args.runs_csv)
    constant = toy_constant_loss()
    constant_loss = {task: constant for task in scored["task"].unique() if task.split()[0] == "toy"}
    text = league.format_runs_csv(args.runs_csv, constant_loss)
    note = f"constant-prediction test loss (flag level), toy tasks: {constant:.3g}; other tasks: not computed"
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "reread.txt").write_text(text + "\n" + note + "\n")
    figure = league_figures.plot_final_losses(league.final_loss_table(scored, constant_loss=constant_loss), args.out)
    print(f"{args.out / 'reread.txt'}\n{figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
