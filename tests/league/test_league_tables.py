"""The league's exported tables (higbench.league.tables): what a root carries to another machine
re-scores as its run files do, and several roots merge into one score."""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest
import yaml

from higbench.league import tables
from higbench.results import league
from higbench.results.index import load_runs
from higbench.runfile.writer import RunFileWriter


def write_run(root: Path, name: str, optimizer: str, seed: int, losses, *, lr: float, load="3.50 2.00 1.00", cores=2,
              status: str | None = "completed"):  # fmt: skip
    """A toy run under ``root/figures-runs`` (where the league's launches put them); completed, or
    ``status=None``: left ``running``, as a run killed by SIGKILL leaves its file."""
    config = {"problem": {"name": "toy", "targets": [1e-1, 1e-2]}, "optimizer": {"name": optimizer, "lr": lr}, "seed": seed,
              "budget": {"seconds": 5.0, "max_updates": None}}  # fmt: skip
    env = {"hostname": "test", "device": "cpu", "cpu_count": cores, "cpu_share": 0.8, "load_at_finish": load}
    w = RunFileWriter(
        root / "figures-runs" / "x" / name / "run.h5", yaml.safe_dump(config),
        ["problem=toy", f"optimizer={optimizer}", f"seed={seed}", f"optimizer.lr={lr}"],
        env=env, meta={"problem": "toy", "optimizer": optimizer},
    )  # fmt: skip
    for i, loss in enumerate(losses):
        w.append_row("curves", {"step": i * 10, "epoch": 0, "wall_time": i * 0.37, "train_loss": loss,
                                "test_loss": loss, "val_loss": loss * 1.1, "rss_mb": 1.0})  # fmt: skip
    w.flush()
    w.f.attrs["steps"] = (len(losses) - 1) * 10
    w.f.attrs["wall_time"] = (len(losses) - 1) * 0.37
    w.close(status, "", (len(losses) - 1) * 10)


def league_root(root: Path, seeds, cores=2) -> dict:
    """Confirmation runs of hig and adam on ``seeds``; returns their roles (identity -> entry)."""
    for seed in seeds:
        write_run(root, f"h{seed}", "hig", seed, [1.0, 0.05 / (seed + 1), 0.001], lr=0.5, cores=cores)
        write_run(root, f"a{seed}", "adam", seed, [1.0, 0.5, 0.05, 0.009 * (seed + 1)], lr=0.01, cores=cores)
    runs = load_runs(root, figure_runs=True)
    return {
        cid: {"role": "confirm", "job": f"confirm/toy/base/{opt}"} for cid, opt in zip(runs["config_id"], runs["optimizer.name"])
    }


def score(runs: pd.DataFrame, curves: pd.DataFrame) -> str:
    return league.format_league(runs, curves, league.all_spaces())


def score_files(root: Path) -> str:
    """The score of the run files themselves, each run's hardware named as the tables name it."""
    runs, curves = load_runs(root, curves=True, figure_runs=True)
    return score(runs.assign(hardware=tables.hardware(runs)), curves)


def test_tables_hold_the_contract_columns_and_the_load(tmp_path):
    jobs = league_root(tmp_path, [0, 1])
    runs_path, curves_path = tables.export(tmp_path, jobs)
    assert runs_path == tmp_path / "tables" / "runs.csv.gz" and curves_path.is_file()
    runs = pd.read_csv(runs_path)
    assert list(runs.columns) == list(tables.RUN_COLUMNS) and len(runs) == 4
    assert set(runs["league_role"]) == {"confirm"} and set(runs["hardware"]) == {"CPU, 2 cores"}
    assert set(runs["env.load_1min"]) == {3.5}  # the first of the three load averages, not its first character
    assert runs["run"].str.startswith("figures-runs/x/").all()
    roles = tables._roles(tmp_path, {i: {"role": "tune", "job": "tune/toy/adam/1/3", "study": 1, "trial": 3} for i in jobs})
    tune = tables.runs_table(tmp_path, load_runs(tmp_path, figure_runs=True), roles)
    assert "1,3," in tune.to_csv(index=False)  # study and trial as whole numbers
    curves = pd.read_csv(curves_path)
    assert list(curves.columns) == list(tables.CURVE_COLUMNS) and len(curves) == 2 * 3 + 2 * 4
    assert 0.37 * 3 in set(curves["wall_time"])  # full precision


def test_tables_written_before_runs_named_their_machine_read_with_those_columns_empty(tmp_path):
    tables.export(tmp_path, league_root(tmp_path, [0]))
    path = tmp_path / "tables" / "runs.csv.gz"
    older = pd.read_csv(path).drop(columns=list(tables.MACHINE_COLUMNS))
    older.to_csv(path, index=False, compression="gzip")
    runs, _ = tables.read_root(tmp_path)
    assert len(runs) == 2 and runs[list(tables.MACHINE_COLUMNS)].isna().all().all()


def test_a_root_without_its_run_files_rescores_the_same_from_its_tables(tmp_path):
    jobs = league_root(tmp_path, [0, 1, 2])
    from_files = score_files(tmp_path)
    tables.export(tmp_path, jobs)
    shutil.rmtree(tmp_path / "figures-runs")
    assert "6 scored runs" in from_files and "toy: CPU, 2 cores" in from_files
    assert score(*tables.read(tmp_path)) == from_files
    tables.export(tmp_path)  # exporting again without the run files keeps their rows
    assert score(*tables.read(tmp_path)) == from_files


