"""Figures machinery without training: registry, presets, run identity, grouping into Hydra multiruns."""

from __future__ import annotations

import json
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from higbench.figures import registry
from higbench.figures.spec import PRESETS, Preset, expand
from higbench.jobs import Job, Launcher, fmt, identity_of, job_seconds, multirun_command
from higbench.results.index import COSMETIC_KEYS

# The paper's numbered figures and tables that higbench regenerates (docs/figures.md; figures 2-4 have
# panels a-c drawn apart, fig12's a/b panels are one figure): the ids themselves are the registry's.
PAPER_FIGURES, PAPER_TABLES = range(1, 14), range(2, 6)


def test_registry_holds_every_figure_and_table_of_the_paper_in_its_order():
    ids = list(registry.figures())
    numbered = {kind: {int(m[1]) for i in ids if (m := re.fullmatch(rf"{kind}(\d+)[a-z]?", i))} for kind in ("fig", "table")}
    assert numbered["fig"] >= set(PAPER_FIGURES) and numbered["table"] >= set(PAPER_TABLES)
    assert {"fig2a", "fig2b", "fig2c", "fig3a", "fig3b", "fig3c", "fig4a", "fig4b", "fig4c"} <= set(ids)
    assert ids == sorted(ids, key=registry._order) and ids.index("table2") > ids.index("fig13")  # figures, then tables


def test_every_claim_names_registered_figures():
    figs = registry.figures()
    claims = registry.claims()
    assert len(claims) >= 20
    for c in claims.values():
        assert all(f in figs for f in c.figures), c.id


@pytest.mark.parametrize("preset", PRESETS)
def test_every_figure_expands_at_every_preset(preset, tmp_path):
    from higbench.cards import problem_configs

    shipped_problems = problem_configs()
    p = Preset(preset, str(tmp_path))  # no bench tables under tmp_path: tables declare timing runs
    for fid, fig in registry.figures().items():
        jobs = expand(fig, p)
        assert jobs, fid
        for j in jobs:
            ov = j.overrides
            assert ov["problem"] in shipped_problems, (fid, ov)
            assert "seed" in ov
            if preset == "smoke":
                assert ov["budget.max_updates"] <= 2 and ov["budget.seconds"] is None, (fid, ov)
            else:
                assert (ov.get("budget.seconds") or 0) > 0 or ov["budget.max_updates"] >= 1, (fid, ov)
                if preset == "paper" and j.figure.startswith("fig") and j.figure != "fig1" and not j.sweep.endswith("/search"):
                    assert ov["budget.seconds"] == 3600, (fid, ov)  # the paper's hour per run
            if j.parent is not None:
                assert j.parent in jobs and jobs.index(j.parent) < jobs.index(j), fid
            for s in j.search:  # seed-search runs come before the run whose seed they pick
                assert s in jobs and jobs.index(s) < jobs.index(j), fid


@pytest.mark.parametrize("preset, panels", [("standard", 2), ("long", 4)])
def test_fig3b_draws_the_authors_setup_where_hig_runs_at_b64(preset, panels, tmp_path, monkeypatch):
    from higbench.figures import plot
    from higbench.figures.data import FigureData

    fig, p = registry.figures()["fig3b"], Preset(preset, str(tmp_path))
    jobs = expand(fig, p)
    theirs = [j for j in jobs if j.sweep.endswith("_authors")]
    assert len(theirs) == (4 if preset == "long" else 0)
    for j in theirs:  # the authors' script: PhiFlow noise, network [64, 128, 64], b = 64
        assert "problem.data=phiflow_noise" in j.override_list() and "problem.hidden=[64,128,64]" in j.override_list()
        assert j.overrides.get("batch_size", 64) == 64
    data, saved = FigureData(fig, p, tmp_path, jobs), []
    monkeypatch.setattr(data, "save", saved.append)
    plot.draw(data)
    titles = [ax.get_title() for ax in saved[0].axes]
    assert len(titles) == panels and ["authors'" in t for t in titles] == [False, False, True, True][:panels]


def test_quick_budgets_are_smaller_than_paper_and_smoke_is_small():
    counts = {}
    for preset in PRESETS:
        seen = {}
        for fig in registry.figures().values():
            for j in expand(fig, Preset(preset)):
                seen[tuple(j.override_list())] = j
        counts[preset] = seen
    quick_s = sum(j.overrides.get("budget.seconds") or 0 for j in counts["quick"].values())
    paper_s = sum(j.overrides.get("budget.seconds") or 0 for j in counts["paper"].values())
    assert quick_s < 3600 * 1.75  # under an hour of wall clock on 2 parallel jobs (seed-search duplicates counted twice here)
    assert paper_s >= 3600 * 100
    assert len(counts["smoke"]) <= 80


