"""Claims as data: the vocabulary the family modules of ``higbench.paper`` declare each claim of the paper in
(``@claim``: the paper's statement and value, the rule and the measurement its verdict is
decided on, the budget and seeds it needs to show, and its root cause stated from evidence,
``Cause``), the verdict of a claim's row (``judge``, ``finish``), the helpers the measurements
share (values read from runs), the paper's numbers a cause may quote (``PAPER``) and the
budgets sized by them. Runs are read duck-typed: a figure's data answers ``runs(sweep,
**where)`` with runs that have ``curves``, ``cfg(key)``, ``status``, ``seed``, ``logs``."""

from __future__ import annotations

import errno
import io
import json
import math
import os
import stat
import string
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from higbench.bench.paper import PAPER_COSTS
from higbench.claims.reference import TRACE_SECONDS
from higbench.display import sci

REPRODUCED, PARTLY, NOT, NA = "reproduced", "partly", "not", "n/a"
CAUSES = {
    "budget": "too short a budget (the trend points the paper's way)",
    "deviation": "a deviation from the paper forced by cost",
    "unspecified": "a setting the paper does not give",
    "disagreement": "a genuine disagreement with the paper",
    "hardware": "the paper's GPU against this CPU, or the paper's implementation against ours",
    "bug": "a bug (fixed or open)",
    "seeds": "too few seeds for a median",
    "open": "not explained by the runs yet (no cause, its evidence missing, or contradicted by the runs)",
}


class Missing(Exception):
    """The runs a claim needs are missing (verdict n/a)."""


class _Numbers(string.Formatter):
    """str.format with one extra spec: ``{x:e}`` -> sci(x) ('1.2e-5')."""

    def format_field(self, value, spec):
        return sci(value) if spec == "e" else super().format_field(value, spec)


@dataclass(frozen=True)
class Cause:
    """The root cause of a verdict, stated from evidence rather than typed.

    ``text`` is a template: every number in it is a ``{field}`` of the evidence (the values the
    claim's own measurement returned, its budget and seeds, and the numbers in ``PAPER``); a
    test forbids digits outside the fields. ``facts`` are what the text asserts about those
    values (name -> predicate); a cause whose facts do not hold for the runs it sits beside,
    or whose values they lack, is printed as "open" with the reason (``render``). ``probe``:
    more evidence from a committed probe (``probe_values``), its fields prefixed ``probe_``.
    ``otherwise``: the cause stated when this one's facts do not hold (a claim judged at two
    settings, e.g. Poisson's HIG at b=16 and at the paper's b=64, has a cause for each).
    """

    category: str
    text: str
    facts: dict[str, Callable[[dict], bool]] = field(default_factory=dict)
    probe: Callable[[], dict] | None = None
    otherwise: Cause | None = None

    def chain(self) -> list[Cause]:
        """This cause and its alternatives, in the order they are tried."""
        return [self, *(self.otherwise.chain() if self.otherwise else [])]

    def contradicted(self, evidence: dict) -> list[str]:
        """[] if some alternative holds; else the facts the evidence contradicts, of every
        alternative (KeyError: an alternative lacks a value, so it might still hold)."""
        judged = [c._failed(evidence) for c in self.chain()]
        if [] in judged:
            return []
        if None in judged:
            raise KeyError(self.chain()[judged.index(None)]._absent(evidence)[0])
        return [name for wrong in judged for name in wrong]

    def render(self, evidence: dict) -> tuple[str, str]:
        """(category, text) of the first alternative that holds, filled from the evidence; else
        ("open", why): the values an alternative lacks, or (none lacks any) the facts that fail."""
        try:
            wrong = self.contradicted(evidence)
        except KeyError:
            lacking = next(c for c in self.chain() if c._absent(evidence))
            needs = ", ".join(lacking._absent(evidence))
            return "open", f"the stated cause ({lacking.category}) needs {needs}, which these runs' data do not hold"
        if wrong:
            categories = "/".join(c.category for c in self.chain())
            return "open", f"the stated cause ({categories}) is contradicted by these runs: not {'; not '.join(wrong)}"
        holding = next(c for c in self.chain() if c._failed(evidence) == [])
        return holding.category, _Numbers().vformat(holding.text, (), evidence)

    def _absent(self, evidence: dict) -> list[str]:
        """The values the text or the facts quote that the evidence lacks."""
        absent = {  # None is a value the runs did not give (a smoke preset's few updates): absent too
            name for _, name, _, _ in string.Formatter().parse(self.text) if name and evidence.get(name) is None
        }
        try:
            [holds(evidence) for holds in self.facts.values()]
        except KeyError as missing:
            absent.add(missing.args[0])
        return sorted(absent)

    def _failed(self, evidence: dict) -> list[str] | None:
        """The names of the facts that fail ([]: it holds), or None when a value is missing."""
        if self._absent(evidence):
            return None
        return [name for name, holds in self.facts.items() if not holds(evidence)]


