"""The fault-injection suite (issue 7). Helpers live in rel_helpers.py (imported by name:
pytest puts this folder on sys.path when it imports the test modules)."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