def test_fmt_values_for_hydra_overrides():
    assert fmt(None) == "null" and fmt(True) == "true" and fmt(3e-4) == "0.0003" and fmt(1e-10) == "1e-10"
    assert fmt(128) == "128" and fmt("hig") == "hig"
    assert fmt("/a b/run.h5").startswith("'")


def test_identity_ignores_cosmetic_keys_and_follows_init_from():
    base = {"seed": 0, "batch_size": 16, "optimizer": {"name": "hig", "lr": 1.0}, "init_from": None}
    ident = identity_of(base)
    for key in COSMETIC_KEYS:
        assert identity_of({**base, key: "something"}) == ident, key
    assert identity_of({**base, "batch_size": 32}) != ident
    assert identity_of({**base, "optimizer": {"name": "hig", "lr": 0.5}}) != ident
    a = identity_of({**base, "init_from": "/x/run.h5"}, "p1")
    b = identity_of({**base, "init_from": "/elsewhere/run.h5"}, "p1")
    c = identity_of({**base, "init_from": "/x/run.h5"}, "p2")
    assert a == b != c


def _jobs(rows: list[dict]) -> list[Job]:
    return [Job("f", "s", dict(r), seed=0) for r in rows]


def test_a_round_is_one_job_list_multirun_on_a_hydra_launcher(tmp_path):
    jobs = tmp_path / "jobs.json"
    joblib = Launcher("joblib").args(n_runs=4, n_jobs=2, seconds=240)
    assert joblib == ["hydra/launcher=joblib", "hydra.launcher.n_jobs=2"]
    cmd = multirun_command(jobs, tmp_path / "s", joblib)
    assert cmd[1:6] == ["-m", "higbench.cli", "-m", "hydra/sweeper=joblist", f"hydra.sweeper.jobs_file={jobs}"]
    assert f"hydra.sweep.dir={tmp_path / 's'}" in cmd and cmd[-2:] == joblib
    assert Launcher("joblib").args(n_runs=1, n_jobs=2, seconds=240) == []  # one run: Hydra's basic launcher
    assert Launcher("auto").args(n_runs=4, n_jobs=2, seconds=4) == []  # a few seconds: no worker start-up
    slurm = Launcher("slurm", ("hydra.launcher.partition=gpu",))
    assert slurm.args(n_runs=4, n_jobs=2, seconds=240) == ["hydra/launcher=slurm", "hydra.launcher.partition=gpu"]
    with pytest.raises(ValueError, match="only hydra"):
        Launcher("slurm", ("optimizer.lr=1",))  # would change the runs, not where they run


def test_launch_sends_every_job_in_one_multirun_longest_first(tmp_path, monkeypatch):
    from higbench import jobs as runs

    calls = []

    def fake_run(cmd, **kwargs):
        calls.append(cmd)
        jobs = json.loads(Path(next(a for a in cmd if "jobs_file=" in a).split("=", 1)[1]).read_text())
        sweep = Path(next(a for a in cmd if a.startswith("hydra.sweep.dir=")).split("=", 1)[1])
        for i in range(len(jobs)):
            (sweep / str(i)).mkdir()
            (sweep / str(i) / "run.h5").write_bytes(b"")

        class Done:
            returncode = 0

        return Done()

    monkeypatch.setattr(runs, "run_to_end", fake_run)
    short = [{"optimizer": o, "seed": s, "budget.seconds": 15.0} for o in ("adam", "sgd") for s in (0, 1)]
    long = [{"optimizer": "hig", "seed": 0, "batch_size": 128, "budget.seconds": 240.0}]
    written = runs.launch(_jobs(short + long), tmp_path, n_jobs=3, launcher="joblib", log=lambda *a: None)
    assert len(calls) == 1 and len(written) == 5
    assert calls[0][-2:] == ["hydra/launcher=joblib", "hydra.launcher.n_jobs=3"]
    jobs = json.loads((Path(written[0]).parents[1] / "jobs.json").read_text())
    assert jobs[0][:2] == ["optimizer=hig", "seed=0"] and len(jobs) == 5  # the longest run starts first


