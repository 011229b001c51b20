"""higbench opens only its run directory and the files named on its command line (issue 39,
items 1-3): no Hydra flag unpickles a file, a stored config cannot name a file to read, and
no output is written through a link that appears after the checks. In-process, each case
one ``higbench`` command line."""

from __future__ import annotations

import os
import pickle
from pathlib import Path

import pytest
import yaml

from higbench import cli
from rel_helpers import compose_here
from test_front_door_security import TINY, completed, listing, refused, sha  # noqa: F401  (completed: a fixture)


class _Payload:
    """Unpickling this creates the marker file (as a crafted pickle would run a command)."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


@pytest.mark.parametrize("form", ["separate", "joined"])
def test_hydra_experimental_rerun_is_refused_before_the_pickle_is_read(form, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    marker = tmp_path / "payload-ran"
    crafted = tmp_path / "config.pickle"
    crafted.write_bytes(pickle.dumps(_Payload(marker)))
    args = ["--experimental-rerun", str(crafted)] if form == "separate" else [f"--experimental-rerun={crafted}"]
    before = listing(tmp_path)
    line = refused(args, capsys)
    assert "--experimental-rerun=" in line and "unpickle" in line, line
    assert not marker.exists() and listing(tmp_path) == before


def test_no_other_hydra_path_loads_a_pickle():
    """Hydra's only ``pickle.load`` is the rerun flag (its callbacks write pickles, never read them)."""
    import hydra

    root = Path(hydra.__file__).parent
    loaders = [
        str(p.relative_to(root))
        for p in root.rglob("*.py")
        if "pickle.load" in p.read_text() and "target_policy" not in p.name  # the policy lists it to forbid it
    ]
    assert loaders == ["main.py"], loaders
    assert (root / "main.py").read_text().split("pickle.load")[0].rsplit("\ndef ", 1)[-1].startswith("_get_rerun_conf")


def test_a_stored_config_cannot_make_higbench_read_another_file(completed, tmp_path, capsys):
    """A dead run dir (an unreadable 2 KB run.h5) whose .hydra/config.yaml names
    ``init_from=<someone's private run>``: ``resume=`` would start it again and copy the
    private weights in. Refused naming the key; nothing read, nothing written."""
    private = completed("private")
    digest = sha(private)
    from omegaconf import OmegaConf

    config = OmegaConf.to_container(compose_here(["problem=toy", "optimizer=adam", *TINY]), resolve=True)
    config["init_from"] = str(private)
    planted = tmp_path / "planted"
    (planted / ".hydra").mkdir(parents=True)
    (planted / ".hydra" / "config.yaml").write_text(yaml.safe_dump(config))
    (planted / "run.h5").write_bytes(os.urandom(2048))
    before = listing(tmp_path)
    reads = []
    import higbench.runfile.reader as reader

    original = reader.read_head

    def spying(path, *a, **k):
        reads.append(Path(path).resolve())
        return original(path, *a, **k)

    with pytest.MonkeyPatch.context() as m:
        m.setattr(reader, "read_head", spying)
        line = refused([f"resume={planted}"], capsys)
    assert f"init_from={private}" in line and "command line" in line, line
    assert private.resolve() not in reads
    assert sha(private) == digest and listing(tmp_path) == before


def test_the_stored_init_from_named_again_on_the_command_line_is_used(completed, tmp_path, capsys):
    private = completed("mine")
    from omegaconf import OmegaConf

    config = OmegaConf.to_container(compose_here(["problem=toy", "optimizer=adam", *TINY]), resolve=True)
    config["init_from"] = str(private)
    dead = tmp_path / "dead"
    (dead / ".hydra").mkdir(parents=True)
    (dead / ".hydra" / "config.yaml").write_text(yaml.safe_dump(config))
    (dead / "run.h5").write_bytes(os.urandom(2048))
    cli.main([f"resume={dead}", f"init_from={private}"])
    from higbench.runfile.reader import read_head

    assert read_head(dead / "run.h5").status == "completed"
