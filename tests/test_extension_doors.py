"""What each extension costs, proved: the files it takes, and a few updates through the front door.

Every door is opened the way a user outside the package opens it: the YAML files in a folder
of their own found through ``hydra.searchpath``, the modules on the import path. Nothing
under higbench/ or conf/ changes. Each run is a toy-sized run in this process
(``higbench.cli.main``, the ``higbench`` fixture).

* a torch.optim optimizer: one YAML file (``conf/optimizer/NAME.yaml``);
* an optimizer class: one module plus one YAML file; it reports each step through
  ``higbench.optim.contract.StepReport``, and what it reports is what the run file records;
* a problem: one module plus one YAML file (``conf/problem/NAME.yaml``); its declared
  ``physics_jacobian`` is what the Jacobian-power optimizers use, its targets are read from it;
* a sink: one module plus one YAML file (``conf/sink/NAME.yaml``).
"""

from __future__ import annotations

import itertools
import textwrap
from pathlib import Path

import pytest

from higbench.results import load_run
from higbench.runfile.reader import load_updates

_names = itertools.count()


class Extension:
    """A folder outside the package: ``conf/`` for Hydra's search path, ``py/`` on the import path."""

    def __init__(self, root: Path, monkeypatch):
        self.root, self.conf, self.py = root, root / "conf", root / "py"
        self.py.mkdir(parents=True)
        monkeypatch.syspath_prepend(str(self.py))
        self.suffix = f"_{next(_names)}"  # module names unique per test: the process imports each once

    def module(self, name: str, source: str) -> str:
        """Writes ``py/NAME<suffix>.py``; returns the module's name."""
        (self.py / f"{name}{self.suffix}.py").write_text(textwrap.dedent(source))
        return f"{name}{self.suffix}"

    def yaml(self, group: str, name: str, text: str) -> None:
        (self.conf / group).mkdir(parents=True, exist_ok=True)
        (self.conf / group / f"{name}.yaml").write_text(textwrap.dedent(text))

    def files(self) -> list[str]:
        return sorted(str(p.relative_to(self.root)) for p in self.root.rglob("*") if p.is_file() and "__pycache__" not in p.parts)

    def searchpath(self) -> str:
        return f"hydra.searchpath=[file://{self.conf}]"


@pytest.fixture
def ext(tmp_path, monkeypatch):
    return Extension(tmp_path / "mine", monkeypatch)


def only_run(tmp_path: Path) -> Path:
    (path,) = sorted((tmp_path / "outputs").rglob("run.h5"))
    return path


def completed(higbench, tmp_path, *args):
    code, _out, err = higbench("threads=1", *args)
    assert code == 0, err
    path = only_run(tmp_path)
    meta, _curves = load_run(path)
    assert meta["status"] == "completed" and meta["steps"] == 3, meta
    return path, meta


def test_a_torch_optimizer_is_one_yaml_file(higbench, ext, tmp_path):
    ext.yaml(
        "optimizer",
        "rmsprop_centered",
        """\
        name: rmsprop_centered
        _target_: torch.optim.RMSprop
        lr: 1.0e-3
        centered: true
        """,
    )
    assert ext.files() == ["conf/optimizer/rmsprop_centered.yaml"]
    path, meta = completed(higbench, tmp_path, ext.searchpath(), "problem=toy", "optimizer=rmsprop_centered")
    assert meta["optimizer"] == "rmsprop_centered"
    updates = load_updates(path)
    assert len(updates) == 3 and (updates["inversion_s"] == 0).all() and (updates["jacobian_s"] > 0).all()  # timed by the closure


# A first-order optimizer of its own that keeps the step contract: it calls the closure as
# torch.optim expects, times its phases and reports a value of its own.
SIGN_DESCENT = """\
    import time

    import torch

    from higbench.optim.contract import StepReport, StepReporter


    class SignDescent(torch.optim.Optimizer, StepReporter):
        def __init__(self, params, lr=1e-3):
            if not lr > 0:
                raise ValueError(f"lr={lr}: must be > 0")
            super().__init__(params, {"lr": lr})

        @torch.no_grad()
        def step(self, closure):
            t0 = time.perf_counter()
            with torch.enable_grad():
                loss = closure()
            t1 = time.perf_counter()
            moved = 0
            for group in self.param_groups:
                for p in group["params"]:
                    if p.grad is not None:
                        p.sub_(group["lr"] * p.grad.sign())
                        moved += int((p.grad != 0).sum())
            timings = {"jacobian_s": t1 - t0, "inversion_s": 0.0, "apply_s": time.perf_counter() - t1}
            self.last_report = StepReport(timings=timings, metrics={"signs_moved": float(moved)})
            return loss
    """


