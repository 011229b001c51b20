"""The committed results (docs/results/REPORT.md) list exactly the registry's claims.

When a claim is added, removed or renamed, this fails until docs/results/ is regenerated
(`python -m higbench.figures all --preset quick --out docs/results`, see docs/results/README.md).
"""

import re
from pathlib import Path

import pytest

from higbench.figures import registry

REPORT = Path(__file__).resolve().parents[2] / "docs" / "results" / "REPORT.md"


@pytest.mark.skipif(not REPORT.is_file(), reason="no published results committed")
def test_published_report_lists_the_registry_claims():
    ids = re.findall(r"^\| ([a-z]+-\d+[a-z]?): ", REPORT.read_text(), re.M)
    assert len(ids) == len(set(ids))
    assert sorted(ids) == sorted(registry.claims())
