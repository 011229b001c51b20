"""The results index on synthetic run files written with the real RunFileWriter."""

from __future__ import annotations

import math
import sys

import numpy as np
import pandas as pd
import pytest
from synthetic import write_run

from higbench.results import best_runs, load_curves, load_runs
from higbench.results.__main__ import main as results_main
from higbench.results.index import config_id, one_per_config, threshold_column


@pytest.fixture
def tree(tmp_path):
    root = tmp_path / "outputs"
    write_run(root / "a/0_lr=0.1/run.h5", optimizer="adam", lr=0.1, test_loss=[1.0, 0.05, 0.004, 0.002])
    write_run(root / "a/1_lr=0.01/run.h5", optimizer="adam", lr=0.01, batch_size=128, test_loss=[1.0, 0.3, 0.2, 0.1])
    # the lowest loss of all, but diverged: never the best run
    write_run(root / "b/0/run.h5", optimizer="adam", lr=1.0, test_loss=[1.0, 1e-4, 1e-5, math.inf], status="diverged")
    write_run(root / "b/1/run.h5", optimizer="hig", lr=1.0, batch_size=32, test_loss=[1.0, 1e-3, 1e-6, 5e-7])
    write_run(root / "b/2/run.h5", optimizer="hig", lr=0.5, batch_size=32, test_loss=[1.0, 1e-2, 1e-3, 2e-4])
    return root


def test_one_row_per_run_with_flattened_config_and_metrics(tree):
    runs = load_runs(tree, thresholds=(1e-2, 1e-3))
    assert len(runs) == 5
    row = runs.set_index("path").loc[str(tree / "a/0_lr=0.1/run.h5")]
    assert row["problem.name"] == "toy" and row["optimizer.name"] == "adam"
    assert row["optimizer.lr"] == 0.1 and row["batch_size"] == 64 and row["optimizer.betas"] == (0.9, 0.999)
    assert row["status"] == "completed" and row["error"] == ""
    assert row["final_test_loss"] == 0.002 and row["best_test_loss"] == 0.002
    assert row["steps"] == 20 and row["train_time_s"] == 1.5 and row["n_evals"] == 4
    # the synthetic evaluations are 0.5 s apart: 0.05 at 0.5 s, 0.004 at 1.0 s
    assert row[threshold_column(1e-2)] == 1.0 and row[threshold_column(1e-3)] != row[threshold_column(1e-3)]  # NaN: never reached
    assert threshold_column(1e-2) == "time_to_1e-2" and threshold_column(3e-4) == "time_to_3e-4"
    assert row["mean_update_s"] == pytest.approx(0.01) and row["mean_jacobian_s"] == pytest.approx(0.004)
    assert row["peak_rss_mb"] == 123.0 and row["resumes"] == 0
    assert row["overrides"] == "optimizer=adam optimizer.lr=0.1 batch_size=64"
    diverged = runs[runs["status"] == "diverged"].iloc[0]
    assert math.isinf(diverged["final_test_loss"]) and diverged["best_test_loss"] == 1e-5


def test_best_runs_never_pick_a_diverged_run(tree):
    runs = load_runs(tree)
    best = best_runs(runs, by="optimizer.name")
    assert list(best["optimizer.name"]) == ["adam", "hig"]
    assert best.set_index("optimizer.name").loc["adam", "path"] == str(tree / "a/0_lr=0.1/run.h5")
    assert best.set_index("optimizer.name").loc["hig", "optimizer.lr"] == 1.0
    assert "overrides" in best and (best["status"] == "completed").all()
    by_best = best_runs(runs, by=["optimizer.name", "batch_size"], metric="best_test_loss")
    assert len(by_best) == 3  # adam/64, adam/128, hig/32 (the diverged adam/64 run excluded)
    with pytest.raises(KeyError):
        best_runs(runs, by="no.such.column")


