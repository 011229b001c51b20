"""One seed rule for every claim read from runs (``rules.seed_gate``), computed from the runs.

Runs on the committed results (docs/results: each claim's row, the runs its figures list and
their plotted data) and on synthetic rows. No training.
"""

from pathlib import Path

import pytest

from higbench.claims.rules import (
    NO_RUNS,
    NOT,
    PARTLY,
    REPRODUCED,
    REQUIRED_SEEDS,
    claim_seeds,
    finish,
    reads_run,
    seeds_read,
    sidecar_seeds,
)
from higbench.figures import registry
from higbench.figures.report import collect, sidecars

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results"
# Single-seed comparisons the committed report read as `reproduced` under the per-claim `min_seeds` it had.
SINGLE_SEED_ONCE_REPRODUCED = ("osc-1", "poi-3", "poi-3a", "poi-5", "dip-5", "dip-6", "abl-2", "abl-4")


def _row(cid, seeds, values=None, verdict=REPRODUCED):
    return {"id": cid, "rule_verdict": verdict, "why": "rule", "values": values or {}, "seconds": 1e9, "seeds": seeds}


@pytest.mark.parametrize("cid", sorted(registry.claims()))
def test_no_claim_escapes_the_seed_rule(cid):
    """Every claim, whatever it declares: a passing rule on one seed per setting reads `partly` with
    the seed cause, whatever margin it records; on three seeds, or no runs, it passes."""
    c = registry.claims()[cid]
    capped = finish(c, _row(cid, 1))
    assert capped["verdict"] == PARTLY and capped["cause"][0] == "seeds", capped
    if c.decide is None:  # a rule decided from stored values needs all of them: margin alone is no row of it
        assert finish(c, _row(cid, 1, {"margin": 1e9}))["verdict"] == PARTLY  # no margin excuses one seed
    assert finish(c, _row(cid, REQUIRED_SEEDS))["verdict"] == REPRODUCED
    assert finish(c, _row(cid, NO_RUNS))["verdict"] == REPRODUCED  # a benchmark table: no runs, no seeds


@pytest.mark.parametrize("cid", ["dip-8", "toy-2", "abl-2"])
def test_a_negative_verdict_on_one_seed_is_raised_to_partly(cid):
    """Fails on the old rule (it capped `reproduced` only): a `not` on one seed reads `partly` with the
    seed cause, which says what the rule said; on three seeds the `not` stands."""
    c = registry.claims()[cid]
    one = finish(c, _row(cid, 1, verdict=NOT))
    assert one["verdict"] == PARTLY and one["cause"][0] == "seeds" and "'not'" in one["cause"][1], one
    assert finish(c, _row(cid, REQUIRED_SEEDS, verdict=NOT))["verdict"] == NOT
    assert finish(c, _row(cid, 1, verdict=PARTLY))["verdict"] == PARTLY


def test_committed_dip8_not_rests_on_one_seed_and_reads_partly():
    """Fails on the old rule: dip-8's `not` (fig. 9, one seed per τ) was published as `not`."""
    row = {r["id"]: r for r in collect(RESULTS)}["dip-8"]
    assert row["rule_verdict"] == NOT and row["seeds"] == 1
    assert row["verdict"] == PARTLY and row["cause"][0] == "seeds" and "hardware" in row["cause"][1]


def test_seeds_are_counted_over_the_runs_the_rule_reads():
    """Fails on the old rule (every run the figure lists): osc-2 reads GN's searched seed alone, which
    is settled, so no seed gate; toy-6 read the trajectory of one seed of fig. 1's three."""
    rows = {r["id"]: r for r in collect(RESULTS)}
    assert rows["osc-2"]["seeds"] == NO_RUNS and rows["osc-2"]["verdict"] == REPRODUCED
    assert rows["osc-1"]["seeds"] == 1  # fig2b's other optimizers: one seed each
    assert rows["toy-6"]["seeds"] == 1 and rows["toy-1"]["seeds"] == 3