@dataclass
class Claim:
    """A headline claim of the paper, checked against the runs of ``figures``.

    measure(datas) -> (measured text, full, partly[, values]): the values behind the rule, read
    from the runs (``datas``: the FigureData of each figure), whether the rule holds fully and
    partly, and the named numbers a cause may quote; full None means the rule cannot be applied
    (n/a, ``partly`` then says why). values["decisive"] = True: the rule's verdict cannot change
    with a longer budget (the budget gate then keeps it).
    """

    id: str
    figures: tuple[str, ...]
    statement: str
    paper: str
    rule: str
    measure: Callable[[dict], tuple]
    min_seconds: float | None = None  # below this training budget per run: "n/a (budget)" unless decided
    cause: Cause | None = None  # root cause of a "not"/"partly" verdict, filled from the evidence
    # decide(values) -> (measured, full, partly[, derived values]): the rule apart from the measurement, which then
    # returns its values only; a committed row is judged again by it from its stored values (``redecide``).
    decide: Callable[[dict], tuple] | None = None
    # The runs the rule reads, where not every run its figures list ("<figure>:<sweep>[ key=value ...]", ``reads_run``):
    # the seed gate counts seeds over these.
    reads: tuple[str, ...] = ()

    def check(self, datas: dict) -> tuple[str, str, str, dict]:
        """(measured, verdict, why, values)."""
        try:
            if self.decide is not None:
                values = self.measure(datas)
                measured, full, partly, *derived = self.decide(values)
                values = {**values, **(derived[0] if derived else {})}
            else:
                measured, full, partly, *rest = self.measure(datas)
                values = rest[0] if rest else {}
        except Missing as m:
            return "-", NA, f"runs missing: {m}", {}
        if full is None:
            return measured, NA, f"rule: {self.rule}; {partly}", values
        return measured, verdict_of(full, partly), f"rule: {self.rule}", values


def verdict_of(full: bool, partly: bool) -> str:
    return REPRODUCED if full else (PARTLY if partly else NOT)


def redecide(c: Claim, row: dict) -> dict:
    """A row judged again by the claim's rule (``Claim.decide``) from its stored values: a rule
    changed since the row was measured applies to it without the runs."""
    values = row.get("values") or {}
    if c.decide is None or not values or row.get("rule_verdict") == NA:
        return row
    try:
        measured, full, partly, *derived = c.decide(values)
    except KeyError as missing:  # measured by an older revision's measurement: it lacks a value the rule reads
        return {**row, "rule_verdict": NA, "why": f"rule: {c.rule}; the stored row lacks {missing}: measure it again"}
    row = {**row, "values": {**values, **(derived[0] if derived else {})}}  # what the rule computed from them
    if full is None:
        return {**row, "measured": measured, "rule_verdict": NA, "why": f"rule: {c.rule}; {partly}"}
    return {**row, "measured": measured, "rule_verdict": verdict_of(full, partly), "why": f"rule: {c.rule}"}


