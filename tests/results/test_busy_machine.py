"""A busy machine is said where runs end: the closing lines of a run, a sweep and a figure
build, and a marker in higbench-results tables. All on hand-made CPU shares and loads (the
run file's env/cpu_share and env/load_at_finish), never on this machine's load."""

from __future__ import annotations

import types

import h5py
from omegaconf import OmegaConf
from synthetic import write_run

from higbench.display import BUSY_SHARE, busy_note, busy_summary
from higbench.results.__main__ import main as results_main
from higbench.results.index import cpu_uses


def _with_cpu(path, share, load="12.3 11.0 9.8"):
    with h5py.File(path, "a") as f:
        f["env"].attrs["cpu_share"] = share
        f["env"].attrs["load_at_finish"] = load
    return path


def test_busy_note_names_share_and_load_only_under_the_threshold():
    assert busy_note(0.33, "12.3 11.0 9.8") == (
        "this run had 0.33 of a core (load 12): its update count and loss are not what an idle machine gives"
    )
    assert busy_note(0.95, "12.3 11.0 9.8") is None and busy_note(BUSY_SHARE, 3.0) is None
    assert busy_note(None) is None and busy_note(float("nan")) is None
    assert busy_note(0.5, "") == "this run had 0.50 of a core: its update count and loss are not what an idle machine gives"


def test_busy_summary_counts_the_busy_runs():
    text = busy_summary([(0.33, "12.0 1 1"), (0.9, "2.0 1 1"), (0.6, 8.0), (None, "")], noun="jobs")
    assert text.startswith("2 of 3 jobs had under 0.7 of a core (least 0.33, load up to 12):")
    assert busy_summary([(0.9, "1 1 1"), (0.8, None)]) is None


def test_closing_lines_of_a_run_say_the_machine_was_busy(tmp_path):
    from higbench.results.end_of_run import summary_lines

    cfg = OmegaConf.create({"problem": {"name": "toy", "targets": [1e-2]}, "optimizer": {"name": "hig"}})
    for share, said in ((0.33, True), (0.97, False)):
        path = _with_cpu(write_run(tmp_path / f"{share}/run.h5", optimizer="hig"), share)
        summary = types.SimpleNamespace(
            status="completed", steps=20, wall_time=1.5, final_test_loss=0.005, reason="", path=path, tables=None
        )
        lines = summary_lines(summary, cfg)
        busy = [line for line in lines if "of a core" in line]
        assert busy == (
            ["this run had 0.33 of a core (load 12): its update count and loss are not what an idle machine gives"]
            if said
            else []
        )
        assert lines[-1].startswith("run file:")


def test_results_table_marks_runs_of_a_busy_machine_with_a_legend(tmp_path, capsys):
    _with_cpu(write_run(tmp_path / "busy/run.h5", optimizer="hig"), 0.33)
    _with_cpu(write_run(tmp_path / "idle/run.h5", optimizer="adam"), 0.98, "0.5 0.4 0.3")
    assert results_main([str(tmp_path)]) == 0
    out = capsys.readouterr().out
    busy_row = next(line for line in out.splitlines() if line.strip().startswith("busy/run.h5"))
    idle_row = next(line for line in out.splitlines() if line.strip().startswith("idle/run.h5"))
    assert "0.33 (load 12)" in busy_row and "(load" not in idle_row
    assert "  busy: under 0.7 of a core" in out
    assert results_main([str(tmp_path), "--best"]) == 0
    out = capsys.readouterr().out
    assert "busy_seeds" in out and "  busy_seeds: " in out


def test_no_marker_when_every_run_had_its_core(tmp_path, capsys):
    _with_cpu(write_run(tmp_path / "idle/run.h5", optimizer="adam"), 0.98)
    write_run(tmp_path / "old/run.h5", optimizer="adam")  # a file from before the share was recorded
    assert results_main([str(tmp_path)]) == 0
    assert "busy" not in capsys.readouterr().out


def test_sweep_counts_its_jobs_and_says_when_they_were_busy(tmp_path, capsys):
    """The every-batch sweeper's count (in-process jobs: one per job) and its closing line."""
    from hydra_plugins.higbench_joblist_sweeper.every_batch_sweeper import CountingTask, SweepCount, busy_line

    count = SweepCount(enabled=True)
    count.start(3)
    task = CountingTask(lambda cfg: cfg * 2, count)
    assert task(1) == 2 and task(2) == 4
    try:
        CountingTask(lambda cfg: 1 / 0, count)(0)
    except ZeroDivisionError:
        pass
    count.close()
    err = capsys.readouterr().err
    assert "[sweep] 0 of 3 jobs done" in err and "[sweep] 3 of 3 jobs done (1 failed)" in err
    files = [_with_cpu(write_run(tmp_path / f"{i}/run.h5"), share) for i, share in enumerate((0.33, 0.95))]
    assert cpu_uses([*files, tmp_path / "missing/run.h5"]) == [(0.33, "12.3 11.0 9.8"), (0.95, "12.3 11.0 9.8")]
    busy_line(files)
    assert capsys.readouterr().err.startswith("[sweep] 1 of 2 jobs had under 0.7 of a core (least 0.33, load up to 12)")
    busy_line(files[1:])
    assert capsys.readouterr().err == ""
