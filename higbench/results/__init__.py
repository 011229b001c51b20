"""Reading results: one run (``load_run``) or a whole tree of runs (see ``index``)."""

from higbench.runfile.reader import load_logs, load_run, load_updates, load_weights

__all__ = ["load_run", "load_updates", "load_logs", "load_weights"]
