"""``ConfigError``: a config value that cannot work, as one line ``key=value: why``.

Kept apart from the schema (``higbench.config``) so any module can raise one cheaply.
"""

from __future__ import annotations

import re
import sys
from typing import Any

EXIT_BAD_INPUT = 2


class ConfigError(ValueError):
    """A config value that cannot work; ``str()`` is the one-line message."""

    def __init__(self, key: str, value: Any, requirement: str):
        self.key, self.value, self.requirement = key, value, requirement
        super().__init__(f"{key}={show(value)}: {requirement}")


def show(value: Any) -> str:
    """A value as the user would type it on the command line."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return value if value and re.fullmatch(r"[\w./:+-]+", value) else repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(show(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ",".join(f"{k}:{show(v)}" for k, v in value.items()) + "}"
    return str(value)


def fail(exc: BaseException | str, code: int = EXIT_BAD_INPUT) -> None:
    """Print ``higbench: error: <one line>`` on stderr and exit (2: bad input)."""
    from higbench.runner.progress import clear_transient

    clear_transient()  # the terminal's "checking" line: the error replaces it
    message = " ".join(str(exc).split())  # one line, whatever the cause
    print(f"higbench: error: {message}", file=sys.stderr, flush=True)
    sys.exit(code)