def test_best_runs_never_mix_problems_and_skip_figure_runs(tmp_path):
    write_run(tmp_path / "toy/run.h5", problem="toy", optimizer="gn", test_loss=[1.0, 1e-8])
    write_run(tmp_path / "osc/run.h5", problem="oscillator", optimizer="gn", test_loss=[1.0, 1e-3])
    write_run(tmp_path / "figures-runs/fig1/t/0/run.h5", problem="toy", optimizer="gn", test_loss=[1.0, 1e-9])
    runs = load_runs(tmp_path)
    assert len(runs) == 2 and set(runs["source"]) == {"runs"}  # the figures' runs only when asked
    best = best_runs(runs, by="optimizer.name")
    assert sorted(zip(best["problem.name"], best["final_test_loss"])) == [("oscillator", 1e-3), ("toy", 1e-8)]
    assert len(best_runs(runs, by="optimizer.name", per_problem=False)) == 1
    every = load_runs(tmp_path, figure_runs=True)
    assert len(every) == 3 and (every["source"] == "figures").sum() == 1
    assert len(load_runs(tmp_path / "figures-runs")) == 1  # asked for by its root


def test_table_has_no_duplicate_columns_and_integer_keys(tree):
    (tree / "junk.h5").write_bytes(b"not hdf5")  # a corrupt row: integer columns get a missing value
    runs = load_runs(tree)
    for gone in ("problem", "optimizer", "final_step", "wall_time"):
        assert gone not in runs.columns
    assert runs["train_time_s"].dtype.kind == "f"
    for col in ("batch_size", "steps", "n_evals"):
        assert runs[col].dtype.name in ("Int64", "int64"), (col, runs[col].dtype)
    assert runs["batch_size"].isna().sum() == 1


def test_datasets_say_their_units_and_old_text_attributes_still_read(tmp_path):
    import h5py

    from higbench.results import load_run

    path = write_run(tmp_path / "a/run.h5")
    with h5py.File(path, "r+") as f:
        for group in ("curves", "updates"):
            for name, ds in f[group].items():
                assert ds.attrs["units"] and ds.attrs["description"], (group, name)
        assert f["curves/wall_time"].attrs["units"] == "s"
        assert isinstance(f.attrs["steps"], np.integer)
        f.attrs["steps"], f.attrs["wall_time"] = "20", "1.5"  # as an older writer might have left them
    meta, _ = load_run(path)
    assert meta["steps"] == 20 and meta["wall_time"] == 1.5
    runs = load_runs(tmp_path)
    assert runs["steps"].iloc[0] == 20 and runs["train_time_s"].iloc[0] == 1.5


def test_curves_long_table(tree):
    runs, curves = load_runs(tree, curves=True)
    assert len(curves) == 5 * 4
    assert set(curves["path"].astype(str)) == set(runs["path"])
    assert curves["step"].dtype == np.int64
    one = curves[curves["path"] == str(tree / "b/1/run.h5")]
    assert one["test_loss"].tolist() == [1.0, 1e-3, 1e-6, 5e-7]
    assert load_curves(tree).shape == curves.shape


