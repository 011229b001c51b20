"""What the report judges: the paper's claims (``paper``: rule, evidence and cause of each),
the vocabulary they are written in (``rules``), the authors' reference numbers (``reference``)
and the REPORT.md writer (``report``). Below ``higbench.figures``, which draws the runs the
claims read and calls ``rules.judge`` and ``report.write_report``."""
