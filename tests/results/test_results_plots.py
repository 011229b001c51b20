"""higbench-results --plot/--profile/--best/--problem on synthetic run files (real RunFileWriter)."""

from __future__ import annotations

import pytest
from synthetic import write_run

from higbench.results.__main__ import main as results_main  # noqa: E402

PNG = b"\x89PNG"


@pytest.fixture
def sweep(tmp_path):
    """toy: adam and hig, 3 seeds each, 5 s budget; hig reaches 1e-3 at 1.0 s in 2 seeds of 3."""
    root = tmp_path / "sweep"
    curves = {
        "adam": [[1.0, 0.1, 0.02, 0.01], [1.0, 0.2, 0.03, 0.02], [1.0, 0.15, 0.05, 0.008]],
        "hig": [[1.0, 0.01, 5e-4, 1e-4], [1.0, 0.02, 8e-4, 2e-4], [1.0, 0.05, 0.01, 0.005]],
    }
    for opt, losses in curves.items():
        for seed, loss in enumerate(losses):
            write_run(
                root / f"{opt}_{seed}/run.h5",
                optimizer=opt,
                test_loss=loss,
                config_extra={"seed": seed, "budget": {"seconds": 5.0, "max_updates": None}},
            )
    return root


def test_plot_draws_curves_and_prints_time_to_target(sweep, tmp_path, capsys):
    out = tmp_path / "curves.png"
    assert results_main([str(sweep), "--plot", str(out), "--targets", "toy=1e-2,1e-3"]) == 0
    text = capsys.readouterr().out
    assert out.read_bytes()[:4] == PNG
    # 1e-3: hig's seeds reach it at 1.0 s, 1.0 s, never -> median 1.0 s; adam never (0 of 3)
    assert "toy <= 0.001" in text and "1s" in text and "- (0/3)" in text


def test_profile_prints_ratios_and_draws_rho(sweep, tmp_path, capsys):
    out = tmp_path / "profile.png"
    assert results_main([str(sweep), "--profile", str(out), "--targets", "toy=1e-2,1e-3"]) == 0
    text = capsys.readouterr().out
    assert out.read_bytes()[:4] == PNG
    # 1e-2: hig's seeds at 0.5, 1.0, 1.0 s (median 1.0 s, fastest), adam's at 1.5 s, never, 1.5 s (1.5x);
    # 1e-3: hig only
    assert "1.5s (1.5x)" in text
    rho = {line.split()[1]: line.split(": ", 1)[1] for line in text.splitlines() if line.startswith("rho ")}
    assert rho == {"hig": "tau=1: 1.00, tau=2: 1.00, tau=4: 1.00", "adam": "tau=1: 0.00, tau=2: 0.50, tau=4: 0.50"}


def test_bad_targets_exit_2(sweep, capsys):
    assert results_main([str(sweep), "--profile", "x.png", "--targets", "toy=abc"]) == 2
    assert "--targets toy=abc" in capsys.readouterr().err


def test_misspelt_problem_gets_a_suggestion_and_exit_2(sweep, capsys):
    assert results_main([str(sweep), "--problem", "oscilator"]) == 2
    assert "--problem oscilator: no such problem; did you mean oscillator?" in capsys.readouterr().err
    assert results_main([str(sweep), "--problem", "oscillator"]) == 0  # a real problem with no runs here


def test_best_compares_only_runs_of_equal_budget(tmp_path, capsys):
    root = tmp_path / "mixed"
    write_run(root / "hig30/run.h5", optimizer="hig", test_loss=[1.0, 1e-4], config_extra={"budget": {"seconds": 30.0}})
    write_run(root / "adam5/run.h5", optimizer="adam", test_loss=[1.0, 1e-2], config_extra={"budget": {"seconds": 5.0}})
    write_run(root / "adam30/run.h5", optimizer="adam", test_loss=[1.0, 1e-3], config_extra={"budget": {"seconds": 30.0}})
    assert results_main([str(root), "--best"]) == 0
    captured = capsys.readouterr()
    assert "different budgets" in captured.err
    lines = captured.out.splitlines()
    assert "budget" in lines[1]
    rows = [line.split() for line in lines[2:]]
    assert sorted((r[0], r[4]) for r in rows) == [("adam30/run.h5", "30s"), ("adam5/run.h5", "5s"), ("hig30/run.h5", "30s")]


def test_default_table_shows_time_to_thresholds(sweep, capsys):
    assert results_main([str(sweep)]) == 0
    header = capsys.readouterr().out.splitlines()[1]
    assert "time_to_1e-3" in header and "time_to_1e-4" in header