def test_joblist_sweeper_runs_a_job_list(higbench, tmp_path):
    """The plugin through Hydra: two jobs that are no cartesian product, in one multirun."""
    jobs = tmp_path / "jobs.json"
    jobs.write_text(json.dumps([["optimizer=hig", "budget.max_updates=2"], ["optimizer=adam", "seed=1", "budget.max_updates=3"]]))
    args = ["-m", "problem=toy", "hydra/sweeper=joblist", f"hydra.sweeper.jobs_file={jobs}"]
    args += ["budget.seconds=5", "eval_unit=updates", "eval_every=1", "progress=false", f"hydra.sweep.dir={tmp_path / 's'}"]
    code, out, err = higbench(*args, tiny=False)
    assert code == 0, out[-2000:] + err[-2000:]
    made = sorted(p.parent.name for p in (tmp_path / "s").rglob("run.h5"))
    assert len(made) == 2 and "optimizer=adam" in made[1] and "seed=1" in made[1]


def test_missing_runs_go_out_as_one_multirun_longest_first(tmp_path, monkeypatch):
    """The figures schedule nothing themselves: a round of missing runs is one ``higbench -m``
    over a job list (Hydra's launcher runs it), longest first, joblib capped at --jobs."""
    from higbench import jobs as runs

    calls = []
    monkeypatch.setattr(runs, "run_to_end", lambda cmd, **kw: calls.append(cmd) or SimpleNamespace(returncode=0))
    jobs = [Job("f", "s", {"budget.seconds": t, "seed": i}, seed=i) for i, t in enumerate([20, 90, 45])]
    runs.launch(jobs, tmp_path, n_jobs=2, log=lambda _: None)
    assert len(calls) == 1, calls
    cmd = calls[0]
    assert cmd[1:5] == ["-m", "higbench.cli", "-m", "hydra/sweeper=joblist"]
    assert "hydra/launcher=joblib" in cmd and "hydra.launcher.n_jobs=2" in cmd
    jobs_file = Path(next(a for a in cmd if a.startswith("hydra.sweeper.jobs_file=")).split("=", 1)[1])
    listed = json.loads(jobs_file.read_text())
    assert [job[0] for job in listed] == ["budget.seconds=90", "budget.seconds=45", "budget.seconds=20"]


def test_a_stopped_figure_run_is_resumed_in_place_for_the_rest_of_its_budget(tmp_path, monkeypatch):
    """A figure run cut off (a session's end) continues from its checkpoint: the round's multirun
    gets ``resume=<its run dir>``, the same run file completes, and no second run is made."""
    from reliability.rel_helpers import stopped_run

    from higbench import jobs as runs
    from higbench.runfile.reader import read_head

    # Only an update budget: with the toy's default 30 s beside it, a loaded machine ran out of
    # seconds first (914 of 1,000 updates) and the run completed short.
    overrides = {"problem": "toy", "optimizer": "adam", "budget.max_updates": 1000, "eval_unit": "updates", "eval_every": 5}
    overrides["budget.seconds"] = None
    run = tmp_path / "figures-runs" / "earlier" / "0" / "run.h5"
    run.parent.mkdir(parents=True)
    stopped_run(run, monkeypatch, overrides=["budget.seconds=null"], after=25)  # the same config, stopped after 25 loop turns
    job = Job("f", "s", dict(overrides), seed=0)
    runs.resolve([job], runs.run_index(tmp_path))
    assert job.status == "interrupted" and not job.done and job.resume_from == run.resolve()
    assert job.launch_overrides() == [f"resume={run.resolve().parent}"]
    from in_process import launch_in_process

    launched = launch_in_process(monkeypatch)  # the launcher's command line, run here
    written = runs.launch([job], tmp_path, n_jobs=1, log=lambda _: None)
    assert len(launched) == 1
    assert written == [run.resolve()]  # the run continued where it was: no new run file
    head = read_head(run)
    assert str(head.attrs["status"]) == "completed" and int(head.attrs["steps"]) == 1000, dict(head.attrs)
    again = Job("f", "s", dict(overrides), seed=0)
    runs.resolve([again], runs.run_index(tmp_path))
    assert again.done and again.path == run.resolve() and again.resume_from is None


def test_a_resumed_job_counts_only_the_budget_it_has_left():
    job = Job("f", "s", {"budget.seconds": 3000.0}, seed=0)
    assert job_seconds(job) == 3000.0
    job.resume_from, job.clock_done = Path("x/run.h5"), 2394.5
    assert job_seconds(job) == pytest.approx(605.5)
    assert job.launch_overrides() == ["resume=x"]


def test_the_launch_line_counts_update_budgets_as_updates():
    from higbench.jobs import training_text

    timed = Job("f", "s", {"budget.seconds": 60.0}, seed=0)
    counted = Job("f", "s", {"budget.seconds": None, "budget.max_updates": 24657}, seed=0)
    assert training_text([timed, timed]) == "~120 s of training"
    assert training_text([timed, counted, counted]) == "~60 s of training and 49,314 updates"  # not 49,374 s
    assert training_text([Job("f", "s", {}, seed=0)]) == "1 on the problem's default budget"


