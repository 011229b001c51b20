"""One optimizer per group of parameters, chosen by a rule: e.g. Muon for the weight matrices, AdamW for the rest.

Muon (``torch.optim.Muon``) orthogonalises 2-D updates only; its documentation pairs it with
AdamW for biases and other non-matrix parameters. ``SplitOptimizer`` makes that pairing a
config rather than code in the runner::

    _target_: higbench.optim.split.SplitOptimizer
    parts:
      hidden_matrices: {_target_: torch.optim.Muon, lr: 1.0e-3}  # 2-D weights but the first and last
      rest: {_target_: torch.optim.AdamW, lr: 1.0e-3}             # all the others

Each key of ``parts`` is a rule (``RULES``); a parameter goes to the first part, in the
order written, whose rule takes it, and every parameter must go somewhere. Each part's
``_target_`` is a ``torch.optim.Optimizer`` class built on its parameters with the part's
other keys. One ``step(closure)`` evaluates the closure once and steps every part on those
gradients, so only optimizers that take a step from the gradients alone (Adam, AdamW, Muon,
SGD, ...; not L-BFGS, whose line search calls the closure) may be parts.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from higbench.schema import locate

# Which parameters a part takes, by its key: a test of one parameter given the model's 2-D
# parameters in order; with the shape of a parameter each rule takes (a part that gets no
# parameter is still built once on such a dummy, so its arguments are checked).
Rule = Callable[[torch.Tensor, list], bool]


def _hidden(p: torch.Tensor, matrices: list) -> bool:
    """A 2-D weight other than the first (the input layer's) and the last (the output layer's):
    Muon's authors keep those two on AdamW (Jordan et al. 2024, "Muon: An optimizer for hidden layers")."""
    return p.ndim == 2 and p is not matrices[0] and p is not matrices[-1]


RULES: dict[str, tuple[Rule, tuple[int, ...]]] = {
    "matrices": (lambda p, m: p.ndim == 2, (2, 2)),  # every Linear weight
    "hidden_matrices": (_hidden, (2, 2)),  # Linear weights of hidden layers (Muon's)
    "vectors": (lambda p, m: p.ndim <= 1, (2,)),  # biases, scalars
    "rest": (lambda p, m: True, (2,)),  # whatever no earlier part took
}


def build_optimizer(key: str, spec: object, params: list) -> torch.optim.Optimizer:
    """The ``torch.optim.Optimizer`` a sub-config ``{_target_: CLASS, ARG: VALUE, ...}`` names, on
    ``params``; a bad spec is a ValueError that names ``key`` (e.g. ``parts.matrices``)."""
    if not isinstance(spec, dict) or "_target_" not in spec:
        raise ValueError(f"{key}={spec!r}: must be a mapping with a _target_")
    target = spec["_target_"]
    try:
        cls = locate(str(target))
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"{key}._target_={target}: cannot import it ({type(exc).__name__})") from None
    if not (isinstance(cls, type) and issubclass(cls, torch.optim.Optimizer)):
        raise ValueError(f"{key}._target_={target}: is not a torch.optim.Optimizer subclass")
    kwargs = {k: tuple(v) if isinstance(v, list) else v for k, v in spec.items() if k != "_target_"}  # betas: a tuple
    try:
        return cls(params, **kwargs)
    except (ValueError, TypeError, RuntimeError) as exc:
        raise ValueError(f"{key}: {target} refuses its arguments: {exc}") from None


class SplitOptimizer(torch.optim.Optimizer):
    """One ``torch.optim`` optimizer per part of the parameters; ``parts``: rule -> {_target_, arguments}."""

    def __init__(self, params, parts: dict):
        params = [params] if isinstance(params, torch.Tensor) else list(params)
        if any(isinstance(p, dict) for p in params):
            raise ValueError("parameter groups are not supported: the parts' rules make the groups")
        params = [p for p in params if p.requires_grad]
        if not isinstance(parts, dict) or not parts:
            raise ValueError(f"parts={parts!r}: must map rules ({', '.join(RULES)}) to optimizers")
        unknown = [k for k in parts if k not in RULES]
        if unknown:
            raise ValueError(f"parts.{unknown[0]}: unknown rule; valid rules: {', '.join(RULES)}")
        self.parts: dict[str, torch.optim.Optimizer] = {}
        left = list(params)
        matrices = [p for p in params if p.ndim == 2]  # in the model's order: input layer first
        for name, spec in parts.items():
            takes, dummy_shape = RULES[name]
            mine, left = [p for p in left if takes(p, matrices)], [p for p in left if not takes(p, matrices)]
            built = build_optimizer(f"parts.{name}", spec, mine or [torch.nn.Parameter(torch.zeros(dummy_shape))])
            if mine:
                self.parts[name] = built
        if left:
            shapes = sorted({tuple(p.shape) for p in left})
            raise ValueError(f"parts: no rule takes the parameters of shapes {shapes}; add a `rest` part")
        super().__init__(params, {})
        # The parts own the groups: one list of the same dicts, so a scheduler or a reader of
        # param_groups sees (and sets) each part's lr.
        self.param_groups = [g for opt in self.parts.values() for g in opt.param_groups]

    @torch.no_grad()
    def step(self, closure=None):
        """Evaluate the closure once (gradients set), then step every part on those gradients."""
        loss = None
        if closure is not None:
            with torch.enable_grad():
                loss = closure()
        for opt in self.parts.values():
            opt.step()
        return loss

    def zero_grad(self, set_to_none: bool = True) -> None:
        for opt in self.parts.values():
            opt.zero_grad(set_to_none)

    def state_dict(self) -> dict:
        return {name: opt.state_dict() for name, opt in self.parts.items()}

    def load_state_dict(self, state_dict: dict) -> None:
        if set(state_dict) != set(self.parts):
            raise ValueError(f"state of parts {sorted(state_dict)}, this optimizer has {sorted(self.parts)}")
        for name, opt in self.parts.items():
            opt.load_state_dict(state_dict[name])
