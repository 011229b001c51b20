"""Probe: does HIG's rising Poisson test loss come from our data distribution?

The paper (figure 3b/3c) has HIG lower the Poisson loss quickly, also after Adam pre-training;
with our band-limited Fourier potentials HIG's test loss rises after pre-training. The authors'
script draws PhiFlow ``Noise`` potentials instead. This probe varies the data alone
(``problem.data=fourier|phiflow_noise``), everything else at the authors' script's settings
(experiment ``poisson_authors``: network [64, 128, 64], b = 64, HIG tau 1e-5):

1. from scratch, ``--seconds`` of training clock: HIG eta 0.01 (the script's) and 0.02 (the
   paper's figure 3c), Adam eta 1e-4 (figure 3c) and 3e-4 (the script's);
2. continued from the from-scratch Adam eta 1e-4 run's final weights (figure 3c), ``--cont-seconds``:
   HIG eta 0.01 and 0.02, and Adam eta 1e-4 continued.

Every run is evaluated after each HIG update (Adam every 10), so curves compare per update.

    python scripts/probe_poisson_data.py                 # ~35 min on 2 cores, then the summary
    python scripts/probe_poisson_data.py --report-only   # re-read outputs/probes/poisson_data
    python scripts/probe_poisson_data.py --set device=cuda --jobs 6 --pre-updates 20000 --cont-seconds 240 \
        --out docs/results/probes/gpu                    # on a GPU: ~60x more HIG updates per second

Writes ``poisson_data.csv`` (one row per run), ``poisson_data_curves.csv`` (per evaluation)
and ``poisson_data.png`` to ``--out`` (default docs/results/probes).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import probe_runs

DATA = ("phiflow_noise", "fourier")
HIG_LRS = (0.01, 0.02)  # the script's default and the paper's figure 3c
SCRIPT_ADAM_LR = 3e-4  # the authors' script's default Adam rate (the paper's is conf/problem_optimizer/poisson_adam.yaml's)


def paper_adam_lr() -> float:
    """Figure 3c's Adam rate: the pair's shipped default (``higbench problem=poisson optimizer=adam``)."""
    from higbench.jobs import composed_value

    return float(composed_value("optimizer.lr", "problem=poisson", "optimizer=adam"))


EVAL = {"hig": ["eval_unit=updates", "eval_every=1"], "adam": ["eval_unit=updates", "eval_every=10"]}


def job(data: str, optimizer: str, lr: float, seconds: float, updates: int = 0) -> list[str]:
    # experiment poisson_authors's settings, spelled out (its own sweep is of the basic sweeper)
    out = ["problem=poisson", f"problem.data={data}", "problem.hidden=[64,128,64]", "batch_size=64"]
    out += [f"optimizer={optimizer}", f"optimizer.lr={lr:g}"]
    return out + [f"budget.seconds={seconds:g}", *EVAL[optimizer]] + ([f"budget.max_updates={updates}"] if updates else [])


def runs_under(root: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    runs, curves = probe_runs.runs_under(root)
    runs["from"] = np.where(runs["init_from"].notna(), "Adam-pretrained", "scratch")
    return runs, curves


def train(root: Path, seconds: float, cont_seconds: float, n_jobs: int, extra: list[str], pre_updates: int = 0) -> None:
    if pre_updates:  # the pre-training alone, to a number of updates (a GPU's clock is not the paper's)
        scratch = [job(d, "adam", paper_adam_lr(), 100 * seconds, updates=pre_updates) for d in DATA]
    else:
        scratch = [job(d, "hig", lr, seconds) for d in DATA for lr in HIG_LRS]
        scratch += [job(d, "adam", lr, seconds) for d in DATA for lr in (paper_adam_lr(), SCRIPT_ADAM_LR)]
    scratch_jobs = [probe_runs.as_job([*j, *extra], "scratch") for j in scratch]
    probe_runs.launch(scratch_jobs, root, n_jobs)  # runs already under root are reused
    pre_lr = paper_adam_lr()  # figure 3c pre-trains with Adam at the paper's rate
    pre = [j for j in scratch_jobs if j.overrides["optimizer"] == "adam" and np.isclose(j.overrides["optimizer.lr"], pre_lr)]
    cont = []
    for parent in pre:  # continued from the pre-trained run's final weights (init_from)
        data = parent.overrides["problem.data"]
        cont += [probe_runs.as_job([*job(data, "hig", lr, cont_seconds), *extra], "continued", parent) for lr in HIG_LRS]
        cont.append(probe_runs.as_job([*job(data, "adam", pre_lr, cont_seconds), *extra], "continued", parent))
    probe_runs.launch(cont, root, n_jobs)


def summarise(runs: pd.DataFrame, curves: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for _, r in runs.sort_values(["from", "problem.data", "optimizer.name", "optimizer.lr"]).iterrows():
        c = curves[curves["path"] == r["path"]].sort_values("step")
        loss = c.set_index("step")["test_loss"]
        row = {"from": r["from"], "data": r["problem.data"], "optimizer": r["optimizer.name"], "lr": r["optimizer.lr"],
               "batch_size": int(r["batch_size"]),
               "status": r["status"], "updates": int(r["steps"]), "train_s": round(float(r["train_time_s"]), 1),
               "s_per_update": round(float(r["train_time_s"]) / max(int(r["steps"]), 1), 3),
               "device": r["env.device_name"], "test_start": loss.iloc[0]}  # fmt: skip
        for n in (1, 3, 10, 30, 100, 300):
            row[f"test_after_{n}"] = loss[loss.index >= n].iloc[0] if (loss.index >= n).any() else np.nan
        row |= {"test_min": loss.min(), "test_end": loss.iloc[-1], "end_over_start": loss.iloc[-1] / loss.iloc[0]}
        rows.append(row)
    return pd.DataFrame(rows)


def plot(runs: pd.DataFrame, curves: pd.DataFrame, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(9, 6.4), squeeze=False)
    colors = {("hig", 0.01): "#41ab5d", ("hig", 0.02): "#00441b", ("adam", 1e-4): "#4292c6", ("adam", 3e-4): "#9ecae1"}
    for i, data in enumerate(DATA):
        for j, origin in enumerate(("scratch", "Adam-pretrained")):
            ax = axes[i, j]
            for _, r in runs[(runs["problem.data"] == data) & (runs["from"] == origin)].iterrows():
                c = curves[curves["path"] == r["path"]].sort_values("step")
                key = (r["optimizer.name"], round(float(r["optimizer.lr"]), 6))
                label = f"{'HIG' if key[0] == 'hig' else 'Adam'} η={key[1]:g}"
                label += " (diverged)" if r["status"] == "diverged" else ""
                ax.plot(c["step"].clip(lower=0.8), c["test_loss"], color=colors.get(key, "grey"), label=label)
            ax.set(xscale="log", yscale="log", title=f"{data}, {origin}", xlabel="updates (log)", ylabel="test loss")
            ax.title.set_fontsize(9)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
    where = ", ".join(sorted(set(runs["env.device_name"].dropna().astype(str))))
    fig.suptitle(f"Poisson, authors' network and b=64: test loss per update for both data choices ({where})", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> None:
    parser = probe_runs.parser("Poisson data probe (see docstring).", "poisson_data")
    parser.add_argument("--seconds", type=float, default=300.0, help="training clock of the from-scratch runs")
    parser.add_argument("--cont-seconds", type=float, default=240.0, help="training clock of the continued runs")
    parser.add_argument(
        "--pre-updates", type=int, default=0, help="pre-train Adam for this many updates (fig. 3c: 19,202), no other scratch runs"
    )
    args = probe_runs.parse(parser, "probe_poisson_data.py", argv)
    if not args.report_only:
        train(args.root, args.seconds, args.cont_seconds, args.jobs, args.set, args.pre_updates)
    runs, curves = runs_under(args.root)
    table = summarise(runs, curves)
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / "poisson_data.csv", index=False, float_format="%.4g")
    keep = curves.merge(runs[["path", "from", "problem.data", "optimizer.name", "optimizer.lr"]], on="path")
    keep.drop(columns=["path"]).to_csv(args.out / "poisson_data_curves.csv", index=False, float_format="%.5g")
    plot(runs, curves, args.out / "poisson_data.png")
    print(table.to_string(index=False))


if __name__ == "__main__":
    main()
