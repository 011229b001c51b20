"""Every shipped optimizer and every shipped side sink resumes through the command line.

A run is stopped by the runner's own stop path (the flag a SIGINT/SIGTERM handler sets, set
here after a few loop turns: no timed signal) and continued with ``higbench resume=<run dir>``
through the Hydra app, in this process. Before, a run whose stored config nests a
``_target_`` (muon.yaml's ``parts``, any ``sink=NAME``) was refused on resume: the stored
config's check allowed only ``problem._target_`` and ``optimizer._target_``.
"""

from __future__ import annotations

import signal
from pathlib import Path

import pytest
from omegaconf import OmegaConf
from rel_helpers import stop_after

from higbench import cli
from higbench.config import config_dir
from higbench.runfile.reader import load_updates, read_head
from higbench.runner.checkpoint import checkpoint_path

UPDATES = 6
RUN = ["problem=toy", f"budget.max_updates={UPDATES}", "budget.seconds=null", "eval_unit=updates", "eval_every=2"]
RUN += ["progress=false", "threads=1", "batch_size=64"]
OPTIMIZERS = sorted(p.stem for p in (Path(config_dir()) / "optimizer").glob("*.yaml"))
SINKS = sorted(p.stem for p in (Path(config_dir()) / "sink").glob("*.yaml"))
BREAKS = ("muon",)  # resumed on the old code too (in-process), refused through the command line: the fast set


def stopped_and_resumed(tmp_path: Path, monkeypatch, overrides: list[str]) -> Path:
    """Run ``overrides`` into tmp_path/run, stop it after 3 turns, resume it from the command line."""
    monkeypatch.chdir(tmp_path)
    with monkeypatch.context() as m:
        stop_after(m, 3)
        with pytest.raises(SystemExit) as stopped:
            cli.main([*RUN, *overrides, "hydra.run.dir=run"])
    run_file = tmp_path / "run" / "run.h5"
    assert stopped.value.code == 128 + signal.SIGTERM
    assert read_head(run_file).status == "interrupted" and checkpoint_path(run_file).is_file()
    cli.main(["resume=run"])
    return run_file


def assert_whole(run_file: Path) -> None:
    head = read_head(run_file)
    assert head.status in ("completed", "diverged"), (head.status, head.attrs.get("status_reason"))
    assert load_updates(run_file)["step"].tolist() == list(range(1, head.n_updates + 1))  # each update once
    assert head.n_updates == UPDATES or head.status == "diverged"
    assert not checkpoint_path(run_file).exists()


@pytest.mark.parametrize("optimizer", [o if o in BREAKS else pytest.param(o, marks=pytest.mark.slow) for o in OPTIMIZERS])
def test_every_shipped_optimizer_resumes_from_the_command_line(optimizer, tmp_path, monkeypatch):
    assert_whole(stopped_and_resumed(tmp_path, monkeypatch, [f"optimizer={optimizer}"]))


@pytest.mark.parametrize("sink", SINKS)
def test_every_shipped_sink_resumes_from_the_command_line(sink, tmp_path, monkeypatch):
    run_file = stopped_and_resumed(tmp_path, monkeypatch, ["optimizer=adam", f"sink={sink}"])
    assert_whole(run_file)
    assert sink in (read_head(run_file).config_yaml or "")


def test_a_stored_nested_target_is_allowed_only_where_a_config_file_sets_it():
    """Nested ``_target_``s: the one a config file sets at that key, or the command line's own."""
    from higbench.errors import ConfigError
    from higbench.runner.stored import check_stored_targets

    muon = {"optimizer": OmegaConf.to_container(OmegaConf.load(Path(config_dir()) / "optimizer" / "muon.yaml"))}
    part = next(iter(muon["optimizer"]["parts"]))  # the shipped file's own part names
    check_stored_targets(muon, {}, "run")
    check_stored_targets({"sink": {"tensorboard": {"_target_": "higbench.runner.tensorboard.TensorBoardSink"}}}, {}, "run")
    planted = {"optimizer": {"parts": {part: {"_target_": "os.system"}}}}
    with pytest.raises(ConfigError, match=f"optimizer.parts.{part}._target_=os.system"):
        check_stored_targets(planted, {}, "run")
    elsewhere = {"sink": {"x": {"_target_": "higbench.runner.tensorboard.TensorBoardSink"}}}  # shipped, at another key
    with pytest.raises(ConfigError, match="sink.x._target_="):
        check_stored_targets(elsewhere, {}, "run")
    check_stored_targets(planted, planted, "run")  # the command line names it itself
