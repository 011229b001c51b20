"""Bad input: a table of bad values, each refused with exit code 2, one line naming key and
value, and nothing written (no run directory, no file, no change to existing files).

The table runs the real entry point (``higbench.cli.main``: Hydra's app and its ``Checks``
callback) in-process for speed; the job itself must never be reached. A few cases run the
whole command line end to end, including the in-job path (validation inside the Hydra job,
which must remove the directory Hydra made).
"""

from __future__ import annotations

import sys

import h5py
import numpy as np
import pytest
import yaml
from omegaconf import OmegaConf
from rel_helpers import REPO, files_under

from higbench import cli
from higbench.config import ConfigError, validate
from higbench.runfile.writer import RunFileWriter

# End to end through the CLI: (argv, key named in the error, value named in the error).
# "{in}" is a folder of input files (run files to start from or resume).
BAD_CLI = [
    # each schema category once, through Hydra's own parsing of the command line
    (["optimizer.lr=-1"], "optimizer.lr", "-1"),
    (["optimizer.lr=abc"], "optimizer.lr", "abc"),
    (["optimizer.lr=nan"], "optimizer.lr", "nan"),
    (["optimizer.tau=-0.001"], "optimizer.tau", "-0.001"),
    (["optimizer.kappa=1.5"], "optimizer.kappa", "1.5"),
    (["optimizer=gn", "optimizer.beta=3"], "optimizer.beta", "3"),
    (["optimizer=adam", "optimizer.betas=[0.9,1.5]"], "optimizer.betas", "[0.9,1.5]"),
    (["optimizer=sgd", "+optimizer.nesterov=true"], "optimizer.nesterov", "true"),
    (["batch_size=0"], "batch_size", "0"),
    (["batch_size=2.5"], "batch_size", "2.5"),
    (["batch_size=2048"], "batch_size", "2048"),
    (["problem=poisson", "optimizer=adam", "batch_size=2048"], "batch_size", "2048"),
    (["budget.seconds=0"], "budget.seconds", "0"),
    (["budget.max_updates=1.5"], "budget.max_updates", "1.5"),
    (["budget.seconds=null", "budget.max_updates=null"], "budget", "null"),
    (["eval_unit=epochs"], "eval_unit", "epochs"),
    (["checkpoint_every=-5"], "checkpoint_every", "-5"),
    (["device=gpu"], "device", "gpu"),
    (["dtype=float16"], "dtype", "float16"),
    (["seed=-1"], "seed", "-1"),
    (["~seed"], "seed", "missing"),
    (["problem.gamma=0"], "problem.gamma", "0"),
    (["problem=oscillator", "problem.hidden=[20,-1]"], "problem.hidden", "[20,-1]"),
    (["problem=dipole", "problem.cnn_layers=7"], "problem.cnn_layers", "7"),
    (["problem.name=heat"], "problem.name", "heat"),
    (["optimizer._target_=torch.optim.Nope"], "optimizer._target_", "torch.optim.Nope"),
    # unknown keys and groups (the message lists the valid ones)
    (["foo=1"], "foo", "1"),
    (["+bar=2"], "bar", "2"),
    (["problem.foo=1"], "problem.foo", "1"),
    (["+problem.foo=1"], "problem.foo", "1"),
    (["budget.minutes=5"], "budget.minutes", "5"),
    (["optimizer=adam", "optimizer.tau=1e-4"], "optimizer.tau", "1e-4"),
    (["optimizer=adam", "+optimizer.kappa=-0.5"], "optimizer.kappa", "-0.5"),
    (["problem=nope"], "problem", "nope"),
    (["optimizer=bfgs"], "optimizer", "bfgs"),  # not a config (lbfgs is one)
    (["optimizer.lr=[1"], "optimizer.lr", "[1"),
    # init_from: missing file, not a run file, other problem, no weights, other network
    (["init_from={in}/missing.h5"], "init_from", "missing.h5"),
    (["init_from={in}/garbage.h5"], "init_from", "garbage.h5"),
    (["problem=oscillator", "init_from={in}/toy7/run.h5"], "init_from", "toy7"),
    (["init_from={in}/noweights/run.h5"], "init_from", "noweights"),
    (["problem.hidden=5", "init_from={in}/toy7/run.h5"], "init_from", "toy7"),
    # memory guard (GN/HIG)
    (["problem=poisson", "optimizer=hig", "batch_size=1024"], "batch_size", "1024"),
    (["memory_limit_mb=0.01"], "batch_size", "256"),
    (["optimizer=gn", "batch_size=1024", "memory_limit_mb=0.05"], "batch_size", "1024"),
    # resume: nothing there, finished, no checkpoint, changed experiment, no run dir
    (["resume={in}/nothing"], "resume", "nothing"),
    (["resume={in}/toy7"], "resume", "toy7"),
    (["resume={in}/nockpt"], "resume", "nockpt"),
    (["resume={in}/resumable", "optimizer.lr=5"], "optimizer.lr", "5"),
    (["resume={in}/resumable", "optimizer=adam"], "optimizer", "adam"),
    (["resume=true"], "resume", "true"),
    # multirun: one bad job refuses the whole sweep before it starts
    (["-m", "optimizer.lr=0.1,-1"], "optimizer.lr", "-1"),
    (["-m", "batch_size=64,4096"], "batch_size", "4096"),
    (["-m", "optimizer=adam,hig", "optimizer.kappa=0.5"], "optimizer.kappa", "0.5"),
    (["-m", "+experiment=toy_lr_grid", "optimizer.eps=-1"], "optimizer.eps", "-1"),
]

