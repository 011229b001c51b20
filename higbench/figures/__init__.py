"""The machinery that turns the paper's figures into runs, pictures, judged claims and a
reproduction report. It knows no figure: the figures, their settings and their claims are
the family modules of ``higbench.paper``, which ``registry`` finds by scanning.

    python -m higbench.figures all --preset quick     # `make figures`
    python -m higbench.figures fig1 --preset smoke --runs-root outputs/smoke --out figures-smoke

Layout: ``spec`` (Figure/Sweep/Budget/presets, paper facts read from conf/), ``plot`` (the
one plotting layer: panels as data), ``data`` (what drawing reads and writes), ``registry``
(the families found in ``higbench.paper``), ``build`` (the pipeline: the runs each figure
needs, the missing ones run through ``higbench.jobs``, drawing, judging), ``report``
(REPORT.md), ``committed`` (a claim measured again, a figure redrawn, from the committed
data). See docs/figures.md.
"""
