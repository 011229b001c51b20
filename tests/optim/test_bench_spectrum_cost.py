"""higbench.bench.spectrum_cost: the spectrum's cost per update against the update (a tiny config)."""

import json

import torch

from higbench.bench import spectrum_cost
from higbench.optim.hig import JacobianPower


def test_one_json_object_with_every_piece_and_the_share(capsys):
    threads = torch.get_num_threads()
    try:
        spectrum_cost.main(["--config", "toy:hig:8", "--repeats", "2", "--warmup", "1"])
    finally:
        torch.set_num_threads(threads)
    (row,) = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.startswith("{")]
    pieces = ("record_s", "columns_s", "sink_s", "quantiles_s", "write_s")
    assert all(row[k] > 0 for k in (*pieces, "update_s")) and row["singular_values"] > 0
    assert row["spectrum_s"] == sum(row[k] for k in pieces) and row["share"] == row["spectrum_s"] / row["update_s"]


def test_capture_leaves_the_optimizer_as_it_was():
    run = spectrum_cost.Runner(spectrum_cost.parse_config("toy:hig:8"), torch.float32)
    s, keep = spectrum_cost.capture_spectrum(run)
    opt = run.update.optimizer
    assert "_record_spectrum" not in vars(opt) and opt._record_spectrum.__func__ is JacobianPower._record_spectrum
    assert s.shape == keep.shape and float(s.max()) == opt.last_spectrum["sv_max"]