# The schema alone (validate() on a composed config): (problem, optimizer, key, bad value).
BAD_VALUES = [
    ("toy", "hig", "optimizer.lr", 0),
    ("toy", "hig", "optimizer.lr", float("inf")),
    ("toy", "sgd", "optimizer.lr", [1, 2]),
    ("toy", "hig", "optimizer.tau", 2.0),
    ("toy", "gn", "optimizer.tau", -1),
    ("toy", "hig", "optimizer.tau", "small"),
    ("toy", "hig", "optimizer.kappa", -2),
    ("toy", "gn", "optimizer.kappa", -1.01),
    ("toy", "hig", "optimizer.beta", "low"),
    ("toy", "hig", "optimizer.beta", float("nan")),
    ("toy", "hig", "optimizer.truncation", "rel"),
    ("toy", "hig", "optimizer.solver", "qr"),
    ("toy", "hig", "optimizer.precision", "float16"),
    ("toy", "adam", "optimizer.betas", [0.9]),
    ("toy", "adam", "optimizer.eps", -1e-8),
    ("toy", "adam", "optimizer.weight_decay", -1),
    ("toy", "sgd", "optimizer.momentum", -0.5),
    ("toy", "rmsprop", "optimizer.alpha", -0.1),
    ("toy", "adagrad", "optimizer.initial_accumulator_value", -1),
    ("toy", "adadelta", "optimizer.rho", 1.5),
    ("toy", "sgd", "optimizer.betas", [0.9, 0.99]),
    ("toy", "hig", "optimizer.momentum", 0.9),
    ("toy", "hig", "batch_size", -5),
    ("toy", "hig", "batch_size", True),
    ("oscillator", "hig", "batch_size", 8192),
    ("dipole", "adam", "batch_size", 4096),
    ("toy", "hig", "budget.seconds", -10),
    ("toy", "hig", "budget.seconds", "soon"),
    ("toy", "hig", "budget.max_updates", 0),
    ("toy", "hig", "eval_every", 0),
    ("toy", "hig", "eval_every", -1),
    ("toy", "hig", "checkpoint_every", 0),
    ("toy", "hig", "device", "tpu:0"),
    ("toy", "hig", "dtype", "double"),
    ("toy", "hig", "seed", 1.5),
    ("toy", "hig", "threads", 0),
    ("toy", "hig", "progress", "maybe"),
    ("toy", "hig", "memory_limit_mb", -1),
    ("toy", "hig", "resume", ""),
    ("toy", "hig", "problem.gamma", -1),
    ("toy", "hig", "problem.hidden", 0),
    ("toy", "hig", "problem.train_size", 0),
    ("toy", "hig", "problem.test_size", -1),
    ("toy", "hig", "problem.data_seed", -3),
    ("toy", "hig", "problem.init", "xavier"),
    ("toy", "hig", "problem.probe_x", float("nan")),
    ("oscillator", "hig", "problem.dt", 0),
    ("oscillator", "hig", "problem.steps", 0),
    ("oscillator", "hig", "problem.control", [1, 2, 3]),
    ("oscillator", "hig", "problem.activation", "gelu"),
    ("oscillator", "hig", "problem.coupling", "x"),
    ("oscillator", "hig", "problem.train_size", 100),
    ("poisson", "hig", "problem.grid", 1),
    ("poisson", "hig", "problem.modes", 0),
    ("poisson", "hig", "problem.epoch_size", 0),
    ("poisson", "hig", "problem.epoch_size", 32),
    ("dipole", "hig", "problem.model", "rnn"),
    ("dipole", "hig", "problem.dt", -0.05),
    ("dipole", "hig", "problem.steps", 0),
    ("dipole", "hig", "problem.cnn_channels", 0),
    ("dipole_cnn", "hig", "problem.hidden", "wide"),
]