def test_cli_lists_figures_and_plans_without_running(tmp_path, capsys):
    from higbench.figures.__main__ import main

    assert main(["--list"]) == 0
    out = capsys.readouterr().out
    assert [line.split()[0] for line in out.splitlines()] == list(registry.figures())
    assert main(["nope", "--preset", "smoke"]) == 2
    assert main(["fig1", "--plan", "--preset", "smoke", "--runs-root", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert re.search(r"^fig1\s+14\s+14\s", out, re.M), out  # 2 gammas x 3 optimizers x 2 seeds + re-tuned Adam x 2 seeds
    assert not any(Path(tmp_path / "o").rglob("*.h5"))


def test_plan_counts_a_run_two_figures_share_once_even_while_it_waits(tmp_path):
    from higbench.figures.build import plan

    seconds = {fid: s for fid, _, _, s in plan(["fig3c", "fig7"], "long", tmp_path)}
    assert seconds["fig3c"] == 10 * 3000  # per setup: Adam's pre-training and 4 runs continued from it
    assert seconds["fig7"] == 10 * 3000  # fig3b's other 8 runs and 2 Adam-after-HIG runs; not fig3c's waiting ones again


def test_tables_3_to_5_use_the_benchmark_scripts_table_when_present(tmp_path, monkeypatch):
    import json

    import pandas as pd

    from higbench.figures import build as build_module
    from higbench.figures.build import build
    from higbench.runner import revision

    # The checkout counts as modified once the build has written its outputs: the revision recorded must be read first.
    written = lambda: (tmp_path / "figs").is_dir() and any((tmp_path / "figs").iterdir())  # noqa: E731
    monkeypatch.setattr(revision, "git_revision", lambda: "a" * 40 + ("-dirty" if written() else ""))
    build_module._revision.cache_clear()  # read once per process: here, by this build

    bench = tmp_path / "outputs" / "bench"
    bench.mkdir(parents=True)
    rows = [
        ("oscillator", "adam", 512, "-", 0.10, 3),
        ("oscillator", "hig", 128, "structured", 0.25, 3),
        ("oscillator", "hig", 128, "naive", 2.0, 3),
        ("dipole", "adam", 256, "-", 0.4, 5),
    ]
    pd.DataFrame(
        [
            {
                "problem": p,
                "optimizer": o,
                "batch_size": b,
                "jacobian": j,
                "solver": "-",
                "update_s": u,
                "jacobian_s": u / 2,
                "inversion_s": 0.0,
                "peak_mem_mb": 5.0,
                "threads": 1,
                "table": t,
                "paper_mem_mb": None,
                "paper_update_s": None,
                "paper_jacobian_s": None,
            }
            for p, o, b, j, u, t in rows
        ]
    ).to_csv(bench / "paper_tables.csv", index=False)
    try:
        result = build(["table3"], preset="smoke", runs_root=tmp_path / "outputs", out_dir=tmp_path / "figs", bench=False)
    finally:
        build_module._revision.cache_clear()  # not this fake revision for later tests
    assert result.launched == 0 and result.drawn == ["table3"]
    table = pd.read_csv(tmp_path / "figs" / "table3.csv")
    assert list(zip(table["Optimizer"], table["Batch size"], table["Update duration (s)"])) == [
        ("Adam", 512, 0.10),
        ("HIG", 128, 0.25),
        ("HIG", 128, 2.0),
    ]
    report = (tmp_path / "figs" / "REPORT.md").read_text()
    assert "HIG 0.25 s / Adam 0.1 s = 2.5x" in report and "**reproduced**" in report  # 2.5x vs the paper's 1.8x: within 3x
    assert json.loads((tmp_path / "figs" / "table3.json").read_text())["made"]["revision"] == "aaaaaaa"


def _fake_run(t, loss, **cols):
    import pandas as pd

    from higbench.figures.data import RunData

    r = RunData(Job("f", "s", {}, seed=0, status="completed"))
    r.__dict__["_run"] = ({}, pd.DataFrame({"wall_time": t, "test_loss": loss, **cols}))
    return r


def test_claim_helpers_crossing_time_and_plateau():
    from higbench.claims.rules import crossing_time, final, loss_at
    from higbench.paper.dipole import energy_ratio, plateau_seconds

    adam = _fake_run([0, 100, 200, 300], [1.0, 1e-3, 1e-4, 1e-4])
    hig = _fake_run([0, 100, 200, 300], [1.0, 1e-2, 1e-5, 1e-7])
    assert crossing_time(hig, adam) == 200
    assert crossing_time(adam, hig) is None  # Adam ends above HIG
    assert loss_at(adam, 150) == pytest.approx(10**-3.5)
    assert final([adam, hig]) == pytest.approx(np.median([1e-4, 1e-7]))
    stall = _fake_run(
        [0, 10, 20, 30, 40],
        [1.0, 0.5, 0.5, 0.5, 0.1],
        test_low_energy_loss=[0.5, 0.01, 0.01, 0.01, 0.01],
        test_high_energy_loss=[0.5, 0.4, 0.4, 0.3, 0.05],
    )
    assert plateau_seconds(stall) == pytest.approx(30)  # a duration: a longer run keeps it
    longer = _fake_run([0, 10, 20, 30, 40, 400], [1.0, 0.5, 0.5, 0.5, 0.1, 1e-3])
    assert plateau_seconds(longer) == pytest.approx(30)
    # the initial stage only (loss >= 0.4, after the first evaluation): the last evaluation (0.1) is left out
    assert energy_ratio(stall) == pytest.approx(np.median([40, 40, 30]))
    passed = _fake_run([0, 10], [1.0, 0.1], test_low_energy_loss=[0.5, 0.01], test_high_energy_loss=[0.5, 0.05])
    assert np.isnan(energy_ratio(passed))  # no evaluation in the initial stage


# Grids of the appendix's figures: conf/experiment/<name>.yaml (the one copy) -> (figure, sweep).
CONF_GRIDS = {
    "fig5_adadelta": ("fig5", "adadelta"), "fig5_adagrad": ("fig5", "adagrad"), "fig5_sgd": ("fig5", "sgd"),
    "fig5_rmsprop": ("fig5", "rmsprop"), "fig6_adam": ("fig6", "adam"), "fig8_dipole_adam": ("fig8", "adam"),
    "fig9_dipole_hig": ("fig9", "hig"), "fig10_dipole_cnn_adam": ("fig10", "adam"), "fig11_dipole_cnn_hig": ("fig11", "hig"),
    "fig12a_beta": ("fig12", "beta"), "fig12b_kappa": ("fig12", "kappa"), "fig13_tau": ("fig13", "hig"),
}  # fmt: skip


@pytest.mark.parametrize("experiment", CONF_GRIDS)
def test_paper_preset_runs_the_experiment_configs_grids(experiment):
    import yaml

    from higbench.config import config_dir

    params = yaml.safe_load((Path(config_dir()) / "experiment" / f"{experiment}.yaml").read_text())["hydra"]["sweeper"]["params"]
    fid, sweep = CONF_GRIDS[experiment]
    jobs = [j for j in expand(registry.figures()[fid], Preset("paper")) if j.sweep == sweep]
    for key, text in params.items():
        if key == "optimizer":
            continue  # fig13 sweeps the optimizer as two sweeps
        want = sorted(float(v) for v in str(text).split(","))
        assert sorted({float(j.overrides[key]) for j in jobs}) == want, (experiment, key)
    grid = [k for k in params if k != "optimizer"]
    assert len(jobs) == np.prod([len(str(params[k]).split(",")) for k in grid]), experiment  # the full cartesian grid


def test_table2_paper_column_is_the_per_pair_defaults():
    from higbench.paper.tables import paper_table2

    assert paper_table2("adam") == "512 / 3e-4 / -" and paper_table2("gn") == "128 / - / 1e-6"
    assert paper_table2("hig") == "128 / 1 / 1e-6" and paper_table2("rmsprop") == "512 / 1e-4 / -"


def test_a_new_preset_is_one_entry_and_falls_back(monkeypatch):
    from higbench.figures import spec

    monkeypatch.setitem(spec.PRESETS, "mine", "quick")  # what adding a preset takes
    quick, mine = Preset("quick"), Preset("mine")
    assert spec.Budget(seconds={"paper": 3600, "quick": 60}).overrides(mine) == {"budget.seconds": 60.0}
    assert spec.Budget(seconds={"paper": 3600, "quick": 60, "mine": 300}).overrides(mine) == {"budget.seconds": 300.0}
    assert spec.PerPreset([1, 2, 3], quick=[1]).for_preset(mine) == [1] and spec.PerPreset([1, 2, 3], mine=[2]).for_preset(
        quick
    ) == [1, 2, 3]
    assert mine.problem_overrides("dipole") == quick.problem_overrides("dipole")
    for fid, fig in registry.figures().items():  # every figure expands, as at its fallback
        assert [j.override_list() for j in expand(fig, mine)] == [j.override_list() for j in expand(fig, quick)], fid


def _fake_figure_data(figure, rows, tmp_path):
    """A FigureData over fake finished runs: rows of (sweep, seed, overrides, status, losses)."""
    import pandas as pd

    from higbench.figures.data import FigureData, RunData

    d = FigureData(figure, Preset("quick"), tmp_path, [], budgets={"all runs": "1 s"})
    for sweep, seed, ov, status, losses in rows:
        job = Job(figure.id, sweep, dict(ov), seed=seed, status=status)
        job.path, job.config = tmp_path / f"{len(d.jobs)}.h5", {"seed": seed}
        for key, value in {"optimizer.name": ov.get("optimizer", "hig"), **ov}.items():
            if key == "optimizer":
                continue  # the config group choice: optimizer.name
            node = job.config
            *parents, last = key.split(".")
            for part in parents:
                node = node.setdefault(part, {})
            node[last] = value
        run = RunData(job)
        run.__dict__["_run"] = ({"status_step": 3}, pd.DataFrame({"wall_time": [0.0, 1.0, 2.0], "test_loss": losses}))
        d.jobs.append(job)
        d._cache[id(job)] = run
    return d


def test_plot_layer_facets_and_lines_record_what_they_draw(tmp_path):
    from higbench.figures.plot import Curves, Facets, Series, draw, draw_curves, new_figure
    from higbench.figures.spec import Figure

    values = [(b, t, lr) for b in (8, 16) for t in (1e-5, 1e-2) for lr in (0.5, 1.0)]
    settings = [{"optimizer": "hig", "batch_size": b, "optimizer.tau": t, "optimizer.lr": lr} for b, t, lr in values]
    grid = [("hig", seed, ov, "completed", [1.0, 0.5, 0.1]) for ov in settings for seed in (0, 1)]
    facets = Figure("figF", "t", [], panels=[Facets(["hig"], "optimizer.tau", "optimizer.lr", rows="batch_size")])
    d = _fake_figure_data(facets, grid, tmp_path)
    draw(d)
    panels = sorted({r["panel"] for r in d.rows})
    assert panels == ["b=16 τ=0.01", "b=16 τ=1e-5", "b=8 τ=0.01", "b=8 τ=1e-5"]
    assert {r["series"] for r in d.rows} == {"η=0.5", "η=1"}
    assert len(d.rows) == len(grid) * 3 and d.banded and "shaded: min-max over seeds" in d.caption()
    assert (tmp_path / "figF.png").stat().st_size > 0

    kappas = [("kappa", 0, {"optimizer": "hig", "optimizer.kappa": k}, st, ls)
              for k, st, ls in ((1.0, "diverged", [1.0, 5.0, float("nan")]), (-0.5, "completed", [1.0, 0.1, 0.01]))]  # fmt: skip
    lines = Figure(
        "figL", "t", [], panels=[Curves("k", [Series("kappa", "optimizer.kappa", label="{kv}", color="viridis", reverse=True)])]
    )
    d = _fake_figure_data(lines, kappas, tmp_path)
    fig, axes = new_figure()
    draw_curves(d, axes[0, 0], lines.panels[0])
    legend = [t.get_text() for t in axes[0, 0].get_legend().get_texts()]
    assert legend == ["κ=1 (diverged at step 3)", "κ=-0.5"]  # largest first, the divergence named once
    assert [r["series"] for r in d.rows[::3]] == ["κ=1", "κ=-0.5"]
    assert d.diverged_marked and "X: last finite evaluation" in d.caption()


def _compose_both_ways(override_lists):
    """(the figures' compose, Hydra composing each list whole) for each override list."""
    import yaml
    from hydra import compose as hydra_compose
    from omegaconf import OmegaConf

    from higbench.jobs import compose, hydra_conf

    with hydra_conf():
        whole = [
            yaml.safe_load(OmegaConf.to_yaml(hydra_compose("config", overrides=list(o)), resolve=True)) for o in override_lists
        ]
        return [compose(tuple(o)) for o in override_lists], whole


def _override_lists(presets, one_per_figure):
    lists = {}
    for preset in presets:
        for fig in registry.figures().values():
            jobs = expand(fig, Preset(preset))
            for j in jobs[:1] if one_per_figure else jobs:
                lists.setdefault(tuple(j.override_list()), None)
    return list(lists)


def test_shared_group_composition_gives_hydras_config():
    """The fast route (one Hydra composition per group choice, value overrides applied after it)
    against Hydra composing each job whole: one job per figure, a continued run, quoted strings."""
    lists = _override_lists(["quick"], one_per_figure=True)
    lists += [("problem=poisson", "optimizer=hig", "optimizer.lr=0.02", "init_from='/a b/run.h5'", "budget.seconds=null")]
    lists += [("problem=dipole", "optimizer=adam", "eval_unit=updates", "eval_every=10", "problem.test_size=16")]
    authors = next(j for j in expand(registry.figures()["fig3b"], Preset("long")) if j.sweep == "hig_authors")
    lists += [tuple(authors.override_list())]  # a list value: the authors' network replaces ours
    fast, whole = _compose_both_ways(lists)
    assert all(a == b for a, b in zip(fast, whole)), [o for o, a, b in zip(lists, fast, whole) if a != b][:3]
    assert fast[-2]["eval_every"] == 10.0 and fast[-3]["init_from"] == "/a b/run.h5"
    assert fast[-1]["problem"]["hidden"] == [64, 128, 64] and fast[-1]["problem"]["data"] == "phiflow_noise"


@pytest.mark.slow
def test_shared_group_composition_gives_hydras_config_for_every_job():
    lists = _override_lists(list(PRESETS), one_per_figure=False)
    fast, whole = _compose_both_ways(lists)
    assert len(lists) > 300 and [o for o, a, b in zip(lists, fast, whole) if a != b] == []


def test_a_grid_of_facets_without_a_finished_run_still_draws(tmp_path):
    """fig5 before its runs exist (--no-run): every panel says "no runs" instead of the figure failing."""
    from higbench.figures.plot import Facets, draw
    from higbench.figures.spec import Figure

    failed = [(o, 0, {"optimizer": o, "optimizer.lr": lr, "batch_size": 8}, "failed", [1.0, 0.5, 0.1])
              for o in ("sgd", "adam") for lr in (0.1, 1.0)]  # fmt: skip
    fig = Figure("figN", "t", [], panels=[Facets(["sgd", "adam"], "optimizer.lr", "batch_size", rows="sweep")])
    d = _fake_figure_data(fig, failed, tmp_path)
    for job in d.jobs:
        job.path = None  # a failed run leaves nothing to draw
    draw(d)
    assert d.rows == [] and (tmp_path / "figN.png").stat().st_size > 0


def test_a_figure_records_when_and_at_which_revisions_its_runs_were_made():
    from types import SimpleNamespace

    from higbench.figures.build import runs_made

    def run(started, finished, rev):
        return SimpleNamespace(meta={"started": started, "finished": finished, "env": {"git_revision": rev}})

    same_day = [
        run("2026-11-24T04:53:29+0000", "2026-11-24T05:08:00+0000", "ab5624bdeadbeef"),
        run("2026-11-24T05:10:00+0000", "", "b5158bd0"),
    ]
    data = SimpleNamespace(runs=lambda: same_day)
    assert runs_made(data) == {"runs": "runs made 2026-11-24 04:53-05:10 UTC at ab5624b, b5158bd"}
    two_days = [run("2026-11-23T22:20:00+0000", "2026-11-24T01:23:00+0000", "")]
    assert runs_made(SimpleNamespace(runs=lambda: two_days)) == {"runs": "runs made 2026-11-23 22:20-2026-11-24 01:23 UTC"}
    # run files stamp local time with its offset: 00:30 at +0100 is 23:30 UTC the day before
    zones = [run("2026-11-24T00:30:00+0100", "2026-11-24T00:40:00+0100", "c0ffee0"), run("2026-11-23T23:35:00+0000", "", "")]
    assert runs_made(SimpleNamespace(runs=lambda: zones)) == {"runs": "runs made 2026-11-23 23:30-23:40 UTC at c0ffee0"}
    assert runs_made(SimpleNamespace(runs=lambda: [])) == {}
    # run files that record what the runs had of their cores say so (older ones do not)
    same_day[0].meta["env"] |= {"cpu_share": 0.991, "load_at_finish": "2.04 2.01 1.97"}
    same_day[1].meta["env"] |= {"cpu_share": 0.62, "load_at_finish": "3.10 2.80 2.00"}
    shares = "; 2 of 2 runs: CPU share 0.62-0.99, load at the end 2.04-3.10"
    assert runs_made(data) == {"runs": f"runs made 2026-11-24 04:53-05:10 UTC at ab5624b, b5158bd{shares}"}


def test_a_run_file_records_what_the_run_had_of_its_cores(monkeypatch):
    """The CPU share is the process's CPU seconds over wall seconds times threads since the run
    began: 1 for a run busy on all its threads, lower for one that shared its cores or waited.
    (Clocks replaced: a real measure would depend on the machine's load.)"""
    from higbench.runner import environment

    clock = {"cpu": 100.0, "wall": 50.0}
    monkeypatch.setattr(environment, "_cpu_seconds", lambda: clock["cpu"])
    monkeypatch.setattr(environment, "_wall_seconds", lambda: clock["wall"])
    use = environment.CpuUse(threads=2)
    clock["cpu"], clock["wall"] = 100.0 + 2 * 10.0, 60.0  # both threads busy for 10 s
    assert use.summary()["cpu_share"] == 1.0
    clock["cpu"], clock["wall"] = 100.0 + 2 * 10.0 + 5.0, 70.0  # then one thread's worth for half of 10 s
    assert use.summary()["cpu_share"] == 0.625
    assert len(use.summary()["load_at_finish"].split()) == 3


def test_a_resumed_runs_cpu_share_counts_its_earlier_segments(monkeypatch):
    """A run at share 0.6 for 540 s, killed, then resumed alone for its last 60 s records
    (0.6 * 540 + 60) / 600 = 0.64, not the last segment's 1.0. (Clocks replaced.)"""
    from higbench.runner import environment

    clock = {"cpu": 0.0, "wall": 0.0}
    monkeypatch.setattr(environment, "_cpu_seconds", lambda: clock["cpu"])
    monkeypatch.setattr(environment, "_wall_seconds", lambda: clock["wall"])
    first = environment.CpuUse(threads=1)
    clock["cpu"], clock["wall"] = 0.6 * 540, 540.0
    saved = first.totals()  # what the checkpoint carries
    assert saved == {"cpu_seconds": 324.0, "core_seconds": 540.0, "segments": 1}
    clock["cpu"], clock["wall"] = 1000.0, 2000.0  # another process: its clocks start anywhere
    resumed = environment.CpuUse(threads=1, earlier=saved)
    clock["cpu"], clock["wall"] = 1060.0, 2060.0
    assert resumed.summary()["cpu_share"] == 0.64 and resumed.summary()["cpu_segments"] == 2


def test_long_curves_are_thinned_to_what_a_panel_can_show_keeping_the_start_end_and_lowest():
    """A 3,000 s Adam run has ~54,000 evaluations: drawn and written as ~1,000 (the data files stay
    small), evenly spread and log-spaced, with the first, the last and the lowest kept."""
    from higbench.figures.plot import CURVE_POINTS, thinned

    short = np.arange(2 * CURVE_POINTS, dtype=float)
    assert (thinned(len(short), short) == np.arange(len(short))).all()
    n = 54_000
    y = np.abs(np.sin(np.arange(n) / 7.0)) + 1.0
    y[31_337] = 0.5  # the lowest, between the evenly spread points
    idx = thinned(n, y)
    assert len(idx) <= 2 * CURVE_POINTS + 3 and (np.diff(idx) > 0).all()
    assert {0, n - 1, 31_337} <= set(idx.tolist()) and set(range(20)) <= set(idx.tolist())  # dense at the start
    assert np.diff(idx).max() <= n / (CURVE_POINTS - 1) + 1  # no gap wider than the even spacing


def test_a_build_prints_the_claims_of_its_figures(tmp_path):
    """The paper door's short report: each drawn figure's claims, one line each, from its
    <id>.json; a figure whose claims are all n/a (the smoke preset) gets one line."""
    from higbench.figures.__main__ import claim_lines

    judged = [
        {"id": "toy-3", "verdict": "reproduced", "paper": "HIG lowest", "measured": "HIG 5e-4, Adam 4e-3"},
        {"id": "toy-1", "verdict": "partly", "paper": "~3 decades", "measured": "HIG 4.5 decades"},
    ]
    (tmp_path / "fig1.json").write_text(json.dumps({"claims": judged}))
    (tmp_path / "fig2b.json").write_text(json.dumps({"claims": [{"id": "osc-1", "verdict": "n/a"}] * 3}))
    lines = claim_lines(tmp_path, ["fig1", "fig2b", "table9"])  # table9: no json, nothing said
    assert lines[0].startswith("[figures] fig1: 2 claims of the paper, as these runs judge them")
    assert lines[1] == "  toy-3 reproduced: HIG lowest | measured: HIG 5e-4, Adam 4e-3"
    assert lines[2].startswith("  toy-1 partly: ")
    assert lines[3].startswith("[figures] fig2b: its 3 claims n/a at these runs") and len(lines) == 4
