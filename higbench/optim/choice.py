"""An optimizer config node resolved: its class, its constructor arguments, checked once.

``optimizer._target_`` must name a ``torch.optim.Optimizer`` subclass (never any other
callable); the other keys are its constructor's arguments, except the node's own
(``OPTIMIZER_META``: its name, kind, extra, card). ``check_optimizer`` builds it on a dummy
parameter, so that its own constructor checks its arguments (torch's checks for torch.optim
classes, ``JacobianPower``'s for GN/HIG), and returns the ``OptimizerChoice`` a run builds
from (``runner.plan.Plan.optimizer``), as a problem's ``Config`` sits beside its class.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from omegaconf import OmegaConf

from higbench.cards import CARD_KEY
from higbench.errors import ConfigError, MissingExtra
from higbench.schema import locate

# optimizer keys that are not constructor arguments (its card: higbench.cards)
OPTIMIZER_META = ("name", "_target_", "kind", "extra", CARD_KEY)


def optimizer_kwargs(opt_cfg: Any) -> dict:
    """The constructor arguments of an ``optimizer`` node (lists become tuples, e.g. Adam's betas)."""
    kwargs = dict(opt_cfg) if isinstance(opt_cfg, dict) else OmegaConf.to_container(opt_cfg, resolve=True)
    for key in OPTIMIZER_META:
        kwargs.pop(key, None)
    return {k: tuple(v) if isinstance(v, list) else v for k, v in kwargs.items()}


@dataclasses.dataclass(frozen=True)
class OptimizerChoice:
    """An optimizer resolved once: its class, the constructor arguments its config gives, its name."""

    cls: type
    kwargs: Mapping[str, Any]
    name: str


def optimizer_choice(opt: dict) -> OptimizerChoice:
    """The class and arguments of an ``optimizer`` node, without the trial that checks them."""
    return OptimizerChoice(optimizer_class(opt), optimizer_kwargs(opt), str(opt.get("name", opt["_target_"])))


def constructor_args(cls: type) -> tuple[str, ...]:
    """Keyword arguments of an optimizer class (following ``**kwargs`` up to the class that takes them)."""
    import inspect

    names: list[str] = []
    for klass in cls.__mro__:
        params = list(inspect.signature(klass.__init__).parameters.values())[1:]
        if klass is not cls and [p.name for p in params] == ["params", "defaults"]:
            break  # a base optimizer's (torch's, pytorch-optimizer's): the subclass builds its defaults itself
        keywords = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
        names += [p.name for p in params if p.name not in ("params", *names) and p.kind in keywords]
        if not any(p.kind is p.VAR_KEYWORD for p in params) or klass is object:
            break
    return tuple(names)


def takes_any_keyword(cls: type) -> bool:
    """Whether the constructor itself accepts every keyword (``**kwargs``): a misspelt argument
    is then swallowed, never refused (pytorch-optimizer's SOAP and Shampoo)."""
    import inspect

    return any(p.kind is p.VAR_KEYWORD for p in inspect.signature(cls.__init__).parameters.values())


def optimizer_class(opt: Any) -> type:
    """The ``torch.optim.Optimizer`` subclass ``optimizer._target_`` names (never any other callable)."""
    import torch

    if not isinstance(opt, dict):
        raise ConfigError("optimizer", opt, "must be a mapping (pick one with optimizer=<name>)")
    target = opt.get("_target_")
    try:
        cls = locate(target)
    except ImportError as exc:
        if opt.get("extra"):  # a third-party optimizer: its YAML names the optional extra that installs it
            why = f'{target} comes with the {opt["extra"]} extra: pip install -e ".[{opt["extra"]}]"'
            raise MissingExtra("optimizer", opt.get("name", target), why) from None
        raise ConfigError("optimizer._target_", target, f"cannot import this optimizer class ({type(exc).__name__})") from None
    except AttributeError as exc:
        raise ConfigError("optimizer._target_", target, f"cannot import this optimizer class ({type(exc).__name__})") from None
    if not (isinstance(cls, type) and issubclass(cls, torch.optim.Optimizer)):
        raise ConfigError("optimizer._target_", target, "is not a torch.optim.Optimizer subclass")
    return cls


def _check_number_types(cls: type, kwargs: dict) -> None:
    """An argument whose default is a number must be one (``kappa=abc``: one line, not a TypeError)."""
    import inspect

    defaults = {}
    for klass in reversed(cls.__mro__):
        if klass is not object:
            params = inspect.signature(klass.__init__).parameters.values()
            defaults.update({p.name: p.default for p in params if p.default is not inspect.Parameter.empty})
    for key, given in kwargs.items():
        default = defaults.get(key)
        number = isinstance(default, (int, float)) and not isinstance(default, bool)
        if number and (isinstance(given, (str, bool)) or given is None):
            raise ConfigError(f"optimizer.{key}", given, f"must be a number (the default is {default})")


def check_optimizer(opt: Any, device: str = "cpu") -> OptimizerChoice:
    """Build the optimizer on a dummy parameter: its constructor checks its own arguments.

    When it refuses, each argument is left out in turn to find the one it refuses (a pair
    that conflicts, e.g. SGD's nesterov without momentum, names the one listed later).
    """
    import torch

    cls = optimizer_class(opt)
    kwargs = optimizer_kwargs(opt)
    if takes_any_keyword(cls):  # checked against its documented signature: a typo would train with the default
        known = constructor_args(cls)
        for key in kwargs:
            if key not in known:
                raise ConfigError(
                    f"optimizer.{key}", opt[key], f"not an argument of {opt['_target_']}; its arguments: {', '.join(known)}"
                )
    _check_number_types(cls, kwargs)

    trial_step = cls.__module__.startswith("torch.optim")  # ours (GN/HIG/LM) need a problem to step
    trial_device = device if device.startswith("cuda") and torch.cuda.is_available() else "cpu"  # capturable: CUDA only

    def refusal(args: dict) -> Exception | None:
        try:
            param = torch.nn.Parameter(torch.ones(2, device=trial_device))
            optimizer = cls([param], **args)
            if trial_step:  # some arguments fail only when used (L-BFGS history_size=0, Adam capturable)
                optimizer.step(lambda: _dummy_loss(optimizer, param))
        except Exception as exc:  # noqa: BLE001 - ValueError, TypeError, IndexError: whatever the class raises
            return exc
        return None

    exc = refusal(kwargs)
    if exc is None:
        return OptimizerChoice(cls, kwargs, str(opt.get("name", opt["_target_"])))
    target = opt["_target_"]
    culprit = next((k for k in reversed(kwargs) if refusal({a: v for a, v in kwargs.items() if a != k}) is None), None)
    why = " ".join(str(exc).split()) or type(exc).__name__
    if culprit is None:
        raise ConfigError("optimizer", opt.get("name", target), f"{target} refuses its arguments: {why}")
    shown = opt[culprit]
    why = why.split(": ", 1)[1] if why.startswith(f"{culprit}=") and ": " in why else why  # "lr=-1: must be > 0"
    raise ConfigError(f"optimizer.{culprit}", shown, f"refused by {target}: {why}")


def _dummy_loss(optimizer, param):
    """The closure of ``check_optimizer``'s trial step: a quadratic on the dummy parameter."""
    import torch

    with torch.enable_grad():
        optimizer.zero_grad()
        loss = (param**2).sum()
        loss.backward()
    return loss
