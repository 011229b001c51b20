"""examples/hig_in_your_code.ipynb runs top to bottom, and HIG ends far below Adam at lr=1e-3 at equal wall clock.

Against the re-tuned Adam (lr=1e-2) six seconds decide nothing reliably (1.1x above to 10x
below over repeated runs), so the notebook says so and the test does not assert it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat", reason="needs the dev extra (nbformat, nbclient, ipykernel): make install-dev")
nbclient = pytest.importorskip("nbclient", reason="needs the dev extra (nbformat, nbclient, ipykernel): make install-dev")

NOTEBOOK = Path(__file__).resolve().parents[1] / "examples" / "hig_in_your_code.ipynb"


def test_notebook_runs_and_hig_beats_adam_at_its_default_lr():
    nb = nbformat.read(NOTEBOOK, as_version=4)
    for cell in nb.cells:  # run from scratch, not from the stored outputs
        if cell.cell_type == "code":
            cell.outputs = []
    # raises CellExecutionError, with the cell and its traceback, if any cell fails
    where = {"metadata": {"path": str(NOTEBOOK.parent)}}
    client = nbclient.NotebookClient(nb, timeout=240, kernel_name="python3", resources=where)
    client.execute()
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert all(c.execution_count for c in code), "a code cell did not run"
    assert any("image/png" in o.get("data", {}) for c in code for o in c.outputs), "no plot drawn"
    final = json.loads(code[-1].outputs[-1]["text"])
    hig, adams = final.pop("HIG (lr=1)"), final
    assert hig < 1e-2, f"HIG's final test loss {hig:.2e} (expected < 1e-2 after 6 s)"
    assert hig < adams["Adam (lr=1e-3)"] / 3, f"HIG {hig:.2e} not well below Adam at lr=1e-3 {adams}"
