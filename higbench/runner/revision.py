"""The checkout's git revision, without importing torch (the figures read it too)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import higbench


def git_revision() -> str:
    """The checkout's revision (with '-dirty' if modified), or '' when not in a git checkout."""
    root = Path(higbench.__file__).resolve().parent.parent
    try:
        rev = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5)
        if rev.returncode != 0:
            return ""
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True, timeout=5
        )
        return rev.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return ""
