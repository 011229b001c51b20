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
    rho = dict(line[len("rho ") :].split(": ", 1) for line in text.splitlines() if line.startswith("rho "))
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
    assert results_main([str(root), "--best-seed"]) == 0
    captured = capsys.readouterr()
    assert "different budgets" in captured.err
    lines = captured.out.splitlines()
    assert "budget" in lines[1]
    rows = [line.split() for line in lines[2 : lines.index("columns:")]]
    assert sorted((r[0], r[5]) for r in rows) == [("adam30/run.h5", "30s"), ("adam5/run.h5", "5s"), ("hig30/run.h5", "30s")]


def test_default_table_shows_time_to_thresholds(sweep, capsys):
    assert results_main([str(sweep)]) == 0
    header = capsys.readouterr().out.splitlines()[1]
    assert "time_to_1e-3" in header and "time_to_1e-4" in header


def test_seed_band_a_diverged_seed_does_not_end_the_line():
    """Two seeds ran their 10 s, one diverged at 1 s: the line goes on to 10 s, the median of
    (finite, finite, diverged) is the larger finite one, and the band has no top after 1 s."""
    import numpy as np

    from higbench.results.plot import seed_band

    t = np.array([0.0, 5.0, 10.0])
    curves = [(t, np.array([1.0, 1e-2, 1e-3])), (t, np.array([1.0, 1e-1, 1e-2])), (np.array([0.0, 1.0]), np.array([1.0, 0.5]))]
    grid, median, low, high = seed_band(curves, [False, False, True])
    assert grid[-1] == 10.0
    assert median[-1] == pytest.approx(1e-2) and low[-1] == pytest.approx(1e-3)
    assert np.isnan(high[-1]) and np.isfinite(high[0])
    # without the flags the old rule: up to the earliest end (1 s)
    assert seed_band(curves)[0][-1] == 1.0


def _png_size(path):
    import struct

    return struct.unpack(">II", path.read_bytes()[16:24])  # IHDR: width, height


def test_a_sweep_found_twice_counts_once(sweep, tmp_path, capsys):
    """The README's and the recipe's sweep directories nested: every run file twice under the
    root. One run per configuration counts (3 seeds, not 6), and a note says so."""
    import shutil

    shutil.copytree(sweep, sweep / "defaults")
    assert results_main([str(sweep), "--plot", str(tmp_path / "c.png"), "--targets", "toy=1e-3"]) == 0
    out, err = capsys.readouterr()
    assert "- (0/3)" in out and "/6)" not in out
    assert "6 duplicate run(s) left out" in err


def test_left_out_runs_and_problems_without_targets_are_named(sweep, tmp_path, capsys):
    write_run(sweep / "cut/run.h5", optimizer="adam", status="interrupted", config_extra={"seed": 9})
    write_run(sweep / "osc/run.h5", problem="oscillator", optimizer="hig")
    assert results_main([str(sweep), "--plot", str(tmp_path / "c.png"), "--targets", "toy=1e-3"]) == 0
    err = capsys.readouterr().err
    assert "1 interrupted run(s) left out" in err
    assert "oscillator: 1 run(s) in the plot but not in the table" in err


def test_plot_wraps_panels_three_per_row(tmp_path):
    root = tmp_path / "five"
    for problem in ("a", "b", "c", "d", "e"):
        write_run(root / f"{problem}/run.h5", problem=problem, optimizer="hig")
    out = tmp_path / "five.png"
    assert results_main([str(root), "--plot", str(out)]) == 0
    width, height = _png_size(out)
    assert width <= 3 * 6.0 * 120 and height > 2 * 4.0 * 120  # 3 columns, 2 rows (dpi 120)