CLAIMS: list[Claim] = []


def claim(cid: str, figures: str, paper: str, *, min_seconds: float | None = None, cause=None, decide=None, reads=()):
    """Declare the decorated measurement a claim: its docstring is the statement, then "Rule: " the
    rule; ``min_seconds``, ``cause``, ``decide`` and ``reads`` as in ``Claim``. How many seeds a
    claim needs is not declared: one rule for all (``seed_gate``)."""

    def declare(measure: Callable) -> Callable:
        statement, _, rule = " ".join(measure.__doc__.split()).partition(" Rule: ")
        figs = tuple(figures.split())
        CLAIMS.append(
            Claim(cid, figs, statement.removesuffix("."), paper, rule, measure, min_seconds, cause, decide, tuple(reads))
        )
        return measure

    return declare


def by_id(items: Iterable, what: str) -> dict:
    """Items (claims, figures) by their ``id``, in order; an id registered twice is an error."""
    out = {}
    for item in items:
        if item.id in out:
            raise ValueError(f"{what} {item.id} registered twice")
        out[item.id] = item
    return out


def below(a: str, b: str) -> Callable[[dict], bool]:
    """A cause's fact: value ``a`` below value ``b``."""
    return lambda v: v[a] < v[b]


# -- values read from runs -------------------------------------------------------------------


def require(*groups, what: str) -> None:
    if any(not g for g in groups):
        raise Missing(what)


def median(values: Iterable[float]) -> float:
    vals = [v for v in values if v is not None and not math.isnan(v)]
    return float(np.median(vals)) if vals else math.nan


def _loss(r) -> np.ndarray:
    return r.curves["test_loss"].to_numpy(dtype=float)


def final(runs: list) -> float:
    """Median over seeds of the final test loss (diverged runs: their last finite value or inf)."""
    return median(float(c[-1]) if len(c) and np.isfinite(c[-1]) else math.inf for c in map(_loss, runs))


def best(runs: list) -> float:
    """Median over seeds of the lowest test loss reached."""
    return median(float(c.min()) if len(c) else math.inf for c in (c[np.isfinite(c)] for c in map(_loss, runs)))


def end_time(r) -> float:
    return float(r.curves["wall_time"].iloc[-1])


def loss_at(run, t: float, column: str = "test_loss", x: str = "wall_time") -> float:
    """Loss at training time t (log-linear interpolation between evaluations; last value after)."""
    xs, ys = run.curves[x].to_numpy(dtype=float), run.curves[column].to_numpy(dtype=float)
    return float(10 ** np.interp(t, xs, np.log10(np.maximum(ys, 1e-300)))) if len(xs) else math.nan


def half_way(runs: list) -> float:
    """Median over seeds of the test loss at half of each run's training time."""
    return median(loss_at(r, 0.5 * end_time(r)) for r in runs)