def test_unreadable_files_are_reported_not_fatal(tree):
    good = tree / "a/0_lr=0.1/run.h5"
    data = good.read_bytes()
    (tree / "c").mkdir()
    (tree / "c/truncated.h5").write_bytes(data[: len(data) // 3])
    (tree / "c/garbage.h5").write_bytes(b"not hdf5 at all" * 10)
    (tree / "c/empty.h5").write_bytes(b"")
    import h5py

    with h5py.File(tree / "c/foreign.h5", "w") as f:  # an HDF5 file that is not a run file
        f["x"] = [1, 2, 3]
    runs = load_runs(tree).set_index("path")
    assert len(runs) == 9
    for name in ("truncated", "garbage", "empty", "foreign"):
        row = runs.loc[str(tree / f"c/{name}.h5")]
        assert row["status"] == "corrupt" and row["error"], name
    assert (runs["status"] == "completed").sum() == 4
    assert len(best_runs(runs.reset_index())) == 2


def test_run_being_written_and_killed_writer(tree, tmp_path):
    """A live writer's file shows as running; after SIGKILL it reads up to the last flush.
    (The writer is open in this process; the reader meets its bytes and its lock as another
    process would: tests/in_process.py.)"""
    from in_process import seen_from_another_process

    path = tree / "live/run.h5"
    writer = write_run(tmp_path / "writing" / "run.h5", optimizer="sgd", test_loss=[1.0, 0.5], close=False)
    try:
        with seen_from_another_process(writer.f, path):
            row = load_runs(tree).set_index("path").loc[str(path)]
            assert row["status"] == "running" and "being written" in row["error"], row["error"]
            assert len(best_runs(load_runs(tree))) == 2  # a running run is never a best run
        row = load_runs(tree).set_index("path").loc[str(path)]  # killed: the lock went with the writer
        assert row["status"] == "running" and "no writer holds the file" in row["error"], row["error"]
        assert row["final_test_loss"] == 0.5 and row["n_evals"] == 2  # what was flushed is there
    finally:
        writer.f.close()


def test_cli_table_filters_and_best(tree, capsys):
    assert results_main([str(tree)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("5 of 5 runs") and "diverged" in out and "a/0_lr=0.1/run.h5" in out

    assert results_main([str(tree), "--optimizer", "hig", "--columns", "optimizer.lr,batch_size"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("2 of 5 runs") and "adam" not in out and "optimizer.lr" in out

    assert results_main([str(tree), "--status", "diverged"]) == 0
    assert capsys.readouterr().out.startswith("1 of 5 runs")

    assert results_main([str(tree), "--best-seed"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0].startswith("2 of 5 runs")
    assert any("a/0_lr=0.1/run.h5" in ln and "optimizer.lr=0.1" in ln for ln in lines)  # with its overrides
    assert any("b/1/run.h5" in ln for ln in lines) and not any("b/0/run.h5" in ln for ln in lines)

    csv = tree / "runs.csv"
    assert results_main([str(tree), "--problem", "toy", "--csv", str(csv)]) == 0
    capsys.readouterr()
    assert csv.read_text().count("\n") == 6

    assert results_main([str(tree / "missing")]) == 2
    assert results_main([str(tree), "--best", "--metric", "no_such_metric"]) == 2
    assert "no_such_metric" in capsys.readouterr().err


def test_cli_module_entry_point(tree, monkeypatch, capsys):
    import runpy

    monkeypatch.setattr(sys, "argv", ["higbench-results", str(tree), "--best"])
    monkeypatch.delitem(sys.modules, "higbench.results.__main__")  # imported above: run afresh, as `-m` does
    with pytest.raises(SystemExit) as info:
        runpy.run_module("higbench.results", run_name="__main__")  # `python -m higbench.results`, in this process
    assert info.value.code == 0, capsys.readouterr().err
    assert capsys.readouterr().out.startswith("5 of 5 runs")


def test_cli_best_keeps_dipole_mlp_and_cnn_apart(tree, capsys):
    write_run(tree / "d/mlp/run.h5", problem="dipole", optimizer="hig", problem_extra={"model": "mlp"}, test_loss=[1.0, 1e-3])
    write_run(tree / "d/cnn/run.h5", problem="dipole", optimizer="hig", problem_extra={"model": "cnn"}, test_loss=[1.0, 1e-2])
    assert results_main([str(tree), "--best-seed", "--problem", "dipole"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("2 of 7 runs") and "d/mlp/run.h5" in out and "d/cnn/run.h5" in out
    assert results_main([str(tree), "--best-seed", "--by", "problem.name,optimizer.name"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("3 of 7 runs") and "d/mlp/run.h5" in out and "d/cnn/run.h5" not in out


def test_only_unreadable_files_and_empty_root(tmp_path, capsys):
    (tmp_path / "bad.h5").write_bytes(b"garbage")
    runs = load_runs(tmp_path)
    assert runs["status"].tolist() == ["corrupt"] and best_runs(runs).empty
    assert results_main([str(tmp_path), "--best"]) == 0
    assert "\n0 best setting(s)" in capsys.readouterr().out
    empty = tmp_path / "empty"
    empty.mkdir()
    assert load_runs(empty).empty and load_curves(empty).empty
    assert results_main([str(empty)]) == 0


@pytest.mark.process  # the index's reader processes (jobs=2)
def test_parallel_reading_gives_the_same_tables(tree):
    runs, curves = load_runs(tree, curves=True)
    runs2, curves2 = load_runs(tree, curves=True, jobs=2)
    pd.testing.assert_frame_equal(runs, runs2)
    pd.testing.assert_frame_equal(curves, curves2)


def test_config_id_ignores_cosmetic_keys_and_follows_init_from(tmp_path):
    parent = write_run(tmp_path / "p/run.h5", config_extra={"threads": 1, "init_from": None})
    again = write_run(tmp_path / "again/run.h5", config_extra={"threads": 4, "progress": True, "init_from": None})
    other = write_run(tmp_path / "other/run.h5", lr=0.5, config_extra={"init_from": None})
    child = write_run(tmp_path / "c/run.h5", config_extra={"init_from": str(parent.parent)})  # a run dir
    child2 = write_run(tmp_path / "c2/run.h5", config_extra={"init_from": str(again)})  # the same config's other file
    orphan = write_run(tmp_path / "o/run.h5", config_extra={"init_from": str(tmp_path / "gone/run.h5")})
    ids = load_runs(tmp_path).set_index("path")["config_id"]
    assert ids[str(parent)] == ids[str(again)] != ids[str(other)]  # threads/progress do not make another run
    assert ids[str(child)] == ids[str(child2)] != ids[str(orphan)]  # continued from the same config: the same run
    child_cfg = load_runs(tmp_path).set_index("path").loc[str(child)]
    assert child_cfg["init_from"] == str(parent.parent) and ids[str(child)] != ids[str(parent)]


def test_one_run_per_config_newest_done_first(tmp_path):
    import time

    failed = write_run(tmp_path / "a/run.h5", status="failed")
    done = write_run(tmp_path / "b/run.h5", status="diverged", test_loss=[1.0, math.inf])  # a result: done
    time.sleep(1.1)  # started/finished have one-second resolution
    newer = write_run(tmp_path / "c/run.h5", status="completed")
    later_failed = write_run(tmp_path / "d/run.h5", status="interrupted")
    lonely = write_run(tmp_path / "e/run.h5", lr=0.7, status="failed")
    runs = load_runs(tmp_path)
    assert runs["config_id"].nunique() == 2
    chosen = one_per_config(runs).set_index("config_id")["path"]
    assert chosen[runs.set_index("path").loc[str(newer), "config_id"]] == str(newer)  # newest done, not the later failure
    assert chosen[runs.set_index("path").loc[str(lonely), "config_id"]] == str(lonely)  # no done run: the newest of any
    assert config_id({"a": 1, "threads": 3}) == config_id({"a": 1})
    only_old = one_per_config(runs[runs["path"].isin([str(failed), str(done), str(later_failed)])])
    assert only_old["path"].tolist() == [str(done)]  # diverged counts as done; failed/interrupted do not


def test_one_run_per_config_without_a_done_run_takes_the_one_furthest_along(tmp_path):
    """Of two stopped runs of one config, the one with more training clock is the one to resume,
    whichever started later (a session cut off a long run; a later build started it again)."""
    import time

    far = write_run(tmp_path / "a/run.h5", status="interrupted", test_loss=[1.0, 0.5, 0.2, 0.1, 0.05, 0.02])
    time.sleep(1.1)  # started has one-second resolution
    write_run(tmp_path / "b/run.h5", status="interrupted", test_loss=[1.0, 0.5])
    runs = load_runs(tmp_path)
    assert runs["config_id"].nunique() == 1
    assert one_per_config(runs)["path"].tolist() == [str(far)]
    done = write_run(tmp_path / "c/run.h5", status="completed", test_loss=[1.0, 0.5])
    assert one_per_config(load_runs(tmp_path))["path"].tolist() == [str(done)]  # a done run first, however short
