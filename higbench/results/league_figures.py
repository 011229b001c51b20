"""The league's figures, in one colour per setting across them: every seed's final test loss
per task (``final_losses.png``) and the performance profile at equal wall clock (``profile.png``).

    colours = setting_colours(final_loss_table(scored))
    plot_final_losses(final_loss_table(scored), out, colours)
    plot_profile(reached, colours, out)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from higbench.results.algoperf import TAU_MAX
from higbench.results.league import HIG, profile_times
from higbench.results.profile import performance_profile

LEADER_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown")
HIG_COLOURS = {HIG: "tab:red", f"{HIG} (paper)": "tab:pink"}


def assign_colours(settings: Sequence[str], leaders: Sequence[str]) -> dict[str, str]:
    """HIG (tuned, paper) in reds, up to five leaders in distinct colours, the rest grey."""
    given = {name: "0.7" for name in settings}
    for name, colour in zip([n for n in leaders if n not in HIG_COLOURS], LEADER_COLOURS):
        given[name] = colour
    given.update({n: c for n, c in HIG_COLOURS.items() if n in given})
    return given


def setting_colours(table: pd.DataFrame) -> dict[str, str]:
    """One colour per setting for every figure of a league: the settings that lead the most tasks
    by median final loss (then come second, third) and HIG. ``table``: ``final_loss_table``
    (sorted by median within each task)."""
    ranks = table.groupby("task", sort=False).cumcount()
    placed = pd.crosstab(table["setting"], ranks).reindex(columns=[0, 1, 2], fill_value=0)
    ranked = placed.sort_values([0, 1, 2], ascending=False)
    return assign_colours(list(dict.fromkeys(table["setting"])), list(ranked.index[ranked.sum(axis=1) > 0]))


def plot_final_losses(table: pd.DataFrame, out: Path, colours: Mapping[str, str] | None = None) -> Path:
    """final_losses.png: per task (a panel), every seed's final test loss per setting (a dot each,
    log scale; diverged, or ended above its first evaluation: x at the top edge; <= 0: v at the
    bottom), the median as a bar; settings sorted by median, leaders (up to five, one colour each in
    every panel) and HIG in colour, the rest grey.
    ``table``: ``final_loss_table``; ``colours``: ``setting_colours`` of it unless given."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tasks = list(dict.fromkeys(table["task"]))
    ncols = min(len(tasks), 3)
    nrows = -(-len(tasks) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(5.2 * ncols, 4.0 * nrows), squeeze=False)
    for ax in axes.flat[len(tasks) :]:
        ax.set_visible(False)
    colours = colours or setting_colours(table)
    for ax, task in zip(axes.flat, tasks):
        rows = table[table["task"] == task].reset_index(drop=True)
        finite = np.concatenate([np.asarray(s, dtype=float) for s in rows["seeds"]])
        finite = finite[np.isfinite(finite) & (finite > 0)]
        top, bottom = (finite.max() * 3, finite.min() / 3) if len(finite) else (1.0, 0.1)
        for i, r in rows.iterrows():
            seeds = np.asarray(r["seeds"], dtype=float)
            c = colours[r["setting"]]
            ok = np.isfinite(seeds) & (seeds > 0)
            ax.scatter(np.full(ok.sum(), i), seeds[ok], s=14, color=c, zorder=3)
            for where, marker, level in ((~np.isfinite(seeds), "x", top), (np.isfinite(seeds) & (seeds <= 0), "v", bottom)):
                # diverged (NaN, or ended above its start) at the top edge; a loss <= 0 (float rounding) at the bottom
                if where.any():
                    ax.scatter(np.full(where.sum(), i), np.full(where.sum(), level), marker=marker, s=20, color=c, zorder=3)
            if math.isfinite(r["median"]) and r["median"] > 0:
                ax.hlines(r["median"], i - 0.3, i + 0.3, color=c, lw=2, zorder=4)
        ax.set_yscale("log")
        ax.set_xticks(range(len(rows)), rows["setting"], rotation=70, fontsize=7)
        for label, name in zip(ax.get_xticklabels(), rows["setting"]):
            label.set_color(colours[name] if colours[name] != "0.7" else "0.35")
        ax.set_title(f"{task} (leader by median: {rows['setting'][0]})", fontsize=9)
        ax.grid(alpha=0.3, axis="y")
    for row_axes in axes:
        row_axes[0].set_ylabel(
            "final test loss (dots: seeds; bar: median;\nx: diverged or ended above its start; v: <= 0, rounding)", fontsize=8
        )
    fig.tight_layout()
    out.mkdir(parents=True, exist_ok=True)
    path = out / "final_losses.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_profile(reached: pd.DataFrame, colours: Mapping[str, str], out: Path, tau_max: float = TAU_MAX) -> Path:
    """profile.png: rho(tau) in seconds to the problems' targets (equal wall clock; no updates
    view), in the colours of ``final_losses.png`` (``setting_colours``): the leaders by final
    loss and HIG in colour, the rest grey. Coloured lines are drawn widest first, so one lying on
    another shows as a stripe inside it, and the legend (beside the axes, highest first) gives each
    one's rho at ``tau_max``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    taus = np.linspace(1.0, tau_max, 61)
    rho = performance_profile(profile_times(reached), taus)
    fig, ax = plt.subplots(figsize=(8.2, 4.4))
    coloured = [n for n in rho.columns if colours.get(n, "0.7") != "0.7"]
    greys = [n for n in rho.columns if n not in coloured]
    for name in greys:
        ax.step(taus, rho[name], where="post", color="0.7", lw=0.8, zorder=1)
    for i, name in enumerate(coloured):
        ax.step(taus, rho[name], where="post", color=colours[name], lw=max(4.5 - 0.8 * i, 1.2), zorder=3 + i,
                label=f"{name}: {rho[name].iloc[-1]:.2f} at tau={tau_max:g}")  # fmt: skip
    never = sum(rho[n].iloc[-1] == 0 for n in greys)
    ax.set_xlabel("tau (seconds to target over the fastest)")
    ax.set_ylabel("rho(tau): fraction of (task, target) pairs")
    ax.set_title(f"equal wall clock (grey: {len(greys)} other settings, {never} of them at 0 throughout)", fontsize=10)
    ax.set_ylim(-0.03, 1.03)
    ax.grid(alpha=0.3)
    # outside the axes, so it hides no line; ordered by rho at tau_max, so it reads as the ranking
    handles, labels = ax.get_legend_handles_labels()
    order = sorted(range(len(labels)), key=lambda k: -rho[coloured[k]].iloc[-1])
    ax.legend([handles[k] for k in order], [labels[k] for k in order], fontsize=7, loc="upper left",
              bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)  # fmt: skip
    fig.tight_layout()
    path = out / "profile.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
