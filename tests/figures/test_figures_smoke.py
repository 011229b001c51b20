"""`python -m higbench.figures --preset smoke`: one figure of each problem, from real runs.

Default suite: fig1 (toy), fig2b + table2 (oscillators), fig3c (Poisson, a chain of
init_from runs) and fig4c (dipole) in a tmp dir. Checks: every output file exists; the
plotted data (<id>.csv) are the run files' curves; the sidecar names the runs and the
preset; a second invocation trains nothing; a failed run is run again, and only it.
Slow: the whole smoke preset (every figure and table).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pandas as pd
import pytest

from higbench.runfile.reader import load_run

pytestmark = pytest.mark.process  # the figures' joblib rounds start workers (in this process otherwise)

REPO = Path(__file__).resolve().parents[2]
IDS = ["fig1", "fig2b", "table2", "fig3c", "fig4c"]


def figures(*args: str, cwd: Path, timeout: float = 600) -> tuple[SimpleNamespace, float]:
    """``python -m higbench.figures *args`` from ``cwd``, in this process (its runs too:
    tests/in_process.py ``launch_in_process``) -> (returncode, stdout, stderr), seconds."""
    from in_process import launch_in_process, restored_process_state

    from higbench.figures.__main__ import main

    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    with restored_process_state(), pytest.MonkeyPatch.context() as mp:
        mp.chdir(cwd)
        launch_in_process(mp)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(list(args))
            except SystemExit as exc:
                code = exc.code
    elapsed = time.perf_counter() - t0
    proc = SimpleNamespace(returncode=code or 0, stdout=out.getvalue(), stderr=err.getvalue())
    assert proc.returncode == 0, f"exit {proc.returncode}\nstdout:\n{proc.stdout[-4000:]}\nstderr:\n{proc.stderr[-4000:]}"
    return proc, elapsed


def run_files(root: Path) -> set[Path]:
    return set(root.rglob("run.h5"))


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    base = tmp_path_factory.mktemp("figs")
    runs, out = base / "outputs", base / "figures"
    args = [*IDS, "--preset", "smoke", "--runs-root", str(runs), "--out", str(out)]
    first, t_first = figures(*args, cwd=base)
    files_first = run_files(runs)
    second, t_second = figures(*args, cwd=base)
    return {
        "base": base,
        "runs": runs,
        "out": out,
        "args": args,
        "first": first,
        "second": second,
        "t_first": t_first,
        "t_second": t_second,
        "files_first": files_first,
    }


def test_outputs_exist(smoke):
    out = smoke["out"]
    for fid in IDS:
        assert (out / f"{fid}.json").is_file(), fid
        if fid.startswith("table"):
            assert (out / f"{fid}.md").is_file() and (out / f"{fid}.csv").is_file()
        else:
            for ext in ("png", "pdf", "csv"):
                assert (out / f"{fid}.{ext}").stat().st_size > 0, (fid, ext)
    report = (out / "REPORT.md").read_text()
    for cid in ("toy-1", "toy-4", "osc-1", "osc-4", "poi-2", "dip-1", "dip-2"):
        assert f"| {cid}:" in report, cid


def test_runs_are_the_declared_ones(smoke):
    # 14 toy (2 gamma x 3 optimizers x 2 seeds, re-tuned Adam x 2 seeds) + 9 oscillator (6 optimizers, GN's
    # 2-seed search whose best run is GN's run, re-tuned Adam) + 4 Poisson (+ re-tuned Adam continued) + 2 dipole
    assert len(smoke["files_first"]) == 14 + 9 + 4 + 2
    for fid in IDS:
        info = json.loads((smoke["out"] / f"{fid}.json").read_text())
        assert info["preset"] == "smoke" and info["budgets"] == {"all runs": "2 updates"}
        for r in info["runs"]:
            assert r["status"] in ("completed", "diverged"), r
            path = Path(r["path"]) if Path(r["path"]).is_absolute() else smoke["base"] / r["path"]
            meta, curves = load_run(path)
            assert meta["config"]["budget"]["max_updates"] == 2
            assert meta["status"] == r["status"]


def test_plotted_data_come_from_the_run_files(smoke):
    base = smoke["base"]
    checked = 0
    for fid in ("fig1", "fig2b", "fig3c", "fig4c"):
        data = pd.read_csv(smoke["out"] / f"{fid}.csv")
        curves = data[data["x_name"] == "wall_time"]
        assert len(curves), fid
        for (run, y_name), rows in curves.groupby(["run", "y_name"], sort=False):
            path = Path(run) if Path(run).is_absolute() else base / run
            _, c = load_run(path)
            if y_name not in c:
                continue  # per-neuron logs: checked below
            y = c[y_name].to_numpy(dtype=float)
            x = c["wall_time"].to_numpy(dtype=float)
            assert np.allclose(rows["y"].to_numpy(dtype=float), y, rtol=1e-12, equal_nan=True), (fid, run, y_name)
            dx = rows["x"].to_numpy(dtype=float) - x  # continued runs are drawn after their parent: a constant shift
            assert np.allclose(dx, dx[0], atol=1e-9) and dx[0] >= 0, (fid, run)
            checked += 1
    assert checked >= 12 + 7 + 3 + 2 * 2
    fig3c = pd.read_csv(smoke["out"] / "fig3c.csv")
    assert fig3c["series"].str.contains("HIG pre-trained").any()


def test_fig1_neuron_and_trajectory_data_are_the_logged_arrays(smoke):
    from higbench.runfile.reader import load_logs

    data = pd.read_csv(smoke["out"] / "fig1.csv")
    traj = data[data["panel"].str.startswith("trajectory")]
    assert len(traj)
    for run, rows in traj.groupby("run"):
        logs = load_logs(smoke["base"] / run if not Path(run).is_absolute() else run)
        assert np.allclose(rows["x"], logs["probe_output"][:, 0]) and np.allclose(rows["y"], logs["probe_output"][:, 1])


def test_table2_is_read_from_the_fig2b_run_configs(smoke):
    table = pd.read_csv(smoke["out"] / "table2.csv", index_col=0)
    info = json.loads((smoke["out"] / "table2.json").read_text())
    assert {r["identity"] for r in info["runs"]} == {
        r["identity"] for r in json.loads((smoke["out"] / "fig2b.json").read_text())["runs"]
    }
    for r in info["runs"]:
        if r["sweep"] != "best":  # GN's seed search and the re-tuned Adam are not table 2's runs
            continue
        meta, _ = load_run(smoke["base"] / r["path"] if not Path(r["path"]).is_absolute() else r["path"])
        name = {
            "adam": "Adam",
            "hig": "HIG",
            "gn": "GN",
            "sgd": "SGD",
            "adagrad": "Adagrad",
            "adadelta": "Adadelta",
            "rmsprop": "RMSprop",
        }[meta["config"]["optimizer"]["name"]]
        assert int(table.loc["b", name]) == meta["config"]["batch_size"]


def test_second_invocation_trains_nothing(smoke):
    assert "0 run(s) launched" in smoke["second"].stdout, smoke["second"].stdout
    assert run_files(smoke["runs"]) == smoke["files_first"]
    assert smoke["t_second"] < smoke["t_first"]


def test_a_failed_run_is_run_again_and_only_it(smoke):
    info = json.loads((smoke["out"] / "fig2b.json").read_text())
    victim = next(r for r in info["runs"] if "optimizer=sgd" in r["overrides"])
    path = Path(victim["path"]) if Path(victim["path"]).is_absolute() else smoke["base"] / victim["path"]
    with h5py.File(path, "a") as f:
        f.attrs["status"] = "failed"
    before = run_files(smoke["runs"])
    proc, _ = figures("fig2b", *smoke["args"][len(IDS) :], cwd=smoke["base"])
    assert "1 run(s) launched" in proc.stdout, proc.stdout
    new = run_files(smoke["runs"]) - before
    assert len(new) == 1
    meta, _ = load_run(new.pop())
    assert meta["config"]["optimizer"]["name"] == "sgd" and meta["status"] == "completed"


@pytest.mark.slow
def test_whole_smoke_preset(tmp_path):
    proc, elapsed = figures(
        "all",
        "--preset",
        "smoke",
        "--runs-root",
        str(tmp_path / "outputs"),
        "--out",
        str(tmp_path / "figures"),
        cwd=tmp_path,
        timeout=1800,
    )
    from higbench.figures import registry

    for fid, fig in registry.figures().items():
        assert (tmp_path / "figures" / f"{fid}.json").is_file(), fid
        suffixes = ("md", "csv") if fig.kind == "table" else ("png", "pdf", "csv")
        for ext in suffixes:
            assert (tmp_path / "figures" / f"{fid}.{ext}").is_file(), (fid, ext)
        info = json.loads((tmp_path / "figures" / f"{fid}.json").read_text())
        assert "error" not in info, (fid, info.get("error"))
        assert all(r["status"] in ("completed", "diverged") for r in info["runs"]), fid
    again, t_again = figures(
        "all", "--preset", "smoke", "--runs-root", str(tmp_path / "outputs"), "--out", str(tmp_path / "figures"), cwd=tmp_path
    )
    assert "0 run(s) launched" in again.stdout and t_again < elapsed


@pytest.mark.slow
def test_a_run_made_by_hand_with_the_cli_is_reused(tmp_path):
    """A plain `higbench` run with the same resolved config counts (threads/progress do not matter)."""
    from higbench.figures import registry
    from higbench.figures.spec import Preset, expand

    job = next(j for j in expand(registry.figures()["fig4c"], Preset("smoke")) if j.overrides["optimizer"] == "hig")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), *filter(None, [os.environ.get("PYTHONPATH")])]))
    by_hand = [*job.override_list(), "threads=2", "progress=true", f"hydra.run.dir={tmp_path / 'outputs' / 'runs' / 'mine'}"]
    proc = subprocess.run(
        [sys.executable, "-m", "higbench.cli", *by_hand], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    out, _ = figures(
        "fig4c", "--preset", "smoke", "--runs-root", str(tmp_path / "outputs"), "--out", str(tmp_path / "figs"), cwd=tmp_path
    )
    assert "1 run(s) launched" in out.stdout, out.stdout  # the Adam run only
    info = json.loads((tmp_path / "figs" / "fig4c.json").read_text())
    hig = next(r for r in info["runs"] if r["sweep"] == "hig")
    assert "runs/mine/run.h5" in hig["path"]
