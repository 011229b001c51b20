"""The league as a script of the checkout: the installed ``higbench-league`` command (higbench.league)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from higbench.league.__main__ import main  # noqa: E402

sys.exit(main())
