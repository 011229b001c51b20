"""The spectrum of GN/HIG/LM steps in the results: the index's conditioning columns and
``higbench-results --spectrum``, on synthetic run files (real RunFileWriter) and one short real run."""

from __future__ import annotations

import math

import numpy as np
import pytest
from synthetic import short_run, write_run

from higbench.results import load_runs
from higbench.results import plot as plot_mod
from higbench.results.__main__ import main as results_main
from higbench.results.spectrum import conditioning, read_spectrum

PNG = b"\x89PNG"
NAN = math.nan


def spectrum_run(path, sv_max, sv_min_kept, sv_dropped, quantiles=None, tau=0.01, truncation="relative", n_updates=None):
    """A completed HIG run file whose /updates hold the given spectrum columns and whose
    /logs/sv_quantiles the given rows (one per evaluation: 4, as write_run's curves)."""
    n = n_updates or len(sv_max)
    optimizer = {"name": "hig", "lr": 1.0, "tau": tau, "truncation": truncation}
    w = write_run(path, optimizer="hig", n_updates=n, close=False, config_extra={"optimizer": optimizer})
    w.append_rows("updates", {"sv_max": sv_max, "sv_min_kept": sv_min_kept, "sv_dropped": sv_dropped})
    for q in quantiles if quantiles is not None else []:
        w.append_row("logs", {"sv_quantiles": np.asarray(q, dtype=float)})
    w.f.attrs["steps"] = n
    w.close("completed", "", n)
    return path


@pytest.fixture
def mixed(tmp_path):
    """hig: 4 updates with known spectra; adam: no spectrum (the old files look the same)."""
    root = tmp_path / "runs"
    q = [np.full(11, NAN)] + [np.geomspace(1e-3, 10.0, 11)] * 3
    spectrum_run(root / "hig/run.h5", [10.0, 10.0, 20.0, 5.0], [1.0, 0.1, 0.02, NAN], [0, 2, 4, NAN], q)
    write_run(root / "adam/run.h5", optimizer="adam")
    return root


def test_index_says_how_ill_conditioned_each_runs_steps_were(mixed):
    runs = load_runs(mixed).set_index("optimizer.name")
    hig, adam = runs.loc["hig"], runs.loc["adam"]
    # sv_max / sv_min_kept = 10, 100, 1000 (the update without a kept value left out)
    assert hig["cond_kept_median"] == pytest.approx(100.0) and hig["cond_kept_max"] == pytest.approx(1000.0)
    assert hig["sv_dropped_mean"] == pytest.approx(2.0)
    assert all(math.isnan(adam[c]) for c in ("cond_kept_median", "cond_kept_max", "sv_dropped_mean"))


def test_conditioning_of_nothing_is_nan():
    assert all(math.isnan(v) for v in conditioning({}).values())
    c = conditioning({"sv_max": np.array([NAN]), "sv_min_kept": np.array([NAN]), "sv_dropped": np.array([NAN])})
    assert all(math.isnan(v) for v in c.values())


def test_shorter_spectrum_columns_do_not_cut_the_timings(tmp_path):
    # 20 updates timed, the spectrum only for the last 5 (an old file resumed by this version)
    path = spectrum_run(tmp_path / "r.h5", [4.0] * 5, [2.0] * 5, [1] * 5, n_updates=20)
    run = load_runs(path).iloc[0]
    assert run["mean_update_s"] == pytest.approx(0.01) and run["cond_kept_median"] == pytest.approx(2.0)


def test_default_table_shows_the_conditioning(mixed, capsys):
    assert results_main([str(mixed)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split()[-2:] == ["cond_kept_median", "sv_dropped_mean"]  # after the other columns
    hig = next(line.split() for line in lines[2:] if line.split()[0] == "hig/run.h5")
    assert hig[-2:] == ["100", "2"]


def test_read_spectrum_aligns_quantiles_with_evaluations_and_reads_tau(mixed, tmp_path):
    s = read_spectrum(mixed / "hig/run.h5")
    assert s.step.tolist() == [1, 2, 3, 4] and s.eval_step.tolist() == [0, 1, 2, 4]
    assert s.quantiles.shape == (4, 11) and s.levels[5] == 0.5
    np.testing.assert_allclose(s.cutoff(), 0.01 * np.array([10.0, 10.0, 20.0, 5.0]))
    assert read_spectrum(mixed / "adam/run.h5") is None
    absolute = read_spectrum(spectrum_run(tmp_path / "a.h5", [3.0, 4.0], [1.0, 1.0], [0, 0], tau=0.5, truncation="absolute"))
    assert absolute.cutoff().tolist() == [0.5, 0.5] and len(absolute.quantiles) == 0


def test_spectrum_figure_has_one_panel_per_run_with_a_spectrum(mixed, tmp_path, capsys, monkeypatch):
    spectrum_run(mixed / "hig2/run.h5", [1.0, 2.0], [0.5, 0.5], [1, 1])
    (mixed / "broken").mkdir()
    (mixed / "broken/run.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 100)  # truncated
    drawn = []
    real = plot_mod.plot_spectrum
    monkeypatch.setattr(plot_mod, "plot_spectrum", lambda spectra, path: drawn.extend(spectra) or real(spectra, path))
    out = tmp_path / "spectrum.png"
    assert results_main([str(mixed), "--spectrum", str(out)]) == 0
    assert out.read_bytes()[:4] == PNG
    assert [title.split(": ")[-1] for title, _ in drawn] == ["hig/run.h5", "hig2/run.h5"]  # adam has none
    captured = capsys.readouterr()
    assert f"spectrum: {out}" in captured.out and "broken/run.h5" in captured.err  # noted, not drawn


def test_spectrum_without_any_spectrum_is_one_line_and_exit_2(mixed, tmp_path, capsys):
    out = tmp_path / "spectrum.png"
    assert results_main([str(mixed), "--optimizer", "adam", "--spectrum", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"higbench-results: error: --spectrum {out}: none of the 1")
    assert not out.exists()


def _train(tmp_path, *overrides):
    return short_run(tmp_path, "hig", "optimizer.tau=0.05", *overrides, updates=6, eval_every=2)


def test_a_real_hig_run_has_its_conditioning_and_figure(tmp_path, capsys):
    path = _train(tmp_path)
    run = load_runs(path).iloc[0]
    # relative tau = 0.05: every kept singular value is within a factor 20 of the largest
    assert 1.0 <= run["cond_kept_median"] <= run["cond_kept_max"] <= 20.0 * (1 + 1e-12)
    assert run["sv_dropped_mean"] >= 0
    s = read_spectrum(path)
    assert s.step.tolist() == [1, 2, 3, 4, 5, 6] and s.eval_step.tolist() == [0, 2, 4, 6] and s.tau == 0.05
    assert s.quantiles.shape == (4, 11) and np.isnan(s.quantiles[0]).all()  # step 0: no update yet
    np.testing.assert_allclose(s.quantiles[1:, -1], s.sv_max[[1, 3, 5]])  # the largest of the last update
    out = tmp_path / "spectrum.png"
    assert results_main([str(path), "--spectrum", str(out)]) == 0
    assert out.read_bytes()[:4] == PNG
