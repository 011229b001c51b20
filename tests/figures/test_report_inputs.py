"""`python -m higbench.figures --report-only` refuses a results file it cannot read as what it
should be (a FIFO, malformed JSON) with one line naming it, exit 2; it never hangs on one."""

from __future__ import annotations

import json
import os
import threading

import pytest

from higbench.figures.__main__ import main

SIDECAR = {"id": "fig99", "claims": [], "runs": [{"path": "a/run.h5", "status": "completed"}]}


def _report(out, capsys) -> tuple[int | None, str]:
    """main(--report-only) in a thread: a reader blocked on a FIFO would never return."""
    result = {}
    worker = threading.Thread(target=lambda: result.update(code=main(["--report-only", "--out", str(out)])), daemon=True)
    worker.start()
    worker.join(timeout=30)
    assert not worker.is_alive(), "--report-only hung on a results file"
    return result.get("code"), capsys.readouterr().err


@pytest.mark.parametrize(
    "name,make,why",
    [
        ("fig98.json", lambda p: os.mkfifo(p), "not a regular file"),
        ("fig98.json", lambda p: p.write_text('{"id": "fig98", "claims": ['), "malformed JSON"),
    ],
)
def test_an_unreadable_results_file_is_refused_with_its_name(tmp_path, capsys, name, make, why):
    (tmp_path / "fig99.json").write_text(json.dumps(SIDECAR))
    make(tmp_path / name)
    code, err = _report(tmp_path, capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    assert lines[0].startswith("higbench-figures: error: ") and str(tmp_path / name) in lines[0] and why in lines[0]
    assert not (tmp_path / "REPORT.md").exists()  # nothing written


@pytest.mark.parametrize("make", [lambda p: os.mkfifo(p), lambda p: p.write_bytes(b'a,b\n"1,2\n')])
def test_the_report_does_not_read_the_plotted_data(tmp_path, capsys, make):
    """The report is assembled from the rows and run lists (<id>.json) alone: the seed gate no longer
    sizes an exception from the plotted data (<id>.csv), so a FIFO or malformed CSV there is never opened."""
    (tmp_path / "fig99.json").write_text(json.dumps(SIDECAR))
    make(tmp_path / "fig99.csv")
    code, err = _report(tmp_path, capsys)
    assert code == 0, err


def test_well_formed_results_still_make_the_report(tmp_path, capsys):
    (tmp_path / "fig99.json").write_text(json.dumps(SIDECAR))
    (tmp_path / "notes.json").write_text("[1, 2]")  # valid JSON that is not a figure's data: passed over
    code, err = _report(tmp_path, capsys)
    assert code == 0, err
    assert (tmp_path / "REPORT.md").read_text().startswith("# Reproduction report")
