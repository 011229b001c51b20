"""Reading results: one run (``load_run``) or a whole tree of runs (see ``index``)."""

from higbench.results.index import best_runs, config_id, find_run_files, load_curves, load_runs, one_per_config
from higbench.runfile.reader import load_logs, load_run, load_updates, load_weights

__all__ = [
    "load_run", "load_updates", "load_logs", "load_weights", "load_runs", "load_curves", "best_runs", "find_run_files",
    "config_id", "one_per_config",
]  # fmt: skip
