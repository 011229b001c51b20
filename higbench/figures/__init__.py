"""The paper's figures and tables regenerated from run files, and a reproduction report.

    python -m higbench.figures all --preset quick     # `make figures`
    python -m higbench.figures fig1 --preset smoke --runs-root /tmp/o --out /tmp/f

Layout: ``spec`` (Figure/Sweep/Budget/presets, paper facts read from conf/), ``plot`` (the
one plotting layer: panels as data), ``claims`` (claims as data: rules, budgets, causes,
verdicts), one module per family declaring its figures and claims (``toy``, ``oscillator``,
``poisson``, ``dipole``, ``ablation``, ``tables``), ``registry`` (collects them), ``runs``
(run identity, reuse, Hydra multiruns for missing runs), ``data`` (what drawing reads and
writes), ``build`` (the pipeline), ``report`` (REPORT.md). See docs/figures.md.
"""