def test_best_keeps_setups_apart(tmp_path, capsys):
    """Toy GN at gamma=0.01 is not the best of the same group as HIG and Adam at gamma=1, and an
    amsgrad Adam is a setup of its own; the learning rate is what --best selects over."""
    root = tmp_path / "toy"
    write_run(root / "gn/run.h5", optimizer="gn", test_loss=[1.0, 1e-2], problem_extra={"gamma": 0.01})
    write_run(root / "gn1/run.h5", optimizer="gn", test_loss=[1.0, 1e-5])
    write_run(root / "hig/run.h5", optimizer="hig", test_loss=[1.0, 1e-4])
    write_run(root / "adam1/run.h5", optimizer="adam", lr=0.1, test_loss=[1.0, 1e-3])
    write_run(root / "adam2/run.h5", optimizer="adam", lr=0.01, test_loss=[1.0, 2e-3])
    amsgrad = {"optimizer": {"name": "adam", "lr": 0.1, "amsgrad": True}}
    write_run(root / "ams/run.h5", optimizer="adam", test_loss=[1.0, 1e-6], config_extra=amsgrad)
    assert results_main([str(root), "--best-seed"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = [line.split()[0] for line in lines[2 : lines.index("columns:")]]
    assert sorted(rows) == ["adam1/run.h5", "ams/run.h5", "gn/run.h5", "gn1/run.h5", "hig/run.h5"]


def test_bookkeeping_keys_do_not_split_a_setting(tmp_path):
    """tensorboard, threads, progress (the schema's cosmetic keys) and device=auto on a CPU make
    no setting of their own, in the config key and in the override labels alike."""
    import pandas as pd

    from higbench.results.index import load_runs, setting_config
    from higbench.results.profile import setting_labels

    base = {"problem": {"name": "toy"}, "optimizer": {"name": "hig", "lr": 1.0}, "seed": 0, "device": "cpu"}
    same = [
        {**base, "tensorboard": True, "threads": 1, "progress": False, "seed": 3},
        {**base, "device": "auto", "budget": {"seconds": 9}, "eval_every": 0.1},
    ]
    assert {setting_config(c, "cpu") for c in same} == {setting_config(base, "cpu")}
    assert setting_config({**base, "problem": {"name": "toy", "targets": [1e-3]}}, "cpu") == setting_config(base, "cpu")
    assert setting_config({**base, "problem": {"name": "toy", "gamma": 0.01}}, "cpu") != setting_config(base, "cpu")
    by_overrides = pd.DataFrame({"overrides": ["tensorboard=true seed=1", "device=cpu", ""], "optimizer.name": ["hig"] * 3})
    assert setting_labels(by_overrides).tolist() == ["hig", "hig device=cpu", "hig"]
    write_run(tmp_path / "a/run.h5", optimizer="hig", config_extra={"tensorboard": True, "seed": 1})
    write_run(tmp_path / "b/run.h5", optimizer="hig", config_extra={"tensorboard": False, "seed": 2})
    runs = load_runs(tmp_path)
    assert setting_labels(runs).tolist() == ["hig", "hig"]


def test_problem_dipole_cnn_finds_the_dipole_runs_with_the_cnn(tmp_path, capsys):
    root = tmp_path / "dipole"
    write_run(root / "cnn/run.h5", problem="dipole", optimizer="hig", problem_extra={"model": "cnn"})
    write_run(root / "mlp/run.h5", problem="dipole", optimizer="hig", problem_extra={"model": "mlp"})
    assert results_main([str(root), "--problem", "dipole_cnn"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("1 of 2 runs") and "cnn/run.h5" in out and "mlp/run.h5" not in out
    assert results_main([str(root), "--problem", "dipole"]) == 0
    assert capsys.readouterr().out.startswith("2 of 2 runs")


def test_best_reports_the_setting_by_its_median_over_seeds(tmp_path, capsys):
    """Three seeds per setting. HIG lr=1 has the single best seed (1e-6) but a median of 1e-2;
    HIG lr=0.1 has median 1e-4 over 3 seeds (range 5e-5 to 2e-3): --best names lr=0.1 with
    3 seeds and that range. --best-seed names the lucky lr=1 seed instead. Adam's lr=0.01
    has a diverged seed, counted as the worst value: median 3e-3 over 3 seeds, 1 diverged;
    Adam's lr=0.1 has one good seed (1e-5) and two diverged: its median is inf, so it loses."""
    import pandas as pd

    from higbench.results.index import best_settings, load_runs
    from higbench.results.profile import setting_labels

    root = tmp_path / "sweep"
    finals = {
        ("hig", 1.0): [1e-6, 1e-2, 5e-2],
        ("hig", 0.1): [2e-3, 1e-4, 5e-5],
        ("adam", 0.01): [3e-3, 1e-3, None],
        ("adam", 0.1): [1e-5, None, None],
    }
    for (opt, lr), losses in finals.items():
        for seed, final in enumerate(losses):
            write_run(
                root / f"{opt}_{lr}_{seed}/run.h5",
                optimizer=opt,
                lr=lr,
                test_loss=[1.0, 0.5, final if final is not None else float("nan")],
                status="completed" if final is not None else "diverged",
                config_extra={"seed": seed},
            )
    runs = load_runs(root)
    best = best_settings(runs.assign(setting=setting_labels(runs)), by="optimizer.name").set_index("optimizer.name")
    assert best.loc["hig", "optimizer.lr"] == 0.1 and best.loc["hig", "seeds"] == 3
    assert best.loc["hig", "final_test_loss_median"] == pytest.approx(1e-4)
    assert (best.loc["hig", "final_test_loss_min"], best.loc["hig", "final_test_loss_max"]) == pytest.approx((5e-5, 2e-3))
    assert best.loc["adam", "optimizer.lr"] == 0.01 and best.loc["adam", "seeds"] == 3
    assert best.loc["adam", "diverged_seeds"] == 1 and best.loc["adam", "runs_not_completed"] == 0
    assert best.loc["adam", "final_test_loss_median"] == pytest.approx(3e-3)

    assert results_main([str(root), "--best"]) == 0
    out = capsys.readouterr().out
    table = out.split("columns")[0].splitlines()
    header = table[2].split()
    assert header[:3] == ["problem.name", "optimizer.name", "setup"] and "final_test_loss_median" in header
    hig = next(line for line in table if " hig " in f" {line} ")
    assert "lr=0.1" in hig and "0.0001" in hig and "5e-05" in hig and "0.002" in hig
    legend = out.split("columns", 1)[1]
    for column in header:  # every column that does not explain itself has its line
        if column not in ("problem.name", "optimizer.name", "optimizer.lr", "batch_size"):  # names that explain themselves
            assert f"  {column}: " in legend, column

    assert results_main([str(root), "--best-seed"]) == 0
    out = capsys.readouterr().out
    assert any("hig_1.0_0/run.h5" in line for line in out.splitlines())
    assert isinstance(best, pd.DataFrame)
