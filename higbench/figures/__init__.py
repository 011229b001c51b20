"""The paper's figures and tables regenerated from run files, and a reproduction report.

    python -m higbench.figures all --preset quick     # `make figures`
    python -m higbench.figures fig1 --preset smoke --runs-root outputs/smoke --out figures-smoke

Layout: ``spec`` (Figure/Sweep/Budget/presets, paper facts read from conf/), ``plot`` (the
one plotting layer: panels as data), one module per family declaring its figures (``toy``,
``oscillator``, ``poisson``, ``dipole``, ``ablation``, ``tables``), ``registry`` (collects
them), ``runs`` (run identity, reuse, Hydra multiruns for missing runs), ``data`` (what
drawing reads and writes), ``build`` (the pipeline). The claims the report judges on these
figures and REPORT.md's writer are ``higbench.claims``. See docs/figures.md.
"""
