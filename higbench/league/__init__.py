"""The league as a command (``higbench-league``): tune every optimizer the same way on a problem,
confirm on fresh seeds and held-out variants, export the runs' tables and score them.

``driver``: the protocol's phases (tuning, confirmation, manifest, report); ``tables``: the
exported per-run and per-evaluation tables a root carries to another machine (the scorer,
``higbench.results.league``, reads them as it reads the run files)."""