def _default_config(overrides=()) -> dict:
    return _default_configs([overrides])[0]


def _default_configs(override_lists) -> list[dict]:
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=cli.config_dir(), version_base="1.3"):
        return [OmegaConf.to_container(compose("config", overrides=list(o)), resolve=True) for o in override_lists]


def _run_file(path, *, problem="toy", hidden=7, status="completed", weights=True, config=None):
    config = config or _default_config([f"problem={problem}"] if problem != "toy" else [f"problem.hidden={hidden}"])
    w = RunFileWriter(
        path,
        yaml.safe_dump(config),
        [],
        env={},
        meta={"problem": config["problem"]["name"], "optimizer": config["optimizer"]["name"]},
    )
    w.append_row("curves", {"step": 0, "epoch": 0, "wall_time": 0.0, "train_loss": 1.0, "test_loss": 1.0})
    w.append_rows("updates", {"step": [1, 2], "loss": [1.0, 0.9]})  # a run that recorded something
    if weights:
        w.write_weights(
            {
                "0.weight": np.zeros((hidden, 1)),
                "0.bias": np.zeros(hidden),
                "2.weight": np.zeros((2, hidden)),
                "2.bias": np.zeros(2),
            },
            0,
        )
    w.close(status, "", 0)
    return path


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("inputs")
    (d / "garbage.h5").write_bytes(b"this is not HDF5" * 10)
    _run_file(d / "toy7" / "run.h5")
    _run_file(d / "noweights" / "run.h5", weights=False)
    _run_file(d / "nockpt" / "run.h5", status="interrupted")
    _run_file(d / "resumable" / "run.h5", status="interrupted")
    (d / "resumable" / "run.h5.ckpt").write_bytes(b"checked later")
    return d


