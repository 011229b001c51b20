"""The paper's figures and tables regenerated from run files, and a reproduction report.

    python -m higbench.figures all --preset quick     # `make figures`
    python -m higbench.figures fig1 --preset smoke --runs-root /tmp/o --out /tmp/f

Layout: ``registry`` (the one list of figures and claims), one module per family
(``toy``, ``oscillator``, ``poisson``, ``dipole``, ``ablation``, ``tables``), ``spec``
(Figure/Sweep/Budget/Preset), ``runs`` (run identity, reuse, Hydra multiruns for missing
runs), ``data`` (what plot functions read and write), ``build`` (the pipeline),
``report`` (REPORT.md). See docs/figures.md.
"""
