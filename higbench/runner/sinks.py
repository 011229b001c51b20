"""Where a run's rows go: the run file, the progress display, and the side sinks the config names.

The training loop only calls the methods of ``Sink``; each sink decides what to keep.
``on_update`` rows: step, wall_time, loss, the phase times and, for GN/HIG/LM, the spectrum
columns. ``on_eval`` rows: one per evaluation (the curves). ``on_log``: per-evaluation
arrays (neuron statistics, probe outputs, spectrum quantiles).

The run file and the progress display are always there. Side sinks are a config group,
``conf/sink/NAME.yaml``, each file one entry ``NAME: {_target_: CLASS, ARG: VALUE, ...}``;
``sink=NAME`` (or ``sink=[a,b]``) picks them. A new sink is one module with a ``Sink``
subclass plus one such YAML file: the runner builds ``CLASS(run_dir, **args)`` before the
run file opens (``build_side_sinks``). A ``_target_`` that does not import, is no ``Sink``, or
refuses its arguments stops the run there (one line, exit 2); a sink that cannot start
(``OSError``) or fails mid-run is turned off with one line, and the run goes on: the run
file is the record. ``tensorboard=true`` is the shorthand of ``sink=tensorboard``
(``conf/sink/tensorboard.yaml``, ``higbench.runner.tensorboard``).
"""

from __future__ import annotations

import contextlib
import math
import sys
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from higbench.config import config_dir
from higbench.errors import ConfigError, show
from higbench.runfile.writer import RunFileFault, RunFileWriter
from higbench.runner.progress import Progress
from higbench.schema import locate


class Sink:
    """The interface: every method may be a no-op. A side sink is built as ``Sink(run_dir, **args)``."""

    def on_update(self, row: dict[str, float]) -> None: ...

    def on_eval(self, row: dict[str, float]) -> None: ...

    def on_log(self, name: str, value) -> None: ...

    def flush(self) -> None:
        """Make everything received so far durable (before a checkpoint, at evaluations)."""

    def close(self, status: str, reason: str = "", step: int = -1) -> None: ...


class RunFileSink(Sink):
    """The HDF5 run file: per-update rows are buffered and written at each flush."""

    def __init__(self, writer: RunFileWriter):
        self.writer = writer
        self.pending: dict[str, list[float]] = {}

    def on_update(self, row: dict[str, float]) -> None:
        for k, v in row.items():
            self.pending.setdefault(k, []).append(v)

    def on_eval(self, row: dict[str, float]) -> None:
        self.writer.append_row("curves", row)

    def on_log(self, name: str, value) -> None:
        self.writer.append_row("logs", {name: value})

    def write_pending(self) -> None:
        rows, self.pending = self.pending, {}  # cleared first: a stop mid-write never writes them twice
        self.writer.append_rows("updates", rows)

    def flush(self) -> None:
        self.write_pending()
        self.writer.flush()

    def close(self, status: str, reason: str = "", step: int = -1) -> None:
        self.writer.close(status, reason, step)

    def close_failed(self, exc: BaseException, step: int, write_pending: bool = True) -> None:
        """Close as ``failed``, whatever else goes wrong on the way.

        Pending rows are written if the file can still take them (not after a file-system
        fault: the file then keeps what its last flush holds).
        """
        if write_pending and not isinstance(exc, RunFileFault):
            try:
                self.write_pending()
            except Exception:  # noqa: BLE001 - the original error is the one to report
                pass
        try:
            self.writer.close("failed", f"{type(exc).__name__}: {exc}", step)
        except Exception:  # noqa: BLE001
            pass


class ProgressSink(Sink):
    """The bar (terminal) or lines (pipe) of ``Progress``."""

    def __init__(self, progress: Progress):
        self.progress = progress

    def on_update(self, row: dict[str, float]) -> None:
        self.progress.tick(int(row["step"]), row["wall_time"])

    def on_eval(self, row: dict[str, float]) -> None:
        self.progress.update(int(row["step"]), row["wall_time"], row["train_loss"], row["test_loss"])

    def close(self, status: str, reason: str = "", step: int = -1) -> None:
        self.progress.close()


class Sinks(Sink):
    """Several sinks in order; the run file first, so it holds a row before any display shows it.

    ``sinks``: the run's own (the run file first, the display last): the run file is the
    record, and their faults stop the run. ``side``: the side sinks the config names, placed
    after the run file; one that fails is turned off with one line on stderr, and the run
    goes on without it. Which is which is decided here, by the caller, never by a sink's
    class: a side sink of any class (even ``RunFileSink``, named by a config) is a side sink.
    """

    def __init__(self, *sinks: Sink, side: tuple[Sink, ...] | list[Sink] = ()):
        self.sinks = [*sinks[:1], *side, *sinks[1:]]
        self.side = list(side)

    def _each(self, method: str, *args) -> None:
        for s in list(self.sinks):
            if not any(s is side for side in self.side):
                getattr(s, method)(*args)
                continue
            try:
                getattr(s, method)(*args)
            except Exception as exc:  # noqa: BLE001 - a view of the run, never worth the run itself
                self.turn_off(s, exc)

    def turn_off(self, sink: Sink, exc: BaseException) -> None:
        if sink in self.sinks:
            self.sinks.remove(sink)
        _turned_off(getattr(sink, "name", type(sink).__name__), exc)
        with contextlib.suppress(Exception):
            sink.close("failed", " ".join(f"{type(exc).__name__}: {exc}".split())[:300])

    def on_update(self, row):
        self._each("on_update", row)

    def on_eval(self, row):
        self._each("on_eval", row)

    def on_log(self, name, value):
        self._each("on_log", name, value)

    def flush(self):
        self._each("flush")

    def close(self, status, reason="", step=-1):
        self._each("close", status, reason, step)