def test_an_optimizer_class_is_one_module_and_one_yaml_file(higbench, ext, tmp_path):
    module = ext.module("sign_descent", SIGN_DESCENT)
    ext.yaml("optimizer", "sign", f"name: sign\n_target_: {module}.SignDescent\nlr: 1.0e-3\n")
    assert ext.files() == ["conf/optimizer/sign.yaml", f"py/{module}.py"]
    path, meta = completed(higbench, tmp_path, ext.searchpath(), "problem=toy", "optimizer=sign")
    updates = load_updates(path)
    n_params = 30  # the toy's 1 -> 7 -> 2 network
    assert list(updates["signs_moved"]) == [n_params] * 3  # its own column, from its report
    assert (updates["jacobian_s"] > 0).all() and (updates["inversion_s"] == 0).all()
    assert "sv_max" not in updates  # it does not use the Jacobian: no spectrum columns

    code, _out, err = higbench("threads=1", ext.searchpath(), "problem=toy", "optimizer=sign", "optimizer.lr=-1")
    assert code == 2 and err.strip().endswith(f"optimizer.lr=-1: refused by {module}.SignDescent: must be > 0"), err


# A problem of its own: the toy's physics y = (u1, gamma u2), its solver Jacobian declared
# (the Jacobian-power optimizers use it instead of autograd), its targets and league budget in its YAML.
SCALE_PROBLEM = """\
    from dataclasses import dataclass

    import torch

    from higbench.problems.base import Batch, FixedDataConfig, FixedDataProblem
    from higbench.problems.networks import mlp
    from higbench.schema import value

    JACOBIAN_CALLS = []


    class Scale(FixedDataProblem):
        name = "scale"

        @dataclass
        class Config(FixedDataConfig):
            gamma: float = value(gt=0)

        def __init__(self, cfg, dtype, device, seed):
            super().__init__(cfg, dtype, device, seed)
            self.sample_datasets()

        def _sample(self, n, gen):
            x = (2 * torch.rand(n, 1, generator=gen, dtype=torch.float64) - 1).to(self.device, self.dtype)
            return Batch(net_inputs=x, inputs=x, targets=torch.cat([torch.sin(3 * x), torch.cos(3 * x)], 1))

        def make_model(self):
            return mlp([1, 6, 2], activation="tanh")

        def scale(self):
            return torch.tensor([1.0, self.cfg.gamma], dtype=self.dtype, device=self.device)

        def physics(self, inputs, u):
            return u * self.scale()

        def physics_jacobian(self, inputs, u):
            JACOBIAN_CALLS.append(u.shape[0])
            return self.physics(inputs, u), torch.diag_embed(self.scale().expand_as(u))

        def loss(self, y, targets):
            return 0.5 * ((y - targets) ** 2).sum(1)
    """


@pytest.mark.parametrize("optimizer", ["hig", "adam"])
def test_a_problem_is_one_module_and_one_yaml_file(higbench, ext, tmp_path, optimizer):
    import importlib

    module = ext.module("scale_problem", SCALE_PROBLEM)
    ext.yaml(
        "problem",
        "scale",
        f"""\
        # @package _global_
        problem:
          _target_: {module}.Scale
          name: scale
          gamma: 0.1
          train_size: 64
          test_size: 16
          data_seed: 0
          targets: [1.0e-1, 1.0e-2]
          league_seconds: 5
        batch_size: 8
        """,
    )
    assert ext.files() == ["conf/problem/scale.yaml", f"py/{module}.py"]
    completed(higbench, tmp_path, ext.searchpath(), "problem=scale", f"optimizer={optimizer}")
    calls = importlib.import_module(module).JACOBIAN_CALLS
    if optimizer == "hig":  # the declared solver Jacobian, once per update (and the warm-up's 2 samples)
        assert calls.count(8) == 3 and set(calls) <= {2, 8}, calls
    else:
        assert calls == []

    from hydra import compose, initialize_config_dir

    from higbench.config import config_dir
    from higbench.problems.base import build_problem

    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        cfg = compose("config", overrides=[ext.searchpath(), "problem=scale"])
    import torch

    problem = build_problem(cfg.problem, dtype=torch.float32, device=torch.device("cpu"), seed=0)
    assert problem.targets == (0.1, 0.01) and problem.league_seconds == 5.0


# A sink of its own: counts what the loop hands it and writes the counts beside the run file at the end.
ROW_COUNTER = """\
    from pathlib import Path

    from higbench.runner.sinks import Sink


    class RowCounter(Sink):
        def __init__(self, run_dir: Path, file_name: str = "counts.txt"):
            self.path = Path(run_dir) / file_name
            self.updates, self.evals, self.logs = 0, 0, set()

        def on_update(self, row):
            self.updates += 1

        def on_eval(self, row):
            self.evals += 1

        def on_log(self, name, value):
            self.logs.add(name)

        def close(self, status, reason="", step=-1):
            self.path.write_text(f"{status} {step} {self.updates} {self.evals} {','.join(sorted(self.logs))}")
    """


