"""Files in a run directory that somebody else wrote cannot make higbench run code, write
through a link, or rewrite another run (issue 19, items 2, 4 and 6). In-process: the front
door is what is tested, and each case is one ``higbench`` command line."""

from __future__ import annotations

import fcntl
import hashlib
import os
from pathlib import Path

import pytest
import yaml
from cases import TINY_RUN
from rel_helpers import refused

from higbench import cli

TINY = list(TINY_RUN)  # the one tiny run (tests/cases.py)


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def listing(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file() and not p.is_symlink()}


def test_a_stored_config_cannot_name_an_arbitrary_callable(tmp_path, monkeypatch, capsys):
    """A 7-byte run.h5 and a .hydra/config.yaml whose optimizer is ``torch.save``: resume
    would build it (and write the victim file) before checking anything."""
    monkeypatch.chdir(tmp_path)
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    with initialize_config_dir(config_dir=cli.config_dir(), version_base="1.3"):
        config = OmegaConf.to_container(compose("config", overrides=["problem=toy"]), resolve=True)
    victim = tmp_path / "victim"
    config["optimizer"] = {"_target_": "torch.save", "f": str(victim), "name": "hig"}
    evil = tmp_path / "evil"
    (evil / ".hydra").mkdir(parents=True)
    (evil / ".hydra" / "config.yaml").write_text(yaml.safe_dump(config))
    (evil / "run.h5").write_bytes(b"garbage")
    before = listing(tmp_path)
    line = refused([f"resume={evil}"], capsys)
    assert "optimizer._target_=torch.save" in line and f"resume={evil}" in line, line
    assert not victim.exists() and listing(tmp_path) == before


def test_a_stored_problem_target_outside_the_registry_is_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    from higbench.errors import ConfigError
    from higbench.runner.stored import check_stored_targets

    composed = {"problem": {"_target_": "higbench.problems.toy.ToyProblem"}, "optimizer": {"_target_": "x.Y"}}
    with pytest.raises(ConfigError, match="problem._target_=os.system"):
        check_stored_targets({"problem": {"_target_": "os.system"}}, composed, "run")
    check_stored_targets({"optimizer": {"_target_": "x.Y"}}, composed, "run")  # the command line's own: allowed


@pytest.mark.parametrize("link", [".hydra/config.yaml", "higbench.log", ".hydra"])
def test_no_file_higbench_writes_follows_a_link(link, completed, tmp_path, capsys):
    """``E/<link> -> <a completed run file>`` (or a folder of one): refused, the run's bytes unchanged."""
    done = completed("done")
    digest = sha(done)
    out = tmp_path / "E"
    target = done if link != ".hydra" else done.parent
    (out / link).parent.mkdir(parents=True, exist_ok=True)
    (out / link).symlink_to(target)
    before = listing(tmp_path)
    line = refused([*TINY, f"hydra.run.dir={out}"], capsys)
    assert f"hydra.run.dir={out}" in line and "symbolic link" in line, line
    assert sha(done) == digest and listing(tmp_path) == before


def test_a_run_starting_in_a_directory_another_process_holds_writes_nothing(tmp_path, monkeypatch, capsys):
    """Two runs started into one hydra.run.dir at once: the second (exit 2) must not rewrite
    the first's .hydra files (its run file does not exist yet: both passed the checks)."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "same"
    (out / ".hydra").mkdir(parents=True)
    for name in ("config.yaml", "overrides.yaml"):
        (out / ".hydra" / name).write_text(f"the winner's {name}\n")
    before = listing(tmp_path)
    holder = os.open(out, os.O_RDONLY | os.O_DIRECTORY)  # the winner, between its start and its run file
    try:
        fcntl.flock(holder, fcntl.LOCK_EX)
        line = refused([*TINY, "optimizer=sgd", f"hydra.run.dir={out}"], capsys)
    finally:
        os.close(holder)
    assert f"hydra.run.dir={out}" in line and "refusing to overwrite" in line, line
    assert listing(tmp_path) == before


def test_job_files_are_created_exclusively_and_never_through_links(tmp_path):
    from omegaconf import OmegaConf

    hydra_cfg = OmegaConf.create({"overrides": {"task": ["seed=1"]}})
    made = cli.write_job_files(tmp_path, "rerun", hydra_cfg, OmegaConf.create({"seed": 1}))
    assert made[0] == tmp_path / ".hydra" and yaml.safe_load((tmp_path / ".hydra" / "overrides.yaml").read_text()) == ["seed=1"]
    again = cli.write_job_files(tmp_path, "rerun", hydra_cfg, OmegaConf.create({"seed": 2}))  # .hydra is taken
    assert again[0].parent == tmp_path / ".hydra" and again[0].name.startswith("rerun-")
    assert yaml.safe_load((tmp_path / ".hydra" / "config.yaml").read_text()) == {"seed": 1}
    cli.remove_job_files(again)
    assert not again[0].exists() and (tmp_path / ".hydra" / "config.yaml").exists()
