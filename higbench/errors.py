"""``ConfigError``: a config value that cannot work, as one line ``key=value: why``.

The lowest layer: any module can raise one, show a value as the user types it (``show``)
or read a dotted key of a plain config (``dotted_get``) without importing anything else
of higbench.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
from typing import Any

EXIT_BAD_INPUT = 2
ABSENT = KeyError  # what ``dotted_get`` returns for a key that is not there (None is a value)


class ConfigError(ValueError):
    """A config value that cannot work; ``str()`` is the one-line message."""

    def __init__(self, key: str, value: Any, requirement: str):
        self.key, self.value, self.requirement = key, value, requirement
        super().__init__(f"{key}={show(value)}: {requirement}")


class MissingExtra(ConfigError):
    """An optimizer whose package comes with an optional extra that is not installed: fixed by a
    pip install, unlike a setting the problem cannot take (a league refuses to start without it
    rather than leave the optimizer out of its tables)."""


class MemoryRefusal(ConfigError):
    """A config refused because what it needs does not fit in the memory there is (the memory
    guard, the network-size check): the same config is refused again on the same machine, so a
    launcher records it as a result, not a failure to retry."""


MAX_SHOWN = 80  # a value longer than this is cut in messages: one line stays one line


def override_value(value: Any) -> str:
    """A value as a Hydra command-line override value, exactly (``key=<this>`` parses back to it)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        if value and re.fullmatch(r"[\w./:+-]+", value):
            return value
        # Hydra's quoted strings: only backslashes before a quote (or the closing one) are escapes
        return "'" + re.sub(r"(\\*)('|$)", lambda m: m[1] * 2 + ("\\'" if m[2] else ""), value) + "'"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(override_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ",".join(f"{k}:{override_value(v)}" for k, v in value.items()) + "}"
    try:
        return str(value)
    except ValueError:  # an integer of more than 4300 digits: Python refuses to print it
        return f"<an integer of {value.bit_length()} bits>"


def show(value: Any) -> str:
    """A value as the user would type it on the command line, cut to one short line for messages."""
    text = override_value(value)
    return text if len(text) <= MAX_SHOWN else f"{text[: MAX_SHOWN - 20]}...({len(text)} chars)"


def given_value(overrides, key: str) -> str | None:
    """The value ``key`` is given on the command line (the last one: it wins), or None."""
    for o in reversed(list(overrides)):
        k, sep, v = o.partition("=")
        if k.lstrip("+~") == key:
            return v if sep else "<missing>"
    return None


def dotted_get(data: Any, dotted: str, default: Any = ABSENT) -> Any:
    """``data["a"]["b"]`` for ``"a.b"`` in plain nested dicts; ``default`` where a part is missing."""
    node = data
    for part in str(dotted).split("."):
        if not isinstance(node, dict) or part not in node:
            return default
        node = node[part]
    return node


def dotted_set(data: dict, dotted: str, value: Any) -> None:
    """``data["a"]["b"] = value`` for ``"a.b"``, making the missing levels."""
    *parents, leaf = str(dotted).split(".")
    for part in parents:
        data = data.setdefault(part, {})
    data[leaf] = value


def leaves(node: Any, prefix: str = ""):
    """``(dotted key, value)`` of every value in nested mappings and lists that is neither."""
    if isinstance(node, (dict, list)):
        for k, v in node.items() if isinstance(node, dict) else enumerate(node):
            yield from leaves(v, f"{prefix}{k}.")
    else:
        yield prefix[:-1], node


def fail(exc: BaseException | str, code: int = EXIT_BAD_INPUT) -> None:
    """Print ``higbench: error: <one line>`` on stderr and exit (2: bad input)."""
    message = " ".join(str(exc).split())  # one line, whatever the cause
    print(f"higbench: error: {message}", file=sys.stderr, flush=True)
    sys.exit(code)


@contextlib.contextmanager
def quiet_broken_pipe():
    """``higbench --help | head``: the reader left; stop quietly (no BrokenPipeError traceback)."""
    try:
        yield
    except BrokenPipeError:
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        sys.exit(0)


class _OutputThatNeverFails:
    """A text stream whose writes never raise: once its reader is gone (``| head`` closed the
    pipe) or the stream fails, the rest of the output goes to the null device. Everything
    else (``isatty``, ``encoding``, ``fileno``) is the wrapped stream's."""

    def __init__(self, stream):
        self._stream, self.lost = stream, False

    def _lose(self) -> None:
        self.lost = True
        with contextlib.suppress(OSError, ValueError, AttributeError):  # what is still buffered goes nowhere, too
            os.dup2(os.open(os.devnull, os.O_WRONLY), self._stream.fileno())

    def write(self, text: str) -> int:
        if not self.lost:
            try:
                return self._stream.write(text)
            except OSError:
                self._lose()
        return len(text)

    def writelines(self, lines) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        if not self.lost:
            try:
                self._stream.flush()
            except OSError:
                self._lose()

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


@contextlib.contextmanager
def output_never_fails():
    """Inside the block, a failed write to stdout or stderr (a closed pipe: ``make run | head -3``)
    stops the output, never the work: training goes on and its run file says how it ended."""
    saved = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = _OutputThatNeverFails(sys.stdout), _OutputThatNeverFails(sys.stderr)
    try:
        yield
    finally:
        sys.stdout, sys.stderr = saved
