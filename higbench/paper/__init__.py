"""The paper, shaped like its figures: one module per family (``toy``, ``oscillator``,
``poisson``, ``dipole``, ``ablation``, ``tables``), each holding that family's settings (the
optimizers and grids its runs sweep), its figures and tables (``FIGURES``: ``Figure``
declarations of ``higbench.figures.spec`` and their panels) and the claims judged on them
(``@claim`` of ``higbench.claims.rules``), side by side. ``UNTESTED`` below: the paper's
statements no claim tests, and why.

A new figure with its claims is one file here: a module that declares ``FIGURES`` is a family,
found by ``higbench.figures.registry`` scanning this package (no list names it; families are
ordered by their first figure in the paper's order). Its drawn results are committed under
docs/results/ (docs/figures.md, "Adding a figure").
"""

from __future__ import annotations

# The paper's statements no row tests, and why (the report lists them under its table).
UNTESTED: list[tuple[str, str]] = [
    (
        "§2: Gauss-Newton's update steps in y-space are invariant under arbitrary rescaling of the parameters θ",
        "a property of the update's mathematics, not of a training run; it is checked on a 2-D quadratic whose second "
        "parameter is rescaled (scripts/scale_invariance.py, docs/scale-invariance.md, tests/test_scale_invariance.py): "
        "GN's step in y does not change with the scale, gradient descent's does",
    ),
    (
        "§2.3: a HIG update's cost grows quadratically with the dimension of y",
        "each problem here has one fixed |y|, and the committed benchmark varies the batch size only; no run or benchmark "
        "varies |y| at a fixed network and batch",
    ),
    (
        "§2.3: memory can be traded against time by parallelising the Jacobian computation only partly",
        "higbench computes the Jacobian in one vectorised pass per route (structured or whole J); it has no partly "
        "parallel route whose memory and time could be set against each other",
    ),
    (
        "Appendix B.4: Adam's small-η plateaus (fig. 8) differ in nature from HIG's start-up plateaus (fig. 9)",
        "a statement on the plateaus' causes (the framework's start-up against the optimizer), not a measurable "
        "quantity; what runs can show is counted elsewhere: dip-1 counts Adam's plateau in updates against HIG's, and "
        "cnn-3 leaves HIG's start-up out of its comparison",
    ),
    (
        "Appendix C: too little truncation (small τ) over-saturates neurons",
        "neuron statistics are logged for the toy problem only; the ablation's oscillator runs (fig. 13) do not log them",
    ),
    (
        "§2.3: overly large batch sizes make the Jacobian ill-conditioned and destabilise HIG's learning",
        "the paper names no batch size it calls overly large, and over the b=32-128 it runs (fig. 2c) it says HIG "
        "improves with b (osc-5); no HIG run here goes beyond b=128, so no run of fig. 2c can show the statement (the "
        "row that tested it read fig. 2c and demanded the opposite ordering to osc-5)",
    ),
    (
        "Table 1: the HIG update as a steepest descent in its combined metric",
        "a property of the update's mathematics, not of a run: no measurement of a run could contradict it",
    ),
    (
        "Appendix C, pure physics optimisation (no network): the oscillator stable over a large range of τ, the dipole "
        "worse or not converging at far smaller τ",
        "no network-free optimisation is run anywhere in higbench yet",
    ),
    (
        "§2.3: a HIG update's run time grows linearly with the number of network parameters",
        "the committed benchmark varies the batch size only (spd-5); no sweep over network sizes is committed",
    ),
    (
        "§2.3: HIG allows larger learning rates (η=1) than the gradient-descent family",
        "needs HIG's own η grid beside figs 5-6's at the same budget; fig2b runs HIG at η=1 only",
    ),
    (
        "Toy, γ=1: Adam fits ŷ(x) accurately",
        "needs the trained networks' predictions over x (the run files' weights), which the committed data do not hold",
    ),
    (
        "§3.3: the dipole's final losses differ less between the optimizers than in the other experiments",
        "the dipole's final losses sit at the float32 evaluation floor (dip-3), so their ratio only bounds, and ratios "
        "across problems run at different budgets and seeds compare the setups rather than the optimizers",
    ),
    (
        "Fig. 13: HIG's curves 'start to converge' over τ",
        "the text gives no measure of converging curves a run could fail; abl-3 tests HIG's stability over τ",
    ),
    (
        "CNN: the lower edge of τ 'in line with figure 9' (τ=1e-6 is the best CNN run here)",
        "the test would be dip-8's on fig11, and its cause needs a precision probe of the CNN (only the MLP dipole's is "
        "committed); not added yet",
    ),
    (
        "Tables 3-5's other entries: HIG's memory per b on a GPU, table 4's memory and Jacobian time, table 5's b=8 against b=16",
        "GPU memory is only measured in the committed GPU benchmark run (spd-2 quotes it); this CPU's resident memory is "
        "not the paper's quantity; the b=8/16 and table 4's Jacobian-time comparisons are not added yet (table 3's "
        "Jacobian time over b is spd-7, table 5's Adam time over b spd-8)",
    ),
]