def test_two_roots_merge_into_the_score_of_one_root_holding_both(tmp_path):
    a, b, both = tmp_path / "a", tmp_path / "b", tmp_path / "both"
    tables.export(a, league_root(a, [0, 1]))
    tables.export(b, league_root(b, [2, 3]))  # another machine of the same class
    jobs = league_root(both, [0, 1, 2, 3])
    merged_runs, merged_curves = tables.read([a, b])
    assert set(merged_runs["hardware"]) == {"CPU, 2 cores"} and set(merged_runs["root"]) == {str(a), str(b)}
    tables.export(both, jobs)
    single = score(*tables.read(both))
    assert "8 scored runs" in single
    tables.export(b, league_root(b, [4], cores=16))  # a machine of another class: the scorer splits its task
    assert "toy [CPU, 16 cores]" in score(*tables.read([a, b]))
    assert score(merged_runs, merged_curves) == single == score_files(both)


def test_a_run_moved_out_and_trained_again_replaces_its_old_row(tmp_path):
    """A run set aside (moved out of the root, e.g. for a low CPU share) and trained again under
    another directory: the old row, its file gone, must not shadow the new one (the merge keeps
    the first row of an identity)."""
    root = tmp_path / "root"
    jobs = league_root(root, [0])
    tables.export(root, jobs)
    shutil.move(str(root / "figures-runs" / "x" / "h0"), str(tmp_path / "set-aside"))
    write_run(root, "h0-again", "hig", 0, [1.0, 0.04, 0.0005], lr=0.5)  # the same identity, trained again
    tables.export(root, jobs)
    runs, _ = tables.read(root)
    hig = runs[runs["optimizer.name"] == "hig"]
    assert len(runs) == 2 and list(hig["run"]) == ["figures-runs/x/h0-again/run.h5"]
    assert float(hig["final_test_loss"].iloc[0]) == 0.0005


@pytest.mark.parametrize("killed", [None, "interrupted"], ids=["sigkill-left-running", "interrupted"])
def test_a_run_killed_and_trained_again_elsewhere_merges_as_the_finished_one(tmp_path, killed):
    """A run killed mid-way (SIGKILL leaves its file ``running``; SIGTERM ``interrupted``) whose
    job the next sitting trained again in a new directory: both files stay in the root, and the
    merge keeps the finished one, though the killed one's directory sorts first. Keeping the
    first left an oscillator tuning trial of Muon and one of AdaGrad out of the tuning counts."""
    root, out = tmp_path / "root", tmp_path / "out"
    jobs = league_root(root, [0])
    shutil.move(str(root / "figures-runs" / "x" / "h0"), str(tmp_path / "finished"))
    write_run(root, "h0", "hig", 0, [1.0, 0.3], lr=0.5, status=killed)  # the killed attempt, first by path
    write_run(root, "h0-again", "hig", 0, [1.0, 0.04, 0.0005], lr=0.5)  # the same identity, trained again
    tables.export(root, jobs)
    assert len(tables.read(root)[0]) == 3  # the root's own table keeps every file's row
    tables.write_merged(out, [root])
    runs, curves = tables.read(out)
    hig = runs[runs["optimizer.name"] == "hig"]
    assert len(runs) == 2 and list(hig["run"]) == ["figures-runs/x/h0-again/run.h5"]
    assert list(hig["status"]) == ["completed"] and float(hig["final_test_loss"].iloc[0]) == 0.0005
    assert len(curves[curves["run"] == "figures-runs/x/h0-again/run.h5"]) == 3 and set(curves["run"]) == set(runs["run"])


def test_a_run_that_served_two_roles_has_a_row_for_each(tmp_path):
    """A reference's rerun is also a confirmation run when the league's budget is the target
    setting's and tuning chose the same point (the job identities coincide): the target setting
    and the score both need it, so the tables keep a row per role, through the merge too."""
    import json

    root, out = tmp_path / "root", tmp_path / "out"
    jobs = league_root(root, [0])
    adam = next(i for i, e in jobs.items() if e["job"].endswith("adam"))
    entries = [{"identity": i, **e} for i, e in jobs.items()] + [
        {"identity": adam, "role": "target", "job": "target/toy/base/adam"}
    ]
    (root / "manifests").mkdir()
    (root / "manifests" / "sitting.json").write_text(json.dumps({"runs": entries}))
    tables.export(root)
    tables.write_merged(out, [root])
    for folder in (root, out):
        runs, _ = tables.read(folder)
        assert sorted(runs.loc[runs["identity"] == adam, "league_role"]) == ["confirm", "target"]
        assert len(runs) == 3 and runs["run"].nunique() == 2
        scored, _, _ = league.league_frames(runs, tables.read(folder)[1], league.all_spaces())
        assert sorted(scored["optimizer.name"]) == ["adam", "hig"]  # the confirm row scores once


def test_a_run_in_two_roots_keeps_its_evaluations_once_through_repeated_merges(tmp_path):
    """A league's own root and the published tables both hold a run: the merge keeps its row once
    and its curve once, and merging the merged tables again (each sitting) adds nothing."""
    root, out = tmp_path / "root", tmp_path / "out"
    tables.export(root, league_root(root, [0]))
    tables.write_merged(out, [root])
    for _ in range(3):  # three sittings, each merging the league's root with the published tables
        tables.write_merged(out, [root, out])
    runs, curves = tables.read(out)
    assert len(runs) == 2 and len(curves) == 3 + 4  # hig's 3 evaluations, adam's 4
