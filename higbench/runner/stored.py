"""A stopped run's stored config: someone else's file, made the task a resumed run trains.

``stored_task`` is the one entry: the stored YAML (a run file's, or Hydra's copy beside a file
that recorded nothing) parsed with the run-file reader's bounds (size, aliases expanded),
refused where it names a callable that no higbench config registers (``check_stored_targets``),
merged with the keys the command line may change on resume (``resume_config``), and, for a
run started again from it, refused where it would open a file the user did not name on this
command line (``check_stored_paths``).
"""

from __future__ import annotations

import contextlib
import copy
from collections.abc import Mapping
from typing import Any

from omegaconf import OmegaConf

from higbench.config import COSMETIC_KEYS, RESUMABLE_KEYS
from higbench.errors import ABSENT, ConfigError, dotted_get, dotted_set, given_value, show

PATH_KEYS = ("init_from",)  # config keys naming a file higbench opens
# The config groups whose files may name a class to build: where a stored config's ``_target_``s
# may come from (problem_optimizer and experiment files set keys of these nodes).
TARGET_GROUPS = ("problem", "optimizer", "sink", "problem_optimizer", "experiment")


def stored_task(stored: str | dict, composed: dict, overrides, resume_value: Any, *, restart: bool) -> dict:
    """The task a resumed run trains: its stored config (``stored``: the YAML, or already a
    dict) with the changes resuming allows. ``composed``: the config Hydra composed for this
    command line; ``overrides``: its task overrides; ``restart``: the run starts again from
    its stored config (it recorded nothing), so a file that config names would be opened.
    ConfigError on ``resume`` (or the key changed) before anything of it is built."""
    if isinstance(stored, str):
        from higbench.runfile.reader import UnreadableRunFile, parse_config

        try:
            stored = parse_config(stored)
        except UnreadableRunFile as exc:
            raise ConfigError("resume", resume_value, f"its stored config is refused: {exc}") from None
    check_stored_targets(stored, composed, resume_value)  # before anything of it is built
    merged = resume_config(stored, composed, list(overrides))
    if restart:
        check_stored_paths(stored, list(overrides), resume_value)
    return merged


def resume_config(stored: dict, composed: dict, overrides: list[str]) -> dict:
    """The stored config of the run, with the command-line changes that resuming allows.

    ``composed``: the config Hydra composed for this invocation; ``overrides``: the task
    overrides given on the command line. A key outside ``RESUMABLE_KEYS`` may be repeated
    with the run's own value (re-running the same command with ``resume=...``) but not
    changed: that would be another experiment.
    """
    from hydra.core.override_parser.overrides_parser import OverridesParser

    # a key that changes no result and that an older run file lacks: conf/config.yaml's value
    merged = {**{k: composed[k] for k in COSMETIC_KEYS if k not in stored and k in composed}, **copy.deepcopy(stored)}
    for override in OverridesParser.create().parse_overrides(list(overrides)):
        key, line = override.key_or_group, override.input_line
        if key.startswith("hydra.") or key == "hydra":
            continue
        new = dotted_get(composed, key)
        if key.split(".")[0] in RESUMABLE_KEYS:
            if new is not ABSENT:
                dotted_set(merged, key, new)
            continue
        old = dotted_get(stored, key)
        if new is ABSENT or old is ABSENT or new != old:
            shown = "<absent>" if old is ABSENT else show(old)
            why = f"cannot change when resuming (the run has {key}={shown}); resumable keys: {', '.join(RESUMABLE_KEYS)}"
            raise ConfigError(key, line.split("=", 1)[-1], why)
    merged["resume"] = None
    return merged


def registered_targets() -> dict[str, set[str]]:
    """Where a config may name a class, and which: ``{key: {target, ...}}`` for every ``_target_``
    that a config file in Hydra's search path (conf/, and ``hydra.searchpath`` given on the
    command line) sets, at the key it sets it (``optimizer._target_``, the nested
    ``optimizer.parts.PART._target_`` of muon.yaml, ``sink.tensorboard._target_``), and
    every registered Problem class at ``problem._target_``."""
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.object_type import ObjectType

    from higbench.config import config_dir
    from higbench.problems.base import registry

    if not GlobalHydra.instance().is_initialized():
        from hydra import initialize_config_dir

        with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
            return registered_targets()
    targets: dict[str, set[str]] = {"problem._target_": {f"{c.__module__}.{c.__qualname__}" for c in registry().values()}}
    for source in GlobalHydra.instance().config_loader().get_sources():
        for group in TARGET_GROUPS:
            if not source.is_group(group):
                continue
            for name in source.list(group, ObjectType.CONFIG):
                with contextlib.suppress(Exception):  # a YAML that does not load names nothing
                    loaded = source.load_config(f"{group}/{name}")
                    package = loaded.header.get("package") or group  # Hydra's default package: the group
                    prefix = "" if package == "_global_" else f"{package.removeprefix('_global_.')}."
                    for key, target in _targets(OmegaConf.to_container(loaded.config), prefix):
                        targets.setdefault(key, set()).add(str(target))
    return targets


def check_stored_targets(stored: dict, composed: Mapping, resume_value) -> None:
    """Refuse a stored config (a run file's, or .hydra/config.yaml) naming a ``_target_`` that
    no config file sets at that key (``registered_targets``) and this command line does not
    name there either: it would be built (called) before anything else is checked."""
    registered, composed = registered_targets(), dict(composed)
    for key, target in _targets(stored):
        if str(target) not in registered.get(key, set()) and str(target) != str(dotted_get(composed, key, "")):
            why = f"its stored config names {key}={target}, which no config file sets there; refusing to build it"
            raise ConfigError("resume", resume_value, why)


def check_stored_paths(stored: dict, overrides: list[str], resume_value) -> None:
    """A stored config (someone else's file) never makes higbench open a file: a path it
    names must be given again on this command line, where the user names what is opened."""
    for key in PATH_KEYS:
        path = stored.get(key)
        if path and given_value(overrides, key) != str(path):
            why = (
                f"its stored config names {key}={path}; a stored config never makes higbench open a file: "
                f"give {key}={path} on the command line to start it again from that file"
            )
            raise ConfigError("resume", resume_value, why)


def _targets(node, prefix: str = ""):
    if isinstance(node, dict):
        for k, v in node.items():
            if k == "_target_":
                yield f"{prefix}{k}", v
            yield from _targets(v, f"{prefix}{k}.")
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _targets(v, f"{prefix}{i}.")
