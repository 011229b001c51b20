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
from rel_helpers import compose_here
from test_front_door_security import TINY, listing, refused, sha

from higbench import cli


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


def test_a_log_link_planted_after_the_checks_is_not_written_through(tmp_path, monkeypatch, capsys):
    """``higbench.log -> victim`` put in the run dir once the checks passed (as when .hydra
    appears): the log is opened with O_NOFOLLOW when the job starts; refused, victim unchanged."""
    monkeypatch.chdir(tmp_path)
    from higbench import preflight

    victim = tmp_path / "victim.txt"
    victim.write_text("someone's file\n")
    out = tmp_path / "run"
    original = preflight.check_run

    def then_plant(config):
        plan = original(config)
        out.mkdir()
        (out / "higbench.log").symlink_to(victim)
        return plan

    monkeypatch.setattr(preflight, "check_run", then_plant)
    line = refused([*TINY, "problem=toy", "optimizer=adam", f"hydra.run.dir={out}"], capsys)
    assert "higbench.log is a symbolic link" in line, line
    assert victim.read_text() == "someone's file\n" and not (out / "run.h5").exists()


@pytest.mark.parametrize("planted", ["link", "file", "dangling"])
def test_a_tensorboard_dir_that_is_not_a_directory_is_refused_up_front(planted, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    out = tmp_path / "run"
    out.mkdir()
    target = out / "tensorboard"
    if planted == "link":
        target.symlink_to(elsewhere)
    elif planted == "file":
        target.write_text("x")
    else:
        target.symlink_to(tmp_path / "nowhere")
    line = refused([*TINY, "problem=toy", "optimizer=adam", "tensorboard=true", f"hydra.run.dir={out}"], capsys)
    assert f"hydra.run.dir={out}" in line and "tensorboard" in line, line
    assert list(elsewhere.iterdir()) == [] and not (out / "run.h5").exists()


def test_tensorboard_event_files_swapped_for_a_link_mid_run_are_not_followed(tmp_path):
    from higbench.runner.tensorboard import TensorBoardSink

    victim = tmp_path / "victim.bin"
    victim.write_bytes(b"precious")
    sink = TensorBoardSink(tmp_path)
    sink.on_eval({"step": 0, "test_loss": 1.0})
    sink.flush()
    (event,) = (tmp_path / "tensorboard").iterdir()
    event.rename(tmp_path / "moved-event")
    event.symlink_to(victim)  # in its place
    for step in range(1, 50):
        sink.on_eval({"step": step, "test_loss": 1.0 / step})
    sink.flush()
    sink.close("completed")
    assert victim.read_bytes() == b"precious"
    assert (tmp_path / "moved-event").stat().st_size > 200  # the rows went to the run's own file


def test_resume_refuses_a_run_file_with_a_second_hard_link(tmp_path, monkeypatch, capsys):
    """``cp -al run backup``: resume writes the run file in place, which would change the backup."""
    from rel_helpers import stopped_run

    monkeypatch.chdir(tmp_path)
    run = tmp_path / "run" / "run.h5"
    run.parent.mkdir()
    stopped_run(run, monkeypatch)
    backup = tmp_path / "backup.h5"
    os.link(run, backup)
    digest = sha(backup)
    line = refused([f"resume={run.parent}", "progress=false"], capsys)
    assert "2 hard links" in line, line
    assert sha(backup) == digest


def test_the_writer_refuses_a_run_file_relinked_after_the_checks(tmp_path, monkeypatch):
    from rel_helpers import stopped_run

    from higbench.runfile.writer import RunFileShared, RunFileWriter

    run = tmp_path / "run.h5"
    stopped_run(run, monkeypatch)
    os.link(run, tmp_path / "backup.h5")
    digest = sha(run)
    with pytest.raises(RunFileShared, match="hard links"):
        RunFileWriter.reopen(run, rows={})
    assert sha(tmp_path / "backup.h5") == digest


def test_the_index_does_not_follow_a_run_file_link_out_of_its_tree(completed, tmp_path):
    from higbench.results.index import find_run_files

    outside = completed("outside")
    tree = tmp_path / "tree"
    (tree / "a").mkdir(parents=True)
    (tree / "a" / "run.h5").symlink_to(outside)
    inner = completed("tree/b")
    (tree / "c").mkdir()
    (tree / "c" / "run.h5").symlink_to(inner)  # a link within the tree is read
    assert find_run_files(tree) == [tree / "b" / "run.h5", tree / "c" / "run.h5"]
    assert find_run_files(tree / "a" / "run.h5") == [tree / "a" / "run.h5"]  # a file named by the user is read


@pytest.mark.parametrize("planted", ["symbolic", "hard"])
def test_the_log_opener_refuses_a_link_planted_once_the_job_runs(planted, tmp_path):
    """Hydra's handler opens the log at its first line: by then a link may be there."""
    victim = tmp_path / "victim.txt"
    victim.write_text("someone's file\n")
    log = tmp_path / "higbench.log"
    log.symlink_to(victim) if planted == "symbolic" else os.link(victim, log)
    with pytest.raises(OSError):
        cli._open_log(str(log), None)
    assert victim.read_text() == "someone's file\n"
    fresh = cli._open_log(str(tmp_path / "own.log"), None)
    fresh.write("a line\n")
    fresh.close()
    assert (tmp_path / "own.log").read_text() == "a line\n"


def test_a_continued_run_never_opens_the_file_its_stored_init_from_names(completed, tmp_path, monkeypatch, capsys):
    """A run started from another run's weights, interrupted, then that file is gone (or
    someone's private file now): resume takes the weights from the checkpoint and opens only
    its own directory."""
    from rel_helpers import stopped_run

    source = completed("source")
    run = tmp_path / "run" / "run.h5"
    run.parent.mkdir()
    stopped_run(run, monkeypatch, overrides=[f"init_from={source}"])
    source.unlink()
    source.mkdir()  # where the file was, something no reader could open
    cli.main([f"resume={run.parent}", "progress=false", "threads=1"])
    from higbench.runfile.reader import read_head

    assert read_head(run).status == "completed"


def test_a_log_link_planted_once_the_job_runs_turns_the_log_off_and_the_run_goes_on(tmp_path, capsys):
    """The handler's opener refuses the link (above); the job does not die of it at its first line."""
    victim = tmp_path / "victim.txt"
    victim.write_text("someone's file\n")
    log = tmp_path / "higbench.log"
    log.symlink_to(victim)
    stream = cli._open_log_or_off(str(log), None)
    stream.write("a line\n")
    stream.close()
    assert victim.read_text() == "someone's file\n"
    assert "turned off" in capsys.readouterr().err


def test_a_results_file_that_is_a_link_out_of_the_results_directory_is_not_read(tmp_path):
    """`python -m higbench.figures --report-only --out DIR` put the contents of a file outside DIR,
    reached through a link planted as DIR/fig10.json, into DIR/REPORT.md."""
    from higbench.claims.rules import ResultsFileError, read_results_json

    private = tmp_path / "private.json"
    private.write_text('{"secret": 1}')
    results = tmp_path / "results"
    results.mkdir()
    (results / "fig10.json").symlink_to(private)
    with pytest.raises(ResultsFileError):
        read_results_json(results / "fig10.json")
