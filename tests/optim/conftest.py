"""Put this folder on sys.path for ``optim_helpers`` (the tests folders are not packages)."""

import sys
from pathlib import Path

HERE = str(Path(__file__).resolve().parent)
if HERE not in sys.path:
    sys.path.insert(0, HERE)