def _turned_off(name: str, exc: BaseException) -> None:
    why = " ".join(f"{type(exc).__name__}: {exc}".split())[:300]
    print(f"higbench: {name} turned off ({why}); the run goes on, its run file is the record", file=sys.stderr, flush=True)


# -- side sinks: the `sink` config group -------------------------------------------------------

SINK_GROUP = "sink"  # conf/sink/NAME.yaml and the top-level key its entries land in


def side_sink_specs(cfg) -> dict[str, dict]:
    """NAME -> {_target_, arguments} of the side sinks a run config names: the ``sink`` group's
    entries, and ``conf/sink/tensorboard.yaml``'s where ``tensorboard=true`` (its shorthand)."""
    chosen = cfg.get(SINK_GROUP)
    specs = dict(OmegaConf.to_container(chosen, resolve=True) if OmegaConf.is_config(chosen) else chosen or {})
    if cfg.get("tensorboard") and "tensorboard" not in specs:
        shipped = OmegaConf.load(Path(config_dir()) / SINK_GROUP / "tensorboard.yaml")
        specs["tensorboard"] = OmegaConf.to_container(shipped.tensorboard, resolve=True)
    return specs


def side_sink_class(name: str, spec: object) -> type[Sink]:
    """The ``Sink`` subclass a spec's ``_target_`` names; ConfigError naming ``sink.NAME`` otherwise."""
    key = f"{SINK_GROUP}.{name}"
    if not isinstance(spec, dict) or "_target_" not in spec:
        raise ConfigError(key, show(spec), "must be a mapping with a _target_ (a file in conf/sink/)")
    target = spec["_target_"]
    try:
        cls = locate(str(target))
    except (ImportError, AttributeError) as exc:
        raise ConfigError(f"{key}._target_", target, f"cannot import it ({type(exc).__name__}: {exc})") from None
    if not (isinstance(cls, type) and issubclass(cls, Sink)):
        raise ConfigError(f"{key}._target_", target, "is not a higbench.runner.sinks.Sink subclass")
    return cls


def check_side_sinks(specs: dict[str, dict]) -> None:
    """ConfigError unless every side sink of ``specs`` (``side_sink_specs``) imports as a ``Sink``
    (nothing is built: a check for before any work, e.g. of every job of a sweep)."""
    for name, spec in specs.items():
        side_sink_class(name, spec)


def build_side_sinks(specs: dict[str, dict], run_dir: Path) -> list[Sink]:
    """Each spec's sink on ``run_dir``, in order; ConfigError (none left open) for a spec that
    cannot work, one line and no sink for one that cannot start here (``OSError``; TensorBoard's
    writer whose internals moved: ``AttributeError``)."""
    classes = {name: side_sink_class(name, spec) for name, spec in specs.items()}
    built: list[Sink] = []
    for name, cls in classes.items():
        args = {k: v for k, v in specs[name].items() if k != "_target_"}
        try:
            built.append(cls(Path(run_dir), **args))
        except (OSError, AttributeError) as exc:  # its directory became a file or a link after the checks, ...
            _turned_off(name, exc)
        except Exception as exc:
            for sink in built:
                with contextlib.suppress(Exception):
                    sink.close("failed", "another sink refused its config")
            if isinstance(exc, ConfigError):
                raise
            if isinstance(exc, (TypeError, ValueError)):
                raise ConfigError(f"{SINK_GROUP}.{name}", show(args), f"refused by {specs[name]['_target_']}: {exc}") from None
            raise
    return built


SPECTRUM_QUANTILES = np.linspace(0.0, 1.0, 11)


SPECTRUM_COLUMNS = ("sv_max", "sv_min_kept", "sv_dropped", "step_error")


def spectrum_columns(spectrum: dict) -> dict[str, float]:
    """Per-update columns of a GN/HIG/LM spectrum (NaN when the update recorded none).

    ``step_error``: the estimated relative error of the step on the approximate (krylov)
    route; NaN on the exact routes.
    """
    return {k: float(spectrum.get(k, math.nan)) for k in SPECTRUM_COLUMNS}


def spectrum_quantiles(spectrum: dict) -> np.ndarray:
    """Quantiles 0, 0.1, .., 1 of all singular values of an update (NaN when none)."""
    s = spectrum.get("singular_values")
    if s is None or len(s) == 0:
        return np.full(len(SPECTRUM_QUANTILES), math.nan)
    return np.quantile(np.asarray(s, dtype=np.float64), SPECTRUM_QUANTILES)