def test_reads_selects_figure_sweep_and_overrides():
    reads = ("fig2b:best optimizer=gn",)
    assert reads_run(reads, "fig2b", "best", {"optimizer": "gn", "seed": "7"})
    assert reads_run(reads, "fig2b", "best/search", {"optimizer": "gn", "seed": "3"})  # its search counts with it
    assert not reads_run(reads, "fig2b", "best", {"optimizer": "adam", "seed": "0"})
    assert not reads_run(reads, "fig2c", "best", {"optimizer": "gn", "seed": "7"})
    assert not reads_run(reads, "fig2b", "adam_tuned", {"optimizer": "gn", "seed": "7"})
    assert reads_run((), "any", "sweep", {})  # none declared: every run
    assert reads_run(("fig1",), "fig1", "toy", {"seed": "1"})
    assert seeds_read(3, {"seeds_read": 1}) == 1 and seeds_read(3, {}) == 3 and seeds_read(NO_RUNS, {"seeds_read": 2}) == 2


def test_claim_seeds_in_a_build_counts_the_runs_read():
    from types import SimpleNamespace

    def job(opt, seed, sweep="best", search=None):
        return SimpleNamespace(figure="fig2b", sweep=sweep, seed=seed, overrides={"optimizer": opt, "seed": seed}, search=search)

    gn = job("gn", 7, search=[job("gn", 0, "best/search")])
    datas = {"fig2b": SimpleNamespace(jobs=[job("adam", 0), gn, *gn.search])}
    assert claim_seeds(datas) == 1 and claim_seeds(datas, ("fig2b:best optimizer=gn",)) == NO_RUNS


def test_committed_single_seed_comparisons_read_partly():
    """Fails on the old rule (``min_seeds`` declared per claim, 1 for these): with the committed
    values each of these read `reproduced` on one seed per setting."""
    rows = {r["id"]: r for r in collect(RESULTS)}
    for cid in SINGLE_SEED_ONCE_REPRODUCED:
        row = rows[cid]
        assert row["rule_verdict"] == REPRODUCED and row["seeds"] < REQUIRED_SEEDS, cid
        assert row["verdict"] == PARTLY and row["cause"][0] == "seeds", (cid, row["verdict"], row["why"])


def test_no_committed_row_escapes_the_seed_rule():
    """No `reproduced` and no `not` row rests on fewer than three seeds per setting of the runs its rule reads."""
    for row in collect(RESULTS):
        if row["verdict"] in (REPRODUCED, NOT):
            assert row.get("seeds", NO_RUNS) >= REQUIRED_SEEDS, (row["id"], row["why"])


def test_seeds_are_counted_from_the_runs_listed_not_read_from_the_row():
    infos = sidecars(RESULTS)
    for c in registry.claims().values():
        if c.reads:  # counted over fewer runs than the figures drew it from
            continue
        listed = [infos[f] for f in c.figures if f in infos]
        stored = next(r for i in listed for r in i.get("claims", []) if r["id"] == c.id)
        counted = seeds_read(sidecar_seeds(listed), stored.get("values") or {})
        assert counted == stored["seeds"], c.id  # the same count the figures made when drawn


def test_a_searched_seed_counts_as_settled():
    runs = [{"sweep": "best", "seed": 7, "overrides": ["optimizer=gn", "seed=7", "budget.seconds=900"]}]
    search = [
        {"sweep": "best/search", "seed": s, "overrides": ["optimizer=gn", f"seed={s}", "budget.seconds=15"]} for s in range(3)
    ]
    assert sidecar_seeds([{"id": "f", "runs": runs + search}]) == NO_RUNS
    hig = {"sweep": "best", "seed": 0, "overrides": ["optimizer=hig", "seed=0"]}
    assert sidecar_seeds([{"id": "f", "runs": runs + search + [hig]}]) == 1


def test_reads_name_the_claims_own_figures_and_sweeps():
    """A selector that names no figure of its claim (a typo) would count no run, and the row would escape the gate."""
    figs = registry.figures()
    for c in registry.claims().values():
        for selector in c.reads:
            fid, _, sweep = selector.split()[0].partition(":")
            assert fid in c.figures and fid in figs, (c.id, selector)
            assert not sweep or any(s.name == sweep for s in figs[fid].sweeps), (c.id, selector)
