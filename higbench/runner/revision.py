"""The checkout's git revision, without importing torch (the figures read it too)."""

from __future__ import annotations

import os
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
        # GIT_OPTIONAL_LOCKS=0: `git status` would otherwise take the checkout's index.lock to
        # refresh the index (a write into the user's checkout, and a clash with their own git).
        env = {**os.environ, "GIT_OPTIONAL_LOCKS": "0"}
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True, text=True, timeout=5, env=env,
        )  # fmt: skip
        return rev.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return ""
