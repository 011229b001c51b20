"""higbench.bench.step: JSON rows per configuration, memory probe, paper-table files (tiny configs)."""

import json
import sys
from pathlib import Path

import pandas as pd
import pytest
import torch

from higbench.bench import step as bench_step
from higbench.bench.paper import PAPER_COSTS, PROBLEM_TABLES

ROOT = Path(__file__).resolve().parents[2]

REQUIRED = {
    "problem",
    "optimizer",
    "batch_size",
    "update_s",
    "jacobian_s",
    "inversion_s",
    "apply_s",
    "peak_mem_mb",
    "jacobian",
    "solver",
}


def test_one_json_object_per_configuration(capsys):
    threads = torch.get_num_threads()
    try:
        bench_step.main(
            ["--problem", "toy", "--optimizer", "adam", "hig", "--batch-size", "8", "--jacobian", "structured", "naive"]
            + ["--repeats", "2", "--warmup", "1", "--no-memory"]
        )
    finally:
        torch.set_num_threads(threads)
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.startswith("{")]
    assert [(r["optimizer"], r["jacobian"]) for r in rows] == [("adam", "-"), ("hig", "structured"), ("hig", "naive")]
    for r in rows:
        assert REQUIRED <= set(r) and r["batch_size"] == 8 and r["repeats"] == 2 and r["finite"]
        assert r["update_s"] == pytest.approx(r["jacobian_s"] + r["inversion_s"] + r["apply_s"])
        assert r["update_s"] > 0
    assert rows[0]["inversion_s"] == 0.0 and rows[1]["inversion_s"] > 0


def test_memory_probe_counts_the_update_not_the_set_up():
    cfg = bench_step.Config("toy", "hig", 16, "structured", "auto")
    mb = bench_step.memory_probe(cfg, warmup=0, dtype=torch.float64)
    assert 0 <= mb < 50  # the toy's J is 32 x 30: nothing near the ~300 MB of the process itself


def test_paper_tables_files_and_targets(tmp_path):
    rows = []
    for group in bench_step.paper_configs(naive_all=False):
        for cfg in group:
            t = bench_step.Timing()
            t.wall = [1.0]
            seconds = {"adam": 0.1, "hig": 0.12}[cfg.optimizer] * (10 if cfg.jacobian == "naive" else 1)
            t.phases = {"jacobian_s": [seconds], "inversion_s": [0.0], "apply_s": [0.0]}
            rows.append(bench_step.row(cfg, t, 100.0, 1, "float32"))
    meta = {
        "date": "today",
        "machine": "test",
        "torch": torch.__version__,
        "threads": 1,
        "dtype": "float32",
        "repeats": 1,
        "warmup": 0,
    }
    bench_step.write_tables(rows, tmp_path, meta)
    df = pd.read_csv(tmp_path / "paper_tables.csv")
    assert len(df) == 13 + 1 + 6  # paper rows, Poisson b=16 structured, naive beside every HIG row but Poisson b=64
    assert set(df.table) == {3, 4, 5}
    assert df.loc[(df.problem == "poisson") & (df.optimizer == "hig") & (df.batch_size == 64), "paper_update_s"].item() == 13.8
    text = (tmp_path / "paper_tables.md").read_text()
    assert "## Table 3: oscillator" in text and "## Targets" in text
    goals = {t["target"]: t for t in bench_step.targets(rows)}
    assert goals["oscillator HIG b=128 / Adam b=512"]["value"] == pytest.approx(1.2)
    assert goals["oscillator HIG b=128 / Adam b=512"]["reached"]
    assert goals["Poisson b=16 naive SVD / Gram (speed-up)"]["value"] == pytest.approx(10.0)


def test_paper_costs_are_one_copy_shared_by_the_benchmark_and_the_tables():
    from higbench.bench.tables import PAPER_TIMINGS, PROBLEMS

    from_tables = {(PROBLEMS[tid], o, b): cost for tid, rows in PAPER_TIMINGS.items() for (o, b), cost in rows.items()}
    assert from_tables == PAPER_COSTS and len(PAPER_COSTS) == 13
    assert {f"table{n}": p for p, n in PROBLEM_TABLES.items()} == PROBLEMS
    assert PAPER_COSTS[("poisson", "hig", 64)] == (3560, 13.8, 0.0035)  # spot check against the paper's table 4


def test_script_is_a_thin_entry_point_to_the_package(monkeypatch, capsys):
    import runpy

    script = ROOT / "scripts" / "bench_step.py"
    assert "from higbench.bench.step import main" in script.read_text() and "def " not in script.read_text()
    monkeypatch.setattr(sys, "argv", [str(script), "--help"])
    with pytest.raises(SystemExit) as info:
        runpy.run_path(str(script), run_name="__main__")  # `python scripts/bench_step.py --help`, in this process
    assert info.value.code == 0 and "--paper-tables" in capsys.readouterr().out


@pytest.mark.skipif(torch.cuda.is_available(), reason="needs a machine without CUDA")
def test_cuda_asked_for_without_one_is_one_clear_error(capsys):
    with pytest.raises(SystemExit) as exit_info:
        bench_step.main(["--problem", "toy", "--device", "cuda", "--no-memory"])
    assert exit_info.value.code == 2 and "--device cuda: CUDA is not available" in capsys.readouterr().err


def test_the_cpu_targets_are_left_out_of_a_gpu_table(tmp_path):
    cfg = bench_step.Config("oscillator", "adam", 512)
    t = bench_step.Timing()
    t.wall, t.phases = [1.0], {"jacobian_s": [0.1], "inversion_s": [0.0], "apply_s": [0.0]}
    meta = dict(date="today", machine="test", torch="x", threads=1, dtype="float32", repeats=1, warmup=0)
    for device, has_targets in (("cpu", True), ("cuda", False)):
        bench_step.write_tables([bench_step.row(cfg, t, 1.0, 1, "float32")], tmp_path, meta | {"device": device})
        assert ("## Targets" in (tmp_path / "paper_tables.md").read_text()) is has_targets