def oscillation(run) -> float:
    """Median |change of log10 loss| between consecutive evaluations over the run's last half."""
    y = np.log10(_loss(run))
    y = y[len(y) // 2 :]
    return float(np.median(np.abs(np.diff(y)))) if len(y) > 2 else float("nan")


def last_half_trend(run) -> tuple[float, float]:
    """(change of log10 test loss over the run's last half, its standard error), from a
    least-squares line through those evaluations against training time. A noisy plateau
    reads as flat here, where its last value against its half-way value can read as falling."""
    t, y = run.curves["wall_time"].to_numpy(dtype=float), np.log10(_loss(run))
    keep = (t >= 0.5 * t[-1]) & np.isfinite(y)
    t, y = t[keep], y[keep]
    if len(t) < 4:
        return math.nan, math.nan
    (slope, _), cov = np.polyfit(t, y, 1, cov=True)  # cov scaled by the residuals over n-2 degrees of freedom
    span = t[-1] - t[0]
    return float(slope * span), float(math.sqrt(cov[0, 0]) * span)


def falling(change: float, noise: float) -> bool:
    """A trend from ``last_half_trend`` falls when its fall exceeds twice its standard error."""
    return change < -2 * noise


def setting_of(job) -> tuple:
    """A job's setting: its figure, sweep and overrides but the seed (what the seeds of a setting share)."""
    return job.figure, job.sweep, tuple(sorted((k, str(v)) for k, v in job.overrides.items() if k != "seed"))


def by_setting(runs: list) -> list[list]:
    """Runs grouped by setting: the seeds of each."""
    groups: dict[tuple, list] = {}
    for r in runs:
        groups.setdefault(setting_of(r.job), []).append(r)
    return list(groups.values())


def updates_of(r) -> int:
    """Updates the run made (its last evaluation's step)."""
    return int(r.curves["step"].iloc[-1]) if len(r.curves) else 0


def at_update(r, n: float) -> float:
    """Test loss after n updates (log-linear interpolation between evaluations)."""
    return loss_at(r, n, x="step")


def crossing_time(a, b) -> float | None:
    """First evaluation time of ``a`` from which on ``a`` stays below ``b`` (interpolated); None if never."""
    ts, ys = a.curves["wall_time"].to_numpy(dtype=float), _loss(a)
    below_b = [y < loss_at(b, t) for t, y in zip(ts, ys) if t <= min(ts[-1], end_time(b))]
    if not below_b or not below_b[-1]:
        return None
    i = len(below_b) - 1
    while i > 0 and below_b[i - 1]:
        i -= 1
    return float(ts[i])


def budget_of(run) -> str:
    s = run.cfg("budget.seconds")
    return f"{s:g} s" if s is not None else f"{run.cfg('budget.max_updates')} updates"


def stable(r) -> bool:
    return r.status == "completed" and r.final_loss < r.initial_loss


def precision_probe(problem: str) -> Callable[[pd.DataFrame], dict]:
    """The precision probe's runs of ``problem`` (scripts/probe_precision.py): the end loss and
    status at the smaller and larger τ with the inversion in float32 (as the authors' code) and
    float64 (ours)."""

    def read(table: pd.DataFrame) -> dict:
        rows = table[table["problem"] == problem]
        small, large = rows["tau"].min(), rows["tau"].max()
        out = {"tau_small": small, "tau_large": large, "updates": int(rows["updates"].max())}
        for name, tau in (("small", small), ("large", large)):
            for p in ("float32", "float64"):
                row = rows[(rows["tau"] == tau) & (rows["precision"] == p)].iloc[0]
                out[f"{name}_{p}"], out[f"{name}_{p}_status"] = float(row["test_end"]), row["status"]
                out[f"{name}_{p}_over_start"] = float(row["test_end"] / row["test_start"])
            out[f"{name}_single_over_double"] = out[f"{name}_float32"] / out[f"{name}_float64"]
        for p in ("float32", "float64"):
            out[f"{p}_small_over_large"] = out[f"small_{p}"] / out[f"large_{p}"]
        return out

    return read


# -- a claim's row of the report -------------------------------------------------------------


def judge(c: Claim, datas: dict, preset: str, smoke: bool = False) -> dict:
    """A claim's row of the report: its rule on the runs, then the budget, seed and smoke gates
    (``smoke``: the preset's runs stop after a few updates, code paths only)."""
    try:
        measured, verdict, why, values = c.check(datas)
    except Exception as exc:  # noqa: BLE001 - one broken claim does not stop the others
        measured, verdict, why, values = "-", NA, f"could not be evaluated: {type(exc).__name__}: {exc}", {}
    row = {
        "id": c.id,
        "figures": list(c.figures),
        "statement": c.statement,
        "paper": c.paper,
        "measured": measured,
        "budget": "; ".join(sorted({b for d in datas.values() for b in d.budgets.values()})),
        "rule_verdict": verdict,
        "why": why,
        "values": {k: v for k, v in values.items() if isinstance(v, (int, float, str, bool))},
        "seconds": claim_budget(datas),
        "seeds": seeds_read(claim_seeds(datas, c.reads), values),
        "missing": sum(len(d.missing()) for d in datas.values()),
        "smoke": smoke and any(d.jobs for d in datas.values()),
        "preset": preset,
    }
    return finish(c, row)


def evidence(row: dict, cause: Cause | None = None) -> dict:
    """What a cause may quote: the paper's numbers, the row's measured values, budget and seeds,
    and the values of the cause's probe."""
    probe = {k: v for c in (cause.chain() if cause else []) if c.probe is not None for k, v in c.probe().items()}
    return {**PAPER, **row.get("values", {}), "budget": row.get("seconds"), "seeds": row.get("seeds"), **probe}


# Probes: committed, re-runnable sweeps (scripts/probe_*.py) whose per-run tables live here.
PROBES_DIR = Path(__file__).resolve().parents[2] / "docs" / "results" / "probes"


def probe_values(file: str, read: Callable[[pd.DataFrame], dict]) -> Callable[[], dict]:
    """A ``Cause.probe``: ``read`` applied to the probe's CSV, its keys prefixed ``probe_``;
    nothing when the file is not there (an installed package), so the cause reads "open"."""

    def values() -> dict:
        path = PROBES_DIR / file
        return {f"probe_{k}": v for k, v in read(pd.read_csv(path)).items()} if path.is_file() else {}

    return values


def finish(c: Claim, row: dict) -> dict:
    """The verdict and cause of a row of measured values (fresh from runs, or committed data).

    The budget gate turns a verdict into "n/a (budget)" only where the rule has neither passed
    nor failed decisively (values["decisive"]): a passing rule is evidence at any budget. The seed
    gate (``seed_gate``) is one rule for every claim read from runs, for a `reproduced` and a `not`.
    """
    row = redecide(c, row)
    verdict, why, seconds, seeds = row["rule_verdict"], row["why"], row.get("seconds"), row.get("seeds", 99)
    cause = None
    if row.get("missing") and verdict != NA:
        why += f" ({row['missing']} run(s) missing)"
    short = c.min_seconds and seconds is not None and seconds < c.min_seconds
    if short and verdict not in (NA, REPRODUCED) and not row.get("values", {}).get("decisive"):
        why = f"budget {seconds:g} s per run is below the {c.min_seconds:g} s this claim needs to show; {would(verdict)}{why}"
        verdict, cause = "n/a (budget)", ("budget", f"needs >= {c.min_seconds:g} s per run")
    elif verdict in (REPRODUCED, NOT) and (note := seed_gate(row)) is not None:
        why = f"{note} {would(verdict)}{why}"
        cause = ("seeds", f"{seeds} seed(s) per setting at this preset; on them the rule says '{verdict}'")
        if c.cause is not None:  # what the claim's own cause says of that seed: for a `not`, and where it holds
            category, text = c.cause.render(evidence(row, c.cause))
            if verdict == NOT or category != "open":
                cause = (cause[0], f"{cause[1]}, and the claim's cause for it ({category}) reads: {text}")
        verdict = PARTLY
    if row.get("smoke") and verdict != NA:
        why = f"smoke preset ({row['preset']}: a few updates per run) checks code paths only, no verdict; {would(verdict)}{why}"
        verdict = NA
    if verdict in (NOT, PARTLY) and cause is None:
        cause = c.cause.render(evidence(row, c.cause)) if c.cause else ("open", "no cause stated for this verdict")
    return {**row, "verdict": verdict, "why": why, "cause": list(cause) if cause and verdict not in (REPRODUCED, NA) else None}


def rule_why(why: str) -> str:
    """The rule's own explanation in a finished row's ``why``: the gates' notes taken off again
    (``finish`` adds them anew when a committed row is judged again)."""
    why = why[why.find("rule: ") :] if "rule: " in why else why
    head, sep, tail = why.rpartition(" (")
    return head if sep and tail.endswith(" run(s) missing)") else why


def contradictions(c: Claim, row: dict) -> list[str]:
    """The facts of the claim's cause that its row's values contradict (for a "not"/"partly" row
    whose verdict is the rule's: a row the seed gate caps shows the gate's cause, not the claim's)."""
    if c.cause is None or row["verdict"] not in (NOT, PARTLY) or row.get("rule_verdict") == REPRODUCED:
        return []
    try:
        return c.cause.contradicted(evidence(row, c.cause))
    except KeyError:
        return []  # evidence missing: rendered as "open", not as a contradiction


def would(verdict: str) -> str:
    return f"the rule would say '{verdict}'. "


def _main_jobs(datas: dict) -> list:
    return [j for d in datas.values() for j in d.jobs if not j.sweep.endswith("/search")]


def claim_budget(datas: dict) -> float | None:
    """The smallest training budget in seconds of the claim's runs (None: budgets in updates)."""
    secs = [float(s) for j in _main_jobs(datas) if (s := j.overrides.get("budget.seconds")) is not None]
    return min(secs) if secs else None


NO_RUNS = 99  # a row's "seeds" when no run is behind it (the benchmark tables): no seed gate


def fewest_seeds(runs: Iterable[tuple[tuple, int, bool]]) -> int:
    """The fewest seeds of any setting among ``runs`` given as (setting, seed, settled): a setting
    whose seed came from a seed search counts as settled (the paper's fixed seed, picked as the
    best stable one); ``NO_RUNS`` when there are none."""
    groups: dict[tuple, set] = {}
    for setting, seed, settled in runs:
        if not settled:
            groups.setdefault(setting, set()).add(seed)
    return min(len(s) for s in groups.values()) if groups else NO_RUNS


def _fields(overrides: dict, seed) -> dict[str, str]:
    """A run's overrides as text, keyed as the command line names them (a config group's choice by the
    group: ``optimizer``, not ``optimizer.name``), its seed among them."""
    return {str(k).removesuffix(".name"): str(v) for k, v in overrides.items()} | {"seed": str(seed)}


def reads_run(reads: Iterable[str], figure: str, sweep: str, fields: dict[str, str]) -> bool:
    """Whether a claim whose rule reads ``reads`` (``Claim.reads``: "<figure>:<sweep>[ key=value ...]";
    none: every run) reads a run of ``figure``'s ``sweep`` with these override ``fields``. A seed
    search's runs count with the sweep they search for."""
    reads = list(reads)
    if not reads:
        return True
    for selector in reads:
        where, *pairs = selector.split()
        fid, _, want = where.partition(":")
        if fid != figure or (want and want != sweep.removesuffix("/search")):
            continue
        if all(fields.get(k) == v for k, _, v in (p.partition("=") for p in pairs)):
            return True
    return False


def claim_seeds(datas: dict, reads: Iterable[str] = ()) -> int:
    """The fewest seeds of any setting (sweep and overrides but the seed) among the runs the claim's
    rule reads (``reads``; none: every run of its figures)."""
    jobs = [j for j in _main_jobs(datas) if reads_run(reads, j.figure, j.sweep, _fields(j.overrides, j.seed))]
    return fewest_seeds((setting_of(j), j.seed, bool(j.search)) for j in jobs)


def seeds_read(counted: int, values: dict) -> int:
    """The seeds behind a row: those counted over the runs its rule reads, or fewer where its
    measurement read only some of their seeds (values["seeds_read"]: e.g. a log kept for one seed)."""
    read = values.get("seeds_read")
    return min(counted, int(read)) if isinstance(read, (int, float)) and read > 0 else counted


def sidecar_seeds(infos: Iterable[dict], reads: Iterable[str] = ()) -> int:
    """``claim_seeds`` from the figures' data files (<id>.json, their "runs"): the seeds behind a
    committed row, computed again from the runs it lists rather than read from the row."""
    entries = [(info["id"], r) for info in infos for r in info.get("runs", [])]

    def setting(fid: str, r: dict) -> tuple:
        keep = sorted(o for o in r["overrides"] if not o.startswith(("seed=", "budget.", "init_from=")))
        return fid, r["sweep"].removesuffix("/search"), tuple(keep)

    def fields(r: dict) -> dict[str, str]:
        return _fields(dict(o.partition("=")[::2] for o in r["overrides"]), r["seed"])

    entries = [(fid, r) for fid, r in entries if reads_run(reads, fid, r["sweep"], fields(r))]
    searched = {setting(fid, r) for fid, r in entries if r["sweep"].endswith("/search")}
    mains = [(fid, r) for fid, r in entries if not r["sweep"].endswith("/search")]
    return fewest_seeds((setting(fid, r), r["seed"], setting(fid, r) in searched) for fid, r in mains)


# -- the seed gate: one rule for every claim read from runs ------------------------------------

REQUIRED_SEEDS = 3  # a median needs three


# -- reading a results directory -------------------------------------------------------------


class ResultsFileError(ValueError):
    """A file of a results directory that cannot be what it should be (one line naming it)."""


def read_results_text(path: Path) -> str:
    """The text of a file of a results directory. Opened without blocking and checked on the
    open file, so a FIFO (or a device, a directory) among the results is refused, never waited on;
    never through a link (one planted there would put a file from elsewhere into the report)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise ResultsFileError(f"{path}: a symbolic link; results are read only from the files themselves") from None
        raise ResultsFileError(f"{path}: cannot be read ({exc.strerror})") from None
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise ResultsFileError(f"{path}: not a regular file")
        data = f.read()
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ResultsFileError(f"{path}: not UTF-8 text") from None


def read_results_json(path: Path) -> Any:
    text = read_results_text(path)
    try:
        return json.loads(text)
    except ValueError as exc:
        raise ResultsFileError(f"{path}: malformed JSON ({exc})") from None


def read_results_csv(path: Path) -> pd.DataFrame:
    text = read_results_text(path)
    try:
        return pd.read_csv(io.StringIO(text))
    except (ValueError, pd.errors.ParserError) as exc:
        raise ResultsFileError(f"{path}: malformed CSV ({str(exc).strip()})") from None


def read_sidecars(out_dir: Path) -> dict[str, dict]:
    """Every figure's data file (<id>.json with an "id") in ``out_dir``, by id; other JSON
    there is passed over, an unreadable or malformed file refused (``ResultsFileError``)."""
    figs = {}
    for path in sorted(Path(out_dir).glob("*.json")):
        info = read_results_json(path)
        if isinstance(info, dict) and "id" in info:
            figs[info["id"]] = info
    return figs


def seed_gate(row: dict) -> str | None:
    """The one seed rule, for every claim read from runs, both ways: a verdict resting on fewer than
    ``REQUIRED_SEEDS`` seeds per setting of the runs its rule reads (row["seeds"]) is neither
    `reproduced` nor `not`: one seed can flip either, so it reads `partly`. No margin excuses it: a
    between-seed spread measured on other settings (another problem, or a setting the paper calls
    unstable) says nothing about how far this comparison's seeds move. The gate's note; None: it
    does not apply (enough seeds, or no runs behind the row)."""
    seeds = row.get("seeds", NO_RUNS)
    if not isinstance(seeds, int) or seeds >= REQUIRED_SEEDS or seeds >= NO_RUNS:
        return None
    need = f"a verdict needs the median of {REQUIRED_SEEDS}"
    return f"{seeds} seed(s) per setting of the runs the rule reads ({need}), so partly whichever way the rule goes;"


# -- the numbers a cause may quote besides its runs', and budgets sized by them ---------------


def _update_s(problem: str, optimizer: str, b: int) -> float:
    """The paper's seconds per update (tables 3-5, ``higbench.bench.paper``: the one copy)."""
    return PAPER_COSTS[(problem, optimizer, b)][1]


PAPER = {
    "paper_toy_plateau": 0.2,  # figure 1b
    "paper_osc_hig_level": 1e-7,  # section 3.1: HIG's final loss on the oscillators
    "paper_osc_hig_update_s": _update_s("oscillator", "hig", 128),
    "paper_osc_adam_update_s": _update_s("oscillator", "adam", 512),
    "paper_poisson_hig_update_s": _update_s("poisson", "hig", 64),
    "paper_poisson_b": 64,
    "paper_dipole_limit": 1e-6,  # section 3.3
    "float32_floor": 1e-7,  # below this a float32 evaluation of the dipole loss is rounding (±2e-7 per sample)
    "paper_osc_memory_ratio": PAPER_COSTS[("oscillator", "hig", 128)][0] / PAPER_COSTS[("oscillator", "hig", 32)][0],
    "ref_hig_trace_s": TRACE_SECONDS["hig"],  # the authors' code on this machine kind (reference.py)
}


# Each problem's documented training run: (seconds, source). The paper states none; the authors'
# scripts (github.com/tum-pbs/half-inverse-gradients) set these, and the Poisson one sets none.
RUN_LENGTH: dict[str, tuple[float | None, str]] = {
    "oscillator": (60 * 60.0, "the authors' oscillator scripts (Nonlinear_oscillators/submit_*.py) stop after 60 min"),
    "dipole": (90 * 60.0, "the authors' dipole scripts (Quantum_dipole/submit_*.py) stop after 90 min"),
    "poisson": (
        None,
        "none: the paper says the task 'requires longer training runs' and that neither method has fully converged; "
        "the authors' Poisson script runs until stopped",
    ),
}


def float32_loss(v: float) -> str:
    """A dipole loss as text: below the float32 floor the evaluation is rounding, so the value says nothing."""
    return f"below {sci(PAPER['float32_floor'])} (float32 evaluation)" if v < PAPER["float32_floor"] else sci(v)


def documented_updates(problem: str, paper_update_s: float) -> int:
    """Updates the paper's GPU makes in the problem's documented run (``RUN_LENGTH``)."""
    seconds = RUN_LENGTH[problem][0]
    if seconds is None:
        raise ValueError(f"{problem}: no documented run length ({RUN_LENGTH[problem][1]})")
    return int(seconds // paper_update_s)


PAPER["osc_hig_run_updates"] = documented_updates("oscillator", PAPER["paper_osc_hig_update_s"])  # 24,657


def documented_run_here(problem: str, paper_update_s: float, here_update_s: float) -> float:
    """Training seconds in which higbench makes the updates of the problem's documented run on the
    paper's GPU (rounded up to 10 s).

    A claim on the level the paper reached at the end of its run is a claim on what that many
    updates achieve; higbench's cost per update on one CPU core differs from the paper's GPU (and
    per optimizer). higbench, one idle core: oscillator HIG b=128 30 ms, Adam b=512 4.5 ms; dipole
    HIG b=16 43.6 ms (docs/benchmarks.md). Under load these grow, so a budget sized this way is a
    lower bound."""
    return float(-(-documented_updates(problem, paper_update_s) * here_update_s // 10) * 10)


OSC_HIG_RUN = documented_run_here("oscillator", PAPER["paper_osc_hig_update_s"], 0.030)  # 740 s
OSC_ADAM_RUN = documented_run_here("oscillator", PAPER["paper_osc_adam_update_s"], 0.0045)  # 200 s
DIPOLE_HIG_RUN = documented_run_here("dipole", _update_s("dipole", "hig", 16), 0.0436)  # 400 s
