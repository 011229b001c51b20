"""The paper's update cost, tables 3-5 (GPU, TensorFlow): the one copy of these numbers.

The benchmark (``higbench.bench.step --paper-tables``) prints them beside its measurements
and tables 3-5 as measured here (``higbench.bench.tables``) compare against them. Measured
results of the paper, not defaults: the settings behind them are in conf/.
"""

from __future__ import annotations

# Which paper table holds which problem.
PROBLEM_TABLES = {"oscillator": 3, "poisson": 4, "dipole": 5}

# (problem, optimizer, batch size) -> (memory MB, update duration s, Jacobian duration s).
PAPER_COSTS: dict[tuple[str, str, int], tuple[float, float, float]] = {
    ("oscillator", "adam", 256): (11.1, 0.081, 0.070),
    ("oscillator", "adam", 512): (22.2, 0.081, 0.070),
    ("oscillator", "adam", 1024): (44.5, 0.081, 0.070),
    ("oscillator", "hig", 32): (169, 0.087, 0.070),
    ("oscillator", "hig", 64): (676, 0.097, 0.070),
    ("oscillator", "hig", 128): (2640, 0.146, 0.070),
    ("poisson", "adam", 64): (1.3, 0.011, 0.010),
    ("poisson", "hig", 64): (3560, 13.8, 0.0035),
    ("dipole", "adam", 256): (460, 0.40, 0.39),
    ("dipole", "adam", 512): (947, 0.50, 0.49),
    ("dipole", "adam", 1024): (2007, 1.33, 1.32),
    ("dipole", "hig", 8): (1064, 0.42, 0.40),
    ("dipole", "hig", 16): (5039, 0.60, 0.53),
}


def costs_of_table(table_id: str) -> dict[tuple[str, int], tuple[float, float, float]]:
    """One table's rows, ``"table3"`` -> {(optimizer, batch size): (memory MB, update s, Jacobian s)}."""
    problem = next(p for p, n in PROBLEM_TABLES.items() if f"table{n}" == table_id)
    return {(o, b): cost for (p, o, b), cost in PAPER_COSTS.items() if p == problem}
