"""The cards: what a shipped optimizer or problem says about itself, read from its own YAML.

An optimizer's YAML in conf/optimizer/ is its whole card. Besides its constructor arguments
it holds, under ``card:`` (a key no constructor sees: ``higbench.optim.choice.OPTIMIZER_META``, and
no part of a run's identity: ``without_card``), how higbench shows and runs it::

    card:
      display: NAdam            # legends, table columns, claim texts (default: the file's name)
      color: tab:olive          # matplotlib colour of its lines (default: matplotlib's cycle)
      league: true              # the league runs it (needs conf/search/<name>.yaml)
      help: torch.optim.NAdam   # its line in `higbench --help`

The display table (``higbench.display``), the league's optimizer list (``league_optimizers``)
and the optimizer block of ``--help`` (``optimizer_help``) are read from here; shipping a
torch.optim optimizer is one file. A problem is its module plus its YAML in conf/problem/,
whose ``problem.card.help`` is its line in ``--help`` (``problem_help``; like the optimizer's,
no key of the problem's schema and no part of a run's identity): ``problem_configs`` lists the YAMLs, and
``problem_targets`` the classes they name, which ``higbench.problems.base.registry`` imports.

The lowest layer: it reads YAML files and imports nothing of higbench.
"""

from __future__ import annotations

from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any, NamedTuple

import yaml

CARD_KEY = "card"  # the optimizer node's key that holds its card


def conf_dir() -> Path:
    """conf/ of a checkout (or editable install), else the copy shipped in the wheel."""
    checkout = Path(__file__).resolve().parent.parent / "conf"
    if (checkout / "config.yaml").is_file():
        return checkout
    return Path(str(resources.files("higbench") / "conf"))


class OptimizerCard(NamedTuple):
    """An optimizer's card: ``optimizer=name`` and how it is shown and run."""

    name: str  # optimizer=NAME: the YAML file's name
    display: str  # display name (legends, table columns, claim texts)
    color: str | None  # matplotlib colour of its lines (None: matplotlib's colour cycle)
    league: bool  # whether the league runs it
    help: str  # its line in `higbench --help`


def _load(path: Path) -> dict:
    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    return yaml.load(path.read_text(), Loader=loader) or {}


def _card(path: Path) -> OptimizerCard:
    node = _load(path)
    card = node.get(CARD_KEY) or {}
    unknown = set(card) - set(OptimizerCard._fields[1:])
    if unknown:  # a misspelt key would silently fall back to its default
        raise ValueError(f"{path}: unknown card keys {sorted(unknown)}; a card has {', '.join(OptimizerCard._fields[1:])}")
    return OptimizerCard(
        name=path.stem,
        display=str(card.get("display") or path.stem),
        color=card.get("color"),
        league=bool(card.get("league", False)),
        help=str(card.get("help") or node.get("_target_", "")),
    )


@cache
def _optimizer_cards(conf: Path) -> dict[str, OptimizerCard]:
    return {p.stem: _card(p) for p in sorted((conf / "optimizer").glob("*.yaml"))}


def optimizer_cards() -> dict[str, OptimizerCard]:
    """Every shipped optimizer's card, by name (the YAMLs of conf/optimizer/)."""
    return dict(_optimizer_cards(conf_dir()))


def league_optimizers() -> tuple[str, ...]:
    """The optimizers the league runs: those whose card says ``league: true``."""
    return tuple(name for name, card in optimizer_cards().items() if card.league)


def _help_lines(helps: dict[str, str], indent: int, width: int) -> str:
    pad, lines = " " * indent, []
    for name, text in helps.items():
        head, *rest = text.splitlines() or [""]
        lines.append(f"{pad}{name:<{width}}{head}".rstrip())
        lines += [f"{pad}{'':<{width}}{more}" for more in rest]
    return "\n".join(lines)


def optimizer_help() -> str:
    """The optimizer block of ``higbench --help``: one line per card, ``NAME  HELP``."""
    return _help_lines({name: card.help for name, card in optimizer_cards().items()}, indent=2, width=11)


def problem_help() -> str:
    """The problem block of ``higbench --help``: one line per problem config (its ``problem.card.help``)."""
    helps = {name: str((node.get(CARD_KEY) or {}).get("help", "")) for name, node in _problem_nodes(conf_dir()).items()}
    return _help_lines(helps, indent=2, width=13)


def without_card(config: dict) -> dict:
    """A run's config without its optimizer's and its problem's cards (how they are shown
    changes no result; runs recorded before the cards had none)."""
    parts = {key: node for key in ("optimizer", "problem") if isinstance(node := config.get(key), dict) and CARD_KEY in node}
    return {**config, **{key: {k: v for k, v in node.items() if k != CARD_KEY} for key, node in parts.items()}}


# -- problems --------------------------------------------------------------------------------


@cache
def _problem_nodes(conf: Path) -> dict[str, dict[str, Any]]:
    return {p.stem: (_load(p).get("problem") or {}) for p in sorted((conf / "problem").glob("*.yaml"))}


def problem_configs() -> list[str]:
    """The shipped problem configs (``problem=NAME``): the YAMLs of conf/problem/."""
    return list(_problem_nodes(conf_dir()))


def problem_targets() -> dict[str, str]:
    """The problem classes the shipped problem configs name: ``problem._target_`` -> ``problem.name``."""
    nodes = _problem_nodes(conf_dir()).values()
    return {node["_target_"]: str(node.get("name", "")) for node in nodes if isinstance(node.get("_target_"), str)}
