"""Structured-config schemas: a dataclass per config node, range rules beside the fields.

OmegaConf checks the types and refuses unknown keys when a node is merged into its
dataclass; ``check(schema, values, prefix)`` does that and then the rules written next to
the fields with ``value(...)`` (bounds, choices, list length), turning any failure into a
one-line ``ConfigError``. Float values must be finite. A problem's schema is the ``Config``
dataclass of its ``Problem`` class (``higbench.problems.base``).
"""

from __future__ import annotations

import dataclasses
import importlib
import math
import re
import typing
from typing import Any

from omegaconf import MISSING, OmegaConf
from omegaconf.errors import ConfigKeyError, ValidationError

from higbench.errors import ConfigError


def value(default: Any = MISSING, *, ge=None, gt=None, le=None, lt=None, choices=None, length=None) -> Any:
    """A dataclass field with its rule; without a default the key is required (from conf/)."""
    rule = {k: v for k, v in dict(ge=ge, gt=gt, le=le, lt=lt, choices=choices, length=length).items() if v is not None}
    return dataclasses.field(default=default, metadata={"rule": rule})


def _bounds(rule: dict) -> str:
    lo = ("[", rule["ge"]) if "ge" in rule else ("(", rule["gt"]) if "gt" in rule else None
    hi = ("]", rule["le"]) if "le" in rule else (")", rule["lt"]) if "lt" in rule else None
    if lo and hi:
        return f" in {lo[0]}{lo[1]}, {hi[1]}{hi[0]}"
    if lo:
        return f" {'>=' if lo[0] == '[' else '>'} {lo[1]}"
    if hi:
        return f" {'<=' if hi[0] == ']' else '<'} {hi[1]}"
    return ""


def _broken(rule: dict, v: Any) -> str | None:
    """Why the single value ``v`` breaks ``rule`` (None: it does not)."""
    if "choices" in rule:
        return None if v in rule["choices"] else f"must be one of {', '.join(map(str, rule['choices']))}"
    if not isinstance(v, (int, float)) or isinstance(v, bool):
        return None  # OmegaConf checked the type
    kind = "an integer" if isinstance(v, int) else "a number"
    ok = math.isfinite(v) and all(
        (k != "ge" or v >= b) and (k != "gt" or v > b) and (k != "le" or v <= b) and (k != "lt" or v < b) for k, b in rule.items()
    )
    return None if ok else f"must be {kind}{_bounds(rule) or ' (finite)'}"


def locate(path: str) -> Any:
    """The object a dotted ``_target_`` names (a class in a module), or ImportError/AttributeError."""
    parts = str(path).split(".")
    for i in range(len(parts) - 1, 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ModuleNotFoundError:
            continue
        for name in parts[i:]:
            obj = getattr(obj, name)
        return obj
    raise ImportError(f"no module in {path!r}")


def _at(values: Any, dotted: str) -> Any:
    for part in dotted.split("."):
        values = values.get(part) if isinstance(values, dict) else None
    return values


def check(schema: type, values: Any, prefix: str = "") -> dict:
    """``values`` merged into ``schema`` and checked; the plain result, or ConfigError."""
    if not isinstance(values, dict):
        raise ConfigError(prefix.rstrip(".") or "config", values, f"must be a mapping of the keys of {schema.__name__}")
    try:
        merged = OmegaConf.merge(OmegaConf.structured(schema), values)
    except (ConfigKeyError, ValidationError) as exc:
        key = re.sub(r"\[\d+\]", "", str(exc.full_key))
        if isinstance(exc, ConfigKeyError):
            owner = exc.object_type if dataclasses.is_dataclass(exc.object_type) else schema
            valid = ", ".join(sorted(f.name for f in dataclasses.fields(owner)))
            raise ConfigError(prefix + key, _at(values, key), f"unknown key; valid keys: {valid}") from None
        raise ConfigError(prefix + key, _at(values, key), str(exc.msg).splitlines()[0]) from None
    for key in sorted(OmegaConf.missing_keys(merged)):
        raise ConfigError(prefix + key, "<missing>", "is required")
    plain = OmegaConf.to_container(merged)
    _check_rules(schema, plain, values, prefix)
    return plain


def _check_rules(schema: type, plain: dict, given: dict, prefix: str) -> None:
    """The rules of ``value(...)``; errors show the value as given (``0``, not ``0.0``)."""
    hints = typing.get_type_hints(schema)
    for f in dataclasses.fields(schema):
        v = plain[f.name]
        shown = given.get(f.name, v) if isinstance(given, dict) else v
        if dataclasses.is_dataclass(hints[f.name]):
            _check_rules(hints[f.name], v, shown, f"{prefix}{f.name}.")
            continue
        rule = f.metadata.get("rule", {})
        if v is None or isinstance(v, dict):
            continue
        items = v if isinstance(v, list) else [v]
        if "length" in rule and len(items) != rule["length"]:
            raise ConfigError(prefix + f.name, shown, f"must be a list of {rule['length']} items")
        why = next((w for w in (_broken(rule, x) for x in items) if w), None)
        if why:
            raise ConfigError(prefix + f.name, shown, ("each item " + why) if isinstance(v, list) else why)
