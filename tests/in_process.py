"""Helpers for running higbench in the test's own process: configs composed with Hydra's
compose API, ``train`` called directly, a stop signal sent to this process mid-run.

The CLI itself in this process is the ``higbench`` fixture (tests/conftest.py); a process of
its own comes from tests/cli_runner.py, only where the process is the point.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from pathlib import Path


@contextlib.contextmanager
def restored_process_state():
    """Put back, when the block ends, what a run of higbench in this process changes in it.

    A run sets torch's thread count, installs SIGINT/SIGTERM handlers (a single run leaves
    them ignored until exit), records HIGBENCH_PARALLEL_JOBS in the environment, rewrites
    sys.argv and holds a lock on its directory until exit; Hydra adds logging handlers (to
    the streams of the moment) and keeps its global state.
    """
    import logging

    import torch
    from hydra.core.global_hydra import GlobalHydra

    from higbench import cli

    argv = list(sys.argv)
    hydra_was_initialized = GlobalHydra.instance().is_initialized()  # e.g. by a module-scoped compose fixture
    environ = dict(os.environ)
    threads = torch.get_num_threads()
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    loggers = {name: (lg.handlers[:], lg.level, lg.propagate, lg.disabled) for name, lg in _loggers(logging)}
    try:
        yield
    finally:
        sys.argv[:] = argv
        if not hydra_was_initialized:
            GlobalHydra.instance().clear()
        getattr(cli, "release_dirs", lambda: None)()  # as at the process's exit
        torch.set_num_threads(threads)
        for s, handler in handlers.items():
            signal.signal(s, handler)
        if dict(os.environ) != environ:
            os.environ.clear()
            os.environ.update(environ)
        for name, lg in _loggers(logging):
            before, level, propagate, disabled = loggers.get(name, ([], logging.NOTSET, True, False))
            for h in lg.handlers[:]:
                if h not in before:
                    lg.removeHandler(h)
                    h.close()
            lg.setLevel(level)
            lg.propagate, lg.disabled = propagate, disabled


def _loggers(logging):
    """The root logger and every named one."""
    yield "", logging.getLogger()
    for name, lg in list(logging.root.manager.loggerDict.items()):
        if isinstance(lg, logging.Logger):
            yield name, lg


def compose_here(overrides=()):
    """The config ``higbench <overrides>`` would run, composed in-process (no Hydra run dir)."""
    from hydra import compose, initialize_config_dir

    from higbench.config import config_dir

    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        return compose("config", overrides=list(overrides))


def train_here(cfg, path, **kwargs):
    """``train`` in this process, restoring torch's thread count (a run sets its own)."""
    import torch

    from higbench.runner.plan import Plan
    from higbench.runner.train import train

    threads = torch.get_num_threads()
    try:
        return train(Plan.for_run(cfg, path, **kwargs))
    finally:
        torch.set_num_threads(threads)


@contextlib.contextmanager
def signal_when(path: Path, signum: int = signal.SIGINT, timeout: float = 120):
    """Send ``signum`` to this process once ``path`` exists (e.g. a run's first checkpoint),
    as Ctrl-C or ``kill`` would, while the block runs a training in the main thread.

    The run's own handler takes it (it is installed before the run writes anything); the
    block must outlast the wait, e.g. a budget of a minute that the signal cuts short.
    """
    done = threading.Event()
    sent = threading.Event()

    def watch():
        deadline = time.monotonic() + timeout
        while not done.is_set() and time.monotonic() < deadline:
            if Path(path).exists():
                sent.set()
                os.kill(os.getpid(), signum)
                return
            time.sleep(0.01)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        yield sent
    finally:
        done.set()
        watcher.join()


@contextlib.contextmanager
def memory_cap(extra_bytes: int = 1 << 30):
    """While the block runs, this process may map at most ``extra_bytes`` more address space
    (RLIMIT_AS, as a child process with a cap would have): a reader that blows up in memory
    raises MemoryError in the test instead of taking the machine's memory."""
    import resource

    import psutil

    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    cap = psutil.Process().memory_info().vms + extra_bytes
    if hard != resource.RLIM_INFINITY:
        cap = min(cap, hard)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


@contextlib.contextmanager
def seen_from_another_process(writer_file, to: Path, *, flush: bool = True):
    """A run file still open for writing in this process, as a reader in another process meets
    it: its bytes on disk (after a flush, or as they are mid-burst with ``flush=False``), copied
    to ``to`` and locked there as HDF5 locks a file it writes (flock, exclusive) while the block
    runs. After the block the lock is gone: what a writer killed at that moment (SIGKILL) leaves.
    """
    import fcntl
    import shutil

    if flush:
        writer_file.flush()
    Path(to).parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(writer_file.filename, to)
    fd = os.open(to, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        yield Path(to)
    finally:
        os.close(fd)


def launch_in_process(monkeypatch) -> list[list[str]]:
    """Run the command lines ``higbench.jobs.launch`` starts (``python -m higbench.cli -m ...``)
    in this process instead: the same arguments, environment variables and log file; the
    process itself is not what such a test checks. Returns the command lines run."""
    import subprocess

    from higbench import cli, jobs

    launched: list[list[str]] = []
    real_run = subprocess.run  # the module is the one subprocess module: other commands (git) still run

    def run(cmd, stdout=None, stderr=None, env=None, **kwargs):
        if list(cmd[1:3]) != ["-m", "higbench.cli"]:
            return real_run(cmd, stdout=stdout, stderr=stderr, env=env, **kwargs)
        assert not kwargs, kwargs
        launched.append(list(cmd))
        with monkeypatch.context() as m:
            for key, value in (env or {}).items():
                if os.environ.get(key) != value:
                    m.setenv(key, value)
            out = stdout if stdout is not None else sys.stdout
            err = out if stderr == subprocess.STDOUT else (stderr if stderr is not None else sys.stderr)
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                try:
                    cli.main(list(cmd[3:]))
                    code = 0
                except SystemExit as exc:
                    code = exc.code or 0
        return subprocess.CompletedProcess(cmd, code)

    monkeypatch.setattr(jobs, "run_to_end", run)
    return launched
