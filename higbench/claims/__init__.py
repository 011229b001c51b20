"""The vocabulary the paper's claims are written in (``rules``: ``@claim``, ``Cause``, the
verdict and its gates, the values read from runs, the paper's numbers) and the authors'
reference numbers (``reference``). The claims themselves live beside their figures, one
module per family in ``higbench.paper``; the figures' machinery judges them and writes
REPORT.md (``higbench.figures.report``)."""
