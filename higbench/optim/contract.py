"""What an optimizer promises the runner, and what the runner reads back: the step contract.

The runner calls every optimizer the same way, ``optimizer.step(closure)``, with a
``LossClosure`` (``higbench.optim.closure``): a torch.optim closure that also carries the
pieces of the loss (network, physics, per-sample loss, the problem's optional solver
Jacobian and inverse simulator). Afterwards it asks ``report_of(optimizer)``:

* ``None``: a torch.optim optimizer, or a package's (pytorch-optimizer's SOAP and Shampoo,
  ``SplitOptimizer``'s parts). Nothing is asked of it. The runner times the step itself:
  ``jacobian_s`` is the time spent in the closure, ``apply_s`` the rest; a non-finite loss or
  gradient stops the step inside the closure (``NonFiniteStep``) before any parameter moves.
* a ``StepReport``: an optimizer of ours that times its own phases (``StepReporter``). It sets
  a new report in every ``step``, also in one that refuses to move the parameters.

What an optimizer class declares, on the class (``StepReporter``'s attributes):

* ``uses_jacobian``: it builds the stacked per-sample Jacobian J (HIG, Gauss-Newton,
  Levenberg-Marquardt: ``higbench.optim.hig.JacobianPower`` and its subclasses). For such a
  class the runner warms up the solver Jacobian before the clock, sizes the step with the
  memory guard from its parameter group (``solver``, ``tau``, ``truncation``, ``precision``,
  ``krylov_steps``, ``jacobian``, as ``JacobianPower`` holds them), records the spectrum of
  every update (``StepReport.spectrum``) and checks a checkpoint's state as torch.optim's
  layout. ``uses_jacobian(cls_or_optimizer)`` is the one answer to that question.
* ``needs_inverse_simulator``: it calls the problem's inverse simulator
  (``LossClosure.inverse``; SIP). A problem without one is refused before any work.
* ``sets_threads``: it sets torch's thread count inside its step from its ``threads``
  attribute (``"auto"``, N, or None: leave it); under the runner the run's ``threads`` key
  decides instead, so the runner sets the attribute to None (``leave_threads_to_run``).

A new optimizer class is one module plus one YAML file in ``conf/optimizer/``: subclass
``torch.optim.Optimizer`` (and ``StepReporter`` when it times its own phases), take the
closure, return the loss before the update. tests/test_extension_doors.py has a worked one
(``SignDescent``) trained from outside the package; docs/architecture.md lists every door.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

# The phases of one update, as in the paper's tables (keys of ``StepReport.timings``).
PHASES = ("jacobian_s", "inversion_s", "apply_s")


@dataclass(frozen=True)
class StepReport:
    """How one ``step`` went, as the optimizer saw it.

    timings: seconds per phase (``PHASES``: derivatives incl. J or J J^T; the SVD or
        eigen-decomposition and the product back to the parameters; the rest); empty when
        the step was refused.
    finite: False when the optimizer refused the step and left the parameters as they were
        (a non-finite loss, Jacobian or direction, a failed inversion); ``reason`` says why.
        The runner ends the run as ``diverged`` with that reason.
    spectrum: what the inversion saw (``sv_max``, ``sv_min_kept``, ``sv_dropped``,
        ``singular_values``; ``step_error`` on the Krylov route; LM's ``lm_lambda``): per-update
        columns and per-evaluation quantiles in the run file. Empty where there was none.
    metrics: values of the optimizer's own, one column each per update (SIP: ``proxy_loss``).
    """

    timings: Mapping[str, float] = field(default_factory=dict)
    finite: bool = True
    reason: str = ""
    spectrum: Mapping[str, Any] = field(default_factory=dict)
    metrics: Mapping[str, float] = field(default_factory=dict)

    @classmethod
    def refused(cls, reason: str, spectrum: Mapping[str, Any] | None = None) -> StepReport:
        """A step that left the parameters as they were, and why."""
        return cls(timings={}, finite=False, reason=reason, spectrum=dict(spectrum or {}))


class StepReporter:
    """Mixin for an optimizer of ours that reports each step (put it beside ``torch.optim.Optimizer``).

    ``step`` sets ``self.last_report`` to a new ``StepReport`` every time it is called.
    """

    uses_jacobian: ClassVar[bool] = False
    needs_inverse_simulator: ClassVar[bool] = False
    sets_threads: ClassVar[bool] = False
    last_report: StepReport | None = None


def report_of(optimizer: object) -> StepReport | None:
    """The report of the optimizer's last step; None for an optimizer that does not report
    (torch.optim and packages: the runner times it by the closure)."""
    return optimizer.last_report if isinstance(optimizer, StepReporter) else None


def _class(cls_or_optimizer: object) -> type:
    return cls_or_optimizer if isinstance(cls_or_optimizer, type) else type(cls_or_optimizer)


def uses_jacobian(cls_or_optimizer: object) -> bool:
    """Whether an optimizer (class or instance) builds the per-sample Jacobian (HIG, GN, LM)."""
    cls = _class(cls_or_optimizer)
    return issubclass(cls, StepReporter) and cls.uses_jacobian


def leave_threads_to_run(optimizer: object) -> None:
    """An optimizer that sets torch's threads inside its step leaves them to the run's ``threads`` key."""
    if isinstance(optimizer, StepReporter) and optimizer.sets_threads:
        optimizer.threads = None


def needs_inverse_simulator(cls_or_optimizer: object) -> bool:
    """Whether an optimizer (class or instance) needs the problem's inverse simulator (SIP)."""
    cls = _class(cls_or_optimizer)
    return issubclass(cls, StepReporter) and cls.needs_inverse_simulator