def _snapshot(root):
    return {p: (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*")}


@pytest.mark.parametrize("argv,key,value", BAD_CLI, ids=[" ".join(a) for a, _, _ in BAD_CLI])
def test_bad_input_is_refused_and_nothing_is_written(argv, key, value, inputs, tmp_path, monkeypatch, capsys):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    argv = [a.replace("{in}", str(inputs)) for a in argv]
    run_dir = work / "run"
    sweep_dir = work / "sweep"
    before = _snapshot(inputs)

    def run_file_reached(*args, **kwargs):
        raise AssertionError(f"{argv}: passed the checks and reached the run file")

    # The checks that need the network run in the job, before its run file: none may pass.
    monkeypatch.setattr("higbench.runner.train._open_run_file", run_file_reached)
    with pytest.raises(SystemExit) as exit_info:
        cli.main([*argv, f"hydra.run.dir={run_dir}", f"hydra.sweep.dir={sweep_dir}"])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("higbench: error: "), err
    message = lines[0]
    assert f"{key}=" in message, message
    assert value in message.split(f"{key}=", 1)[1], message
    assert files_under(work) == [], "a refused config wrote something"
    assert _snapshot(inputs) == before, "a refused config touched its input files"


@pytest.fixture(scope="module")
def composed():
    pairs = sorted({(p, o) for p, o, _, _ in BAD_VALUES})
    return dict(zip(pairs, _default_configs([[f"problem={p}", f"optimizer={o}"] for p, o in pairs])))


@pytest.mark.parametrize("problem,optimizer,key,value", BAD_VALUES, ids=[f"{p}/{o} {k}={v}" for p, o, k, v in BAD_VALUES])
def test_bad_value_is_refused_by_the_schema(problem, optimizer, key, value, composed):
    import copy

    from higbench.config import show

    config = copy.deepcopy(composed[(problem, optimizer)])
    node = config
    *parents, last = key.split(".")
    for part in parents:
        node = node[part]
    node[last] = value
    with pytest.raises(ConfigError) as info:
        validate(config)
    named = info.value.key
    # the error names the key (or, for a size conflict, the batch size it conflicts with)
    assert named == key or (named == "batch_size" and key.startswith("problem.")), str(info.value)
    if named == key:
        assert str(info.value).startswith(f"{key}={show(value)}: "), str(info.value)


def test_unknown_keys_list_the_valid_ones(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    for argv, expected in (
        (["problem.gama=0.01"], "gamma"),
        (["optimizer=adam", "optimizer.beta=0.9"], "betas"),
        (["+nose=1"], "seed"),
    ):
        with pytest.raises(SystemExit):
            cli.main(argv)
        err = capsys.readouterr().err
        assert "unknown key" in err and expected in err, err


def test_constructor_argument_missing_from_yaml_says_to_add_it_with_plus(tmp_path, monkeypatch, capsys):
    """torch.optim.Adam takes amsgrad, conf/optimizer/adam.yaml does not list it: the error says `+`."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        cli.main(["optimizer=adam", "optimizer.amsgrad=true"])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip()
    expected = "optimizer.amsgrad=true: not set in conf/optimizer/adam.yaml; add it with +optimizer.amsgrad=true"
    assert err == f"higbench: error: {expected}"
    assert files_under(tmp_path) == []


def test_memory_guard_message_gives_estimate_and_fitting_batch(tmp_path, monkeypatch, capsys):
    from higbench.optim import memory_guard

    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit):
        cli.main(["problem=poisson", "optimizer=hig", "batch_size=1024"])
    err = capsys.readouterr().err
    assert "MB" in err and "largest batch size that fits:" in err, err
    fits = int(err.rsplit("fits:", 1)[1].split()[0])
    assert 1 <= fits < 1024
    # the batch size it proposes fits by its own estimate, one more does not
    avail, _ = memory_guard.available_bytes()
    mode = _default_config(["problem=poisson", "optimizer=hig"])["optimizer"].get("jacobian", "naive")
    assert memory_guard.estimate_bytes(fits, 64, 41408, "float32", "auto", jacobian=mode).total <= avail * 1.2  # memory moves
    assert memory_guard.estimate_bytes(1024, 64, 41408, "float32", "auto", jacobian=mode).total > avail


def test_memory_estimate_grows_as_it_should():
    from higbench.optim.memory_guard import estimate_bytes, largest_batch

    small = estimate_bytes(16, 28, 9484, "float32", "gram").total
    double = estimate_bytes(32, 28, 9484, "float32", "gram").total
    assert double > 2 * small  # Gram matrix: quadratic in the rows
    j = 32 * 28 * 9484
    assert estimate_bytes(32, 28, 9484, "float32", "gram").parts["jacobian"] == 2 * j * 4
    assert estimate_bytes(32, 28, 9484, "float64", "gram").parts["jacobian_cast"] == 0
    limit = estimate_bytes(100, 4, 2956, "float32", "auto").total
    assert largest_batch(limit, 4, 2956, "float32", "auto") == 100


def _validate_all(lists):
    for overrides, config in zip(lists, _default_configs(lists)):
        try:
            validate(config)
        except ConfigError as exc:
            pytest.fail(f"{overrides}: {exc}")


def _conf(group):
    return sorted(p.stem for p in (REPO / "conf" / group).glob("*.yaml"))


def test_shipped_configs_pass(inputs):
    """The schema must not refuse what conf/ ships: each problem, optimizer, experiment."""
    lists = [[f"problem={p}"] for p in _conf("problem")] + [[f"optimizer={o}"] for o in _conf("optimizer")]
    lists += [[f"+experiment={e}"] for e in _conf("experiment") if "optuna" not in e] + [[f"init_from={inputs / 'toy7'}"]]
    _validate_all(lists)


@pytest.mark.optuna
def test_shipped_optuna_experiments_pass():
    """Experiments that select Hydra's Optuna sweeper compose only with the optuna extra."""
    _validate_all([[f"+experiment={e}"] for e in _conf("experiment") if "optuna" in e])


@pytest.mark.slow
def test_every_problem_optimizer_pair_passes():
    """Every shipped pair composes and validates, but SIP on a problem without an inverse
    simulator, which is refused by design (tests/optim/test_sip.py)."""
    from higbench.problems.base import registry

    no_inverse = {name for name, cls in registry().items() if not cls.has_inverse_simulator()}
    composed = _default_configs([[f"problem={p}"] for p in _conf("problem")])
    names = {p: c["problem"]["name"] for p, c in zip(_conf("problem"), composed)}
    _validate_all(
        [[f"problem={p}", f"optimizer={o}"] for p in names for o in _conf("optimizer")
         if not (o == "sip" and names[p] in no_inverse)]
    )  # fmt: skip


def test_optimizer_arguments_are_checked_by_their_constructor():
    """No table of torch signatures: torch's own checks, and the argument they refuse named."""
    from higbench.config import check_optimizer

    base = {"name": "adam", "_target_": "torch.optim.Adam", "lr": 1e-3, "betas": [0.9, 0.999], "eps": 1e-7}
    check_optimizer({**base, "amsgrad": True, "foreach": None})  # any argument torch takes
    for change, message in (
        ({"weight_decay": -1}, "optimizer.weight_decay=-1: refused by torch.optim.Adam: Invalid weight_decay value: -1"),
        ({"betas": [0.9]}, "optimizer.betas=[0.9]: refused by torch.optim.Adam:"),
        ({"kappa": 0.5}, "optimizer.kappa=0.5: refused by torch.optim.Adam: Adam.__init__() got an unexpected keyword"),
    ):
        with pytest.raises(ConfigError) as info:
            check_optimizer({**base, **change})
        assert str(info.value).startswith(message), str(info.value)


def test_config_error_names_key_and_value():
    exc = ConfigError("optimizer.lr", -1.0, "must be a number > 0")
    assert str(exc) == "optimizer.lr=-1.0: must be a number > 0"


# -- end to end, as a user runs it -----------------------------------------------------------


def test_cli_exit_code_and_nothing_written_end_to_end(higbench, tmp_path):
    code, _, err = higbench("optimizer.lr=-1", f"hydra.run.dir={tmp_path}/run", tiny=False)
    assert code == 2, err
    assert err.strip() == "higbench: error: optimizer.lr=-1: refused by higbench.optim.JacobianPower: must be a number > 0"
    code, _, err = higbench("problem.foo=1", tiny=False)  # default run dir: outputs/ in the cwd
    assert code == 2 and "problem.foo=1: unknown key" in err, err
    code, _, err = higbench("-m", "optimizer.lr=0.1,-1", "budget.seconds=1", tiny=False)
    assert code == 2 and "optimizer.lr=-1" in err, err
    assert files_under(tmp_path) == []


def test_in_job_validation_removes_what_hydra_made(higbench, tmp_path):
    """Without the Checks callback (as for jobs an Optuna sweeper samples): the job validates
    and cleans up after itself."""
    code, _, err = higbench("~hydra.callbacks.checks", "optimizer.kappa=7", tiny=False)
    assert code == 2, err
    expected = "higbench: error: optimizer.kappa=7: refused by higbench.optim.JacobianPower: must be a number in [-1, 1]"
    assert err.strip().splitlines()[-1] == expected
    assert files_under(tmp_path) == [], files_under(tmp_path)


def test_existing_run_dir_is_never_overwritten(tmp_path, monkeypatch, capsys):
    run_dir = tmp_path / "run"
    _run_file(run_dir / "run.h5")
    (run_dir / ".hydra").mkdir()
    (run_dir / ".hydra" / "config.yaml").write_text("original: true\n")
    before = _snapshot(run_dir)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(cli, "_run_job", lambda cfg: pytest.fail("reached the job"))
    with pytest.raises(SystemExit) as exit_info:
        cli.main([f"hydra.run.dir={run_dir}"])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and "refusing to overwrite" in err and "hydra.run.dir=" in err, err
    assert _snapshot(run_dir) == before
    with h5py.File(run_dir / "run.h5", "r") as f:
        assert f.attrs["status"] == "completed"


def test_a_run_refused_by_a_held_directory_leaves_it_to_its_holder(tmp_path, monkeypatch, capsys):
    """Two runs into one directory: the loser, refused, removed the still-empty directory (and
    its log) as its own leftover, and the winner's next step failed with FileNotFoundError
    (seen under load in tests/reliability/test_concurrent.py). The holder is played here by a
    lock this test takes on the directory."""
    import fcntl
    import os

    run_dir = tmp_path / "run"
    run_dir.mkdir()
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(cli, "_run_job", lambda *a: pytest.fail("reached the job"))
    holder = os.open(run_dir, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(holder, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(SystemExit) as exit_info:
            cli.main(["problem=toy", "optimizer=adam", f"hydra.run.dir={run_dir}"])
    finally:
        os.close(holder)
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and "another higbench process is running in it" in err, err
    assert run_dir.is_dir(), "the refused run removed the directory another run holds"


def test_remove_hydra_outputs_keeps_foreign_files(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    job = tmp_path / "outputs" / "runs" / "d" / "job"
    (job / ".hydra").mkdir(parents=True)
    for name in ("config.yaml", "hydra.yaml", "overrides.yaml"):
        (job / ".hydra" / name).write_text("x")
    cli.remove_hydra_outputs(job, ".hydra")
    assert files_under(tmp_path) == []  # job, d, runs, outputs: all made for it, all gone
    (job / ".hydra").mkdir(parents=True)
    (job / "notes.txt").write_text("mine")
    cli.remove_hydra_outputs(job, ".hydra")
    assert (job / "notes.txt").exists()
    (job / "run.h5").write_bytes(b"")
    (job / ".hydra").mkdir()
    (job / ".hydra" / "config.yaml").write_text("x")
    cli.remove_hydra_outputs(job, ".hydra")
    assert (job / ".hydra" / "config.yaml").exists()  # a run file there: not ours to clean


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))


def test_a_problem_schema_is_the_config_dataclass_of_its_class(monkeypatch):
    """``problem._target_`` names the class; its ``Config`` dataclass types and bounds the keys."""
    import dataclasses

    from higbench.problems import base
    from higbench.schema import value

    class Heat(base.FixedDataProblem):
        @dataclasses.dataclass
        class Config(base.FixedDataConfig):
            alpha: float = value(gt=0)

        def make_model(self): ...

        def physics(self, inputs, u): ...

        def loss(self, y, targets): ...

    monkeypatch.setattr(sys.modules[__name__], "Heat", Heat, raising=False)
    cfg = _default_config(["optimizer=adam", "batch_size=4"])
    cfg["problem"] = {"_target_": f"{__name__}.Heat", "name": "heat", "alpha": 1.0, "train_size": 8, "test_size": 8}
    cfg["problem"]["data_seed"] = 0
    validate(cfg)
    for change, message in (
        ({"alpha": -1}, "problem.alpha=-1: must be a number > 0"),
        ({"alpha": "hot"}, "problem.alpha=hot: Value 'hot' of type 'str' could not be converted to Float"),
        (
            {"beta": 2},
            "problem.beta=2: unknown key; valid keys: _target_, alpha, data_seed, fresh_test_size, held_out, init, "
            "league_seconds, loss_reduction,",
        ),
        ({"train_size": 2}, "batch_size=4: must not exceed problem.train_size=2"),
        ({"_target_": "nowhere.Heat"}, "problem._target_=nowhere.Heat: cannot import this problem class"),
    ):
        bad = {**cfg, "problem": {**cfg["problem"], **change}}
        with pytest.raises(ConfigError) as info:
            validate(bad)
        assert str(info.value).startswith(message), str(info.value)
