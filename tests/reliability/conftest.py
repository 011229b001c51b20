"""Fixtures shared by the reliability tests."""

from __future__ import annotations

from pathlib import Path

import pytest
from cases import TINY_RUN

from higbench import cli


@pytest.fixture
def completed(tmp_path, monkeypatch):
    """A function making a completed run in a new directory under tmp_path."""
    monkeypatch.chdir(tmp_path)

    def make(name: str) -> Path:
        cli.main([*TINY_RUN, "problem=toy", "optimizer=adam", f"hydra.run.dir={tmp_path / name}"])
        return tmp_path / name / "run.h5"

    return make
