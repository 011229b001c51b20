"""``higbench.cli.main(argv)`` from code (a notebook, a test) leaves the process as it found it:
sys.argv, the stop-signal handlers and torch's thread count."""

import signal
import sys

import torch

from higbench import cli


def test_a_library_call_leaves_the_process_as_it_was(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv, threads = list(sys.argv), torch.get_num_threads()
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    cli.main(["problem=toy", "optimizer=adam", "budget.max_updates=2", "budget.seconds=null", "progress=false", "threads=1"])
    assert sys.argv == argv
    assert torch.get_num_threads() == threads
    assert {s: signal.getsignal(s) for s in handlers} == handlers  # Ctrl-C works again after a single run
