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

from higbench.errors import ConfigError, dotted_get


def value(
    default: Any = MISSING,
    *,
    ge=None,
    gt=None,
    le=None,
    lt=None,
    choices=None,
    length=None,
    identity: bool = True,
    resumable: bool = False,
    in_job_dir: bool = True,
    sizing: bool = False,
) -> Any:
    """A dataclass field with its rule; without a default the key is required (from conf/).

    What the key means for a run, read back by ``keys_where`` (the one place for each list):

    * ``identity``: it changes the run's result (False: progress bar, threads, ...; two runs
      differing only in such keys are the same experiment, ``results.index.config_id``);
    * ``resumable``: ``resume=`` may change it (budgets, intervals, ...);
    * ``in_job_dir``: it names a sweep job's directory (False: a sweep run again with a new
      budget finds its jobs' directories, Hydra's ``override_dirname.exclude_keys``);
    * ``sizing``: it changes the network or the memory the GN/HIG step needs (the pre-flight
      builds the network once per distinct value of these keys in a sweep).
    """
    rule = {k: v for k, v in dict(ge=ge, gt=gt, le=le, lt=lt, choices=choices, length=length).items() if v is not None}
    meta = {"rule": rule, "identity": identity, "resumable": resumable, "in_job_dir": in_job_dir, "sizing": sizing}
    return dataclasses.field(default=default, metadata=meta)


def keys_where(schema: type, flag: str, wanted: bool = True, *, nested: bool = False) -> tuple[str, ...]:
    """Names of ``schema``'s fields whose ``value(...)`` metadata has ``flag == wanted``.

    nested: descend into dataclass fields and list their keys dotted (``budget.seconds``);
    otherwise a dataclass field counts by its own flag.
    """
    hints = typing.get_type_hints(schema)
    found: list[str] = []
    for f in dataclasses.fields(schema):
        if nested and dataclasses.is_dataclass(hints[f.name]):
            found += [f"{f.name}.{k}" for k in keys_where(hints[f.name], flag, wanted, nested=True)]
        elif f.metadata.get(flag, value().metadata[flag]) == wanted:
            found.append(f.name)
    return tuple(found)


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


def check(schema: type, values: Any, prefix: str = "", *, typed: bool = False) -> Any:
    """``values`` merged into ``schema`` and checked: the plain result (``typed``: an instance of
    ``schema``), or ConfigError."""
    if not isinstance(values, dict):
        raise ConfigError(prefix.rstrip(".") or "config", values, f"must be a mapping of the keys of {schema.__name__}")
    try:
        merged = OmegaConf.merge(OmegaConf.structured(schema), values)
    except (ConfigKeyError, ValidationError) as exc:
        key = re.sub(r"\[\d+\]", "", str(exc.full_key))
        if isinstance(exc, ConfigKeyError):
            owner = exc.object_type if dataclasses.is_dataclass(exc.object_type) else schema
            valid = ", ".join(sorted(f.name for f in dataclasses.fields(owner)))
            raise ConfigError(prefix + key, dotted_get(values, key, None), f"unknown key; valid keys: {valid}") from None
        raise ConfigError(prefix + key, dotted_get(values, key, None), str(exc.msg).splitlines()[0]) from None
    for key in sorted(OmegaConf.missing_keys(merged)):
        raise ConfigError(prefix + key, "<missing>", "is required")
    plain = OmegaConf.to_container(merged)
    _check_rules(schema, plain, values, prefix)
    return OmegaConf.to_object(merged) if typed else plain


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
