"""examples/hig_in_your_code.ipynb runs top to bottom, and HIG reaches the notebook's target
test loss in far fewer updates and seconds than Adam.

Each optimizer trains for a fixed number of updates, so the loss curves do not depend on the
machine's speed or load. A 6 s wall-clock budget did: made on a loaded machine, the
notebook showed Adam at lr=1e-3 100x above HIG; on an idle one Adam makes four times those
updates in 6 s, and CI measured 2x. Only the seconds are this machine's.

The margins asserted are well inside those measured, so that another machine's floating
point (a slightly different curve) or a burst of load during HIG's fraction of a second does
not fail it: updates 5x (measured 23x: 120 against 2,810), seconds 2x (measured 12x)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytestmark = pytest.mark.process  # a Jupyter kernel runs the notebook

nbformat = pytest.importorskip("nbformat", reason="needs the dev extra (nbformat, nbclient, ipykernel): make install-dev")
nbclient = pytest.importorskip("nbclient", reason="needs the dev extra (nbformat, nbclient, ipykernel): make install-dev")

NOTEBOOK = Path(__file__).resolve().parents[1] / "examples" / "hig_in_your_code.ipynb"


def test_notebook_runs_and_hig_reaches_the_target_loss_long_before_adam(tmp_path):
    nb = nbformat.read(NOTEBOOK, as_version=4)
    for cell in nb.cells:  # run from scratch, not from the stored outputs
        if cell.cell_type == "code":
            cell.outputs = []
    # raises CellExecutionError, with the cell and its traceback, if any cell fails
    where = {"metadata": {"path": str(tmp_path)}}  # run where a copy would be (README: outputs/): it saves its plot there
    client = nbclient.NotebookClient(nb, timeout=240, kernel_name="python3", resources=where)
    client.execute()
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert all(c.execution_count for c in code), "a code cell did not run"
    assert any("image/png" in o.get("data", {}) for c in code for o in c.outputs), "no plot drawn"
    assert (tmp_path / "hig_in_your_code.png").read_bytes()[:4] == b"\x89PNG", "the plot was not saved next to the notebook"
    reached = json.loads(code[-1].outputs[-1]["text"].splitlines()[-1])
    hig, tuned, default = reached["HIG (lr=1)"], reached["Adam (lr=1e-2)"], reached["Adam (lr=1e-3)"]
    assert hig["updates"] is not None, f"HIG never reached the target: {reached}"
    assert tuned["updates"] is not None, f"the re-tuned Adam never reached the target: {reached}"
    assert hig["updates"] * 5 < tuned["updates"], f"HIG not five times fewer updates than Adam at lr=1e-2: {reached}"
    assert hig["seconds"] * 2 < tuned["seconds"], f"HIG not twice as soon as Adam at lr=1e-2: {reached}"
    assert default["updates"] is None or default["updates"] > tuned["updates"], f"Adam at lr=1e-3 beat lr=1e-2: {reached}"