def test_a_sink_is_one_module_and_one_yaml_file(higbench, ext, tmp_path):
    module = ext.module("row_counter", ROW_COUNTER)
    ext.yaml("sink", "counts", f"counts:\n  _target_: {module}.RowCounter\n  file_name: rows.txt\n")
    assert ext.files() == ["conf/sink/counts.yaml", f"py/{module}.py"]
    path, _meta = completed(higbench, tmp_path, ext.searchpath(), "problem=toy", "optimizer=hig", "sink=counts")
    status, step, updates, evals, logs = (path.parent / "rows.txt").read_text().split(" ")
    assert (status, step, updates, evals) == ("completed", "3", "3", "4")  # evaluations at steps 0, 1, 2, 3
    assert "sv_quantiles" in logs.split(",")

    from higbench.results.index import config_id, setting_config
    from higbench.runfile.reader import read_head

    config = read_head(path).config
    assert config["sink"] == {"counts": {"_target_": f"{module}.RowCounter", "file_name": "rows.txt"}}
    without = {**config, "sink": None}  # a sink is a view: the same experiment, the same setting
    assert config_id(config) == config_id(without) and setting_config(config) == setting_config(without)


def test_sinks_are_chosen_together_and_tensorboard_true_is_the_shipped_one(higbench, ext, tmp_path):
    pytest.importorskip("tensorboard", reason="the tensorboard extra is not installed (it is in the dev extra)")
    module = ext.module("row_counter", ROW_COUNTER)
    ext.yaml("sink", "counts", f"counts:\n  _target_: {module}.RowCounter\n")
    path, _meta = completed(
        higbench, tmp_path, ext.searchpath(), "problem=toy", "optimizer=adam", "sink=counts", "tensorboard=true"
    )
    assert (path.parent / "counts.txt").read_text().startswith("completed 3 3 4")
    assert len(list((path.parent / "tensorboard").iterdir())) == 1


def test_side_sinks_are_checked_without_building_them(ext):
    from omegaconf import OmegaConf

    from higbench.errors import ConfigError
    from higbench.runner.sinks import check_side_sinks, side_sink_specs

    module = ext.module("row_counter", ROW_COUNTER)
    good = OmegaConf.create({"tensorboard": True, "sink": {"counts": {"_target_": f"{module}.RowCounter"}}})
    assert list(side_sink_specs(good)) == ["counts", "tensorboard"]
    check_side_sinks(side_sink_specs(good))
    assert not list(ext.root.rglob("*.txt"))  # nothing built, nothing written
    with pytest.raises(ConfigError, match=r"^sink\.bad\._target_=os\.path: is not a higbench"):
        check_side_sinks(side_sink_specs(OmegaConf.create({"sink": {"bad": {"_target_": "os.path"}}})))


@pytest.mark.parametrize(
    ("yaml", "key", "why"),
    [
        ("counts:\n  _target_: no_such_module.Sink\n", "sink.counts._target_=no_such_module.Sink", "cannot import it"),
        (
            "counts:\n  _target_: pathlib.Path\n",
            "sink.counts._target_=pathlib.Path",
            "is not a higbench.runner.sinks.Sink subclass",
        ),
        ("counts:\n  file_name: x.txt\n", "sink.counts=", "must be a mapping with a _target_"),
        ("counts:\n  _target_: {module}.RowCounter\n  colour: red\n", "sink.counts=", "refused by"),
    ],
)
def test_a_sink_that_cannot_work_is_refused_before_the_run_file(higbench, ext, tmp_path, yaml, key, why):
    module = ext.module("row_counter", ROW_COUNTER)
    ext.yaml("sink", "counts", yaml.format(module=module))
    code, _out, err = higbench("threads=1", ext.searchpath(), "problem=toy", "optimizer=adam", "sink=counts")
    (line,) = err.strip().splitlines()
    assert code == 2 and line.startswith(f"higbench: error: {key}") and why in line, err
    assert not list(tmp_path.rglob("run.h5"))


def test_the_shipped_sink_without_its_extra_is_refused_before_the_run_file(higbench, tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "torch.utils.tensorboard", None)  # import fails as if not installed
    code, _out, err = higbench("threads=1", "problem=toy", "optimizer=adam", "sink=tensorboard")
    (line,) = err.strip().splitlines()
    assert code == 2 and "needs the tensorboard package" in line, err
    assert not list(tmp_path.rglob("run.h5")) and not list(tmp_path.rglob("tensorboard"))
