"""The league's statistics: what a handful of seeds can say, and nothing more.

    median_interval([3.1, 2.0, 5.4])          # order-statistics interval for the median, exact coverage
    mann_whitney_less(x, y)                   # one-sided exact p-value that X tends below Y
    holm([0.01, 0.04, 0.03])                  # Holm's step-down adjusted p-values
    compare_to_leader({"a": [...], ...})      # per setting: median, P(leader < X), Holm p, verdict
    probability_of_improvement(x, y)          # P(X < Y) + P(X = Y) / 2 (lower is better)
    iqm(values); stratified_bootstrap_ci(...) # the aggregate across tasks, rliable's way

Every function is pure (arrays in, numbers out) and is checked on hand-made seeds with known
answers, and the aggregate against rliable 1.2.0's values on seeded random score matrices
(tests/results/test_league_stats.py; the oracle file comes from scripts/rliable_oracle.py).

Lower is better everywhere (a loss, a time); a diverged run counts as +inf, the worst, whether
it ended at NaN or at a finite blow-up: a completed run whose final loss lies above its first
evaluation's, worse than the network it started from (``scored_loss`` with ``first``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

CONFIDENCE = 0.95
ALPHA = 0.05  # family-wise error rate of a task's comparisons against its leader (Holm)
BOOTSTRAP_REPS = 2000
STALL_RTOL = 1e-2  # a final loss within 1% of the first evaluation did not move; above that, up: a blow-up


# -- one setting on one task -----------------------------------------------------------------


def scored_loss(loss: Sequence[float], status: Sequence[str], first: Sequence[float] | None = None) -> np.ndarray:
    """The loss a run is scored by: its final loss when it completed with a finite one, +inf
    otherwise (status diverged, NaN or inf): divergence is scored one way, as the worst. With
    ``first`` (each run's first evaluated loss of the same kind; NaN: unknown), a completed run
    that ended above it (by more than ``STALL_RTOL``, within which it did not move) blew up
    without a NaN (LM at 1.2e3 from 0.88) and scores +inf too: no threshold per problem, only
    "worse than where it started"."""
    x = np.asarray(loss, dtype=float)
    ok = (np.asarray(status) == "completed") & np.isfinite(x)
    if first is not None:  # above it by more than flag_row's "did not move": a NaN first compares False
        ok &= ~(x > np.asarray(first, dtype=float) * (1 + STALL_RTOL))
    return np.where(ok, x, math.inf)


def scored_column(runs, metric: str) -> np.ndarray:
    """``scored_loss`` of a runs frame's ``metric`` ('final_test_loss'), with the first evaluation
    ('first_test_loss', from ``league.with_first_losses``) where the frame carries it."""
    return scored_loss(runs[metric], runs["status"], runs.get(metric.replace("final_", "first_", 1)))


@dataclass(frozen=True)
class MedianInterval:
    """[low, high] = [x_(k), x_(n+1-k)] of n sorted seeds: it covers the median of the seeds'
    distribution with probability ``coverage`` (exact for any continuous distribution:
    1 - 2 P(Binomial(n, 1/2) <= k - 1)). ``meets`` is False when even [min, max] falls short of
    the confidence asked for (n <= 5 at 95%): then [min, max] is given with its own coverage."""

    low: float
    high: float
    coverage: float
    k: int
    n: int
    meets: bool

    def label(self) -> str:
        if not self.n:
            return "no seeds"
        what = "[min, max]" if self.k == 1 else f"[x({self.k}), x({self.n + 1 - self.k})]"
        note = "" if self.meets else ", no higher-coverage interval exists at this n"
        return f"{what} of {self.n} seeds, covers the median with probability {self.coverage:.1%}{note}"


def order_statistic_coverage(n: int, k: int) -> float:
    """P(x_(k) <= median <= x_(n+1-k)) for n independent draws of a continuous distribution."""
    return float(1.0 - 2.0 * stats.binom.cdf(k - 1, n, 0.5))


def median_interval(values: Sequence[float], confidence: float = CONFIDENCE) -> MedianInterval:
    """The narrowest distribution-free interval for the median whose coverage is at least
    ``confidence``; [min, max] with its (lower) coverage when no interval reaches it."""
    x = np.sort(np.asarray(values, dtype=float))
    x = x[~np.isnan(x)]
    n = len(x)
    if not n:
        return MedianInterval(math.nan, math.nan, math.nan, 0, 0, False)
    k = 1
    while k + 1 <= (n + 1) // 2 and order_statistic_coverage(n, k + 1) >= confidence:
        k += 1
    coverage = order_statistic_coverage(n, k)
    return MedianInterval(float(x[k - 1]), float(x[n - k]), coverage, k, n, coverage >= confidence)


def probability_of_improvement(x: Sequence[float], y: Sequence[float]) -> float:
    """P(X < Y) + P(X = Y) / 2 for one run X of ``x`` and one run Y of ``y`` (lower is better):
    the Mann-Whitney U of x against y over len(x) len(y) (rliable's, on negated scores)."""
    a, b = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if not len(a) or not len(b):
        return math.nan
    return float((a[:, None] < b[None, :]).mean() + 0.5 * (a[:, None] == b[None, :]).mean())


def _rank_sum_counts(doubled_ranks: np.ndarray, n: int) -> np.ndarray:
    """counts[s]: how many n-subsets of the pooled runs have doubled rank sum s (midranks of tied
    values doubled to integers); dynamic programming over the runs, exact in float64 below 2**53."""
    total = int(doubled_ranks.sum())
    counts = np.zeros((n + 1, total + 1))
    counts[0, 0] = 1.0
    for r in doubled_ranks:
        counts[1:, r:] += counts[:-1, : total + 1 - r].copy()
    return counts[n]


def mann_whitney_less(x: Sequence[float], y: Sequence[float]) -> float:
    """One-sided p-value of the Mann-Whitney U test that X tends below Y. Exact: scipy's exact
    null distribution without ties; with ties (two diverged seeds are tied at inf) the exact
    permutation distribution of the same statistic (the rank sum of x over every split of the
    pooled runs, counted by ``_rank_sum_counts``)."""
    a, b = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if not len(a) or not len(b):
        return math.nan
    pooled = np.concatenate([a, b])
    if len(np.unique(pooled)) == len(pooled):
        return float(stats.mannwhitneyu(a, b, alternative="less", method="exact").pvalue)
    doubled = np.rint(2 * stats.rankdata(pooled)).astype(int)
    counts = _rank_sum_counts(doubled, len(a))
    observed = int(doubled[: len(a)].sum())
    return float(counts[: observed + 1].sum() / math.comb(len(pooled), len(a)))


def holm(pvalues: Sequence[float]) -> np.ndarray:
    """Holm's step-down adjusted p-values (family-wise error over the family given): the i-th
    smallest p times (m - i + 1), made monotone, capped at 1. NaN stays NaN, outside the family."""
    p = np.asarray(pvalues, dtype=float)
    out = np.full(p.shape, math.nan)
    idx = np.flatnonzero(~np.isnan(p))
    if not len(idx):
        return out
    order = idx[np.argsort(p[idx], kind="stable")]
    m = len(order)
    adjusted = np.minimum(1.0, np.maximum.accumulate(p[order] * (m - np.arange(m))))
    out[order] = adjusted
    return out


def leader_by_median(seeds: Mapping[str, Sequence[float]]) -> str:
    """The setting with the lowest median (ties: the lower mean rank of its seeds, then the name)."""
    medians = {name: float(np.median(np.asarray(v, dtype=float))) for name, v in seeds.items() if len(v)}
    if not medians:
        raise ValueError("no setting has a seed")
    pooled = np.concatenate([np.asarray(seeds[n], dtype=float) for n in medians])
    ranks = stats.rankdata(pooled)
    mean_rank, start = {}, 0
    for name in medians:
        mean_rank[name] = float(ranks[start : start + len(seeds[name])].mean())
        start += len(seeds[name])
    return min(medians, key=lambda n: (medians[n], mean_rank[n], n))


def compare_to_leader(seeds: Mapping[str, Sequence[float]], alpha: float = ALPHA, confidence: float = CONFIDENCE) -> list[dict]:
    """One task's settings against its leader (lowest median): per setting its median, seeds
    (sorted), order-statistics interval, P(leader < X), the exact one-sided Mann-Whitney p-value
    that the leader tends below X, that p Holm-adjusted over the task's comparisons, and
    ``separated`` (adjusted p < ``alpha``). Sorted by median; the leader first."""
    leader = leader_by_median(seeds)
    others = [n for n in seeds if n != leader and len(seeds[n])]
    raw = [mann_whitney_less(seeds[leader], seeds[n]) for n in others]
    adjusted = dict(zip(others, holm(raw)))
    raw_p = dict(zip(others, raw))
    rows = []
    for name, values in seeds.items():
        if not len(values):
            continue
        v = np.sort(np.asarray(values, dtype=float))
        is_leader = name == leader
        rows.append({
            "setting": name, "leader": is_leader, "median": float(np.median(v)), "seeds": v.tolist(),
            "interval": median_interval(v, confidence),
            "p_leader_below": math.nan if is_leader else probability_of_improvement(seeds[leader], v),
            "p_value": math.nan if is_leader else raw_p[name],
            "p_holm": math.nan if is_leader else float(adjusted[name]),
            "separated": False if is_leader else bool(adjusted[name] < alpha),
        })  # fmt: skip
    return sorted(rows, key=lambda r: (not r["leader"], r["median"], r["setting"]))


def smallest_attainable_p(n: int, m: int) -> float:
    """The smallest one-sided exact Mann-Whitney p-value with n and m seeds (U = 0): 1 / C(n+m, n).
    With 3 and 3 it is 0.05, so no ordering survives a correction over two or more comparisons."""
    return 1.0 / math.comb(n + m, n)


# -- constant predictors and rows to flag ----------------------------------------------------


def flag_row(
    final: Sequence[float],
    status: Sequence[str],
    constant_loss: float | None = None,
    first: Sequence[float] | None = None,
    rtol: float = STALL_RTOL,
) -> str | None:
    """Why a (task, setting) row must not be published as a result, or None:
    'diverged on every seed'; 'constant predictor' when every seed's final loss is within
    ``rtol`` of the task's constant-prediction loss, or did not move from its first evaluation
    (``first``: each seed's first evaluated loss, when curves exist)."""
    loss = scored_loss(final, status, first)
    if len(loss) and np.isinf(loss).all():
        return "diverged on every seed"
    x = np.asarray(final, dtype=float)
    if constant_loss is not None and len(x) and np.allclose(x, constant_loss, rtol=rtol, atol=0):
        return f"constant predictor (every seed within {rtol:.0%} of the constant-prediction loss {constant_loss:.3g})"
    if first is not None and len(x) and np.allclose(x, np.asarray(first, dtype=float), rtol=rtol, atol=0):
        return f"constant predictor (no seed moved more than {rtol:.0%} from its first evaluation)"
    return None


# -- the aggregate across tasks (rliable) ----------------------------------------------------


def iqm(values: Sequence[float] | np.ndarray, axis: int | None = None) -> float | np.ndarray:
    """Interquartile mean: the mean of the middle 50% after cutting 25% at each end (scipy's
    trim_mean; rliable's ``aggregate_iqm`` over all (run, task) scores when ``axis`` is None)."""
    x = np.asarray(values, dtype=float)
    if axis is None:
        x = x.ravel()
        if not len(x):
            return math.nan
    return stats.trim_mean(x, 0.25, axis=axis) if axis is not None else float(stats.trim_mean(x, 0.25))


def normalised_scores(loss: np.ndarray, worst: Sequence[float], best: Sequence[float]) -> np.ndarray:
    """Losses (runs x tasks, lower better) as scores (higher better) comparable across tasks:
    log(worst / loss) / log(worst / best) per task column, clipped below at 0. 1 is the task's
    ``best`` (e.g. its leader's median), 0 its ``worst`` (the constant-prediction loss) or worse,
    a diverged run (inf) 0."""
    loss = np.asarray(loss, dtype=float)
    worst, best = np.asarray(worst, dtype=float), np.asarray(best, dtype=float)
    if np.any(~(best < worst)) or np.any(best <= 0):
        raise ValueError("normalised_scores: need 0 < best < worst on every task")
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.log(worst / loss) / np.log(worst / best)
    return np.clip(np.where(np.isfinite(loss), s, 0.0), 0.0, None)


def _columns(scores) -> list[np.ndarray]:
    """A (runs x tasks) matrix, or one array of runs per task (counts may differ), as columns."""
    if isinstance(scores, np.ndarray) and scores.ndim == 2:
        return [scores[:, t].astype(float) for t in range(scores.shape[1])]
    return [np.asarray(c, dtype=float) for c in scores if len(c)]


def stratified_bootstrap_ci(
    scores,
    statistic: Callable[[np.ndarray], float] = iqm,
    reps: int = BOOTSTRAP_REPS,
    confidence: float = CONFIDENCE,
    seed: int = 0,
) -> tuple[float, float, float]:
    """(point, low, high) of ``statistic`` over every (run, task) score of a (runs x tasks) matrix
    (or a list of per-task arrays), with the percentile interval of rliable's stratified
    bootstrap: each replicate resamples the runs of every task with replacement, apart, and pools
    them. Its coverage is nominal, not exact: with few runs per task the percentile interval is
    known to be too narrow (with 3 runs a task has only 10 distinct resamples)."""
    columns = _columns(scores)
    if not columns:
        return math.nan, math.nan, math.nan
    point = float(statistic(np.concatenate(columns)))
    rng = np.random.default_rng(seed)
    matrix = np.concatenate([c[rng.integers(0, len(c), (reps, len(c)))] for c in columns], axis=1)
    draws = stats.trim_mean(matrix, 0.25, axis=1) if statistic is iqm else np.apply_along_axis(statistic, 1, matrix)
    lo, hi = np.quantile(draws, [(1 - confidence) / 2, (1 + confidence) / 2])
    return point, float(lo), float(hi)


def average_probability_of_improvement(x: np.ndarray, y: np.ndarray) -> float:
    """P(X < Y) per task (columns of two runs x tasks matrices of losses or times), averaged over
    tasks: rliable's ``probability_of_improvement`` for lower-is-better scores."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    return float(np.mean([probability_of_improvement(x[:, t], y[:, t]) for t in range(x.shape[1])]))


def probability_of_improvement_ci(
    x: np.ndarray, y: np.ndarray, reps: int = BOOTSTRAP_REPS, confidence: float = CONFIDENCE, seed: int = 0
) -> tuple[float, float, float]:
    """``average_probability_of_improvement`` with the stratified bootstrap's percentile interval
    (x's and y's runs resampled apart within each task)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    point = average_probability_of_improvement(x, y)
    rng = np.random.default_rng(seed)
    draws = []
    for _ in range(reps):
        rx = np.take_along_axis(x, rng.integers(0, x.shape[0], x.shape), axis=0)
        ry = np.take_along_axis(y, rng.integers(0, y.shape[0], y.shape), axis=0)
        draws.append(average_probability_of_improvement(rx, ry))
    lo, hi = np.quantile(draws, [(1 - confidence) / 2, (1 + confidence) / 2])
    return point, float(lo), float(hi)
