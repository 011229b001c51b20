"""Numbers measured with the authors' own TensorFlow code, shipped as data.

Source: the authors' repository (github.com/tum-pbs/half-inverse-gradients; scripts
``Nonlinear_oscillators/submit_GN.py``, ``NLO_HIG.py``, ``simulation.py`` and the dipole
scripts), run unchanged on this project's machine kind (2 CPU cores, TensorFlow's CPU
build) by the higbench developers in November 2026. Settings are the paper's table 2
(oscillator: Adam b=512 lr=3e-4; HIG b=128 lr=1 tau=1e-6). Times are the reference's own
training clock: it includes TensorFlow's graph tracing (about 32 s for Adam and 111 s for
HIG before the first update finishes). Losses are test losses per data point. No code or
text of that repository is copied here.

``higbench.paper.oscillator`` draws higbench's oscillator runs beside these points
(figure ``ref_oscillator``), and the report (``higbench.figures.report``) and the claims
(``higbench.paper``) compare them.
"""

from __future__ import annotations

SOURCE = (
    "authors' TensorFlow code (github.com/tum-pbs/half-inverse-gradients), run on 2 CPU cores by the higbench "
    "developers (November 2026); training clock as the reference counts it, graph tracing included"
)

# Seconds of the reference's training clock spent tracing TensorFlow's graph before its first update.
TRACE_SECONDS = {"adam": 32.0, "hig": 111.0}
# (training seconds, test loss per data point)
OSCILLATOR_CURVES: dict[str, dict] = {
    "adam": {
        "settings": {"optimizer": "adam", "batch_size": 512, "optimizer.lr": 3e-4},
        "points": [(0.0, 0.657), (32.0, 0.593), (60.0, 8.3e-3), (120.0, 2.1e-3), (240.0, 4.2e-4)],
        "note": f"the first ~{TRACE_SECONDS['adam']:.0f} s are graph tracing",
    },
    "hig": {
        "settings": {"optimizer": "hig", "batch_size": 128, "optimizer.lr": 1.0, "optimizer.tau": 1e-6},
        "points": [(0.0, 0.789), (149.0, 0.097), (191.0, 0.015), (229.0, 4.8e-3), (265.0, 2.1e-3)],
        "note": f"the first ~{TRACE_SECONDS['hig']:.0f} s are graph tracing",
    },
}

# Seconds per update (after tracing) and peak memory in GB where recorded.
UPDATE_SECONDS: list[dict] = [
    {"problem": "oscillator", "optimizer": "adam", "batch_size": 512, "update_s": 0.034, "memory_gb": None},
    {"problem": "oscillator", "optimizer": "gn", "batch_size": 128, "update_s": 1.14, "memory_gb": None},
    {"problem": "oscillator", "optimizer": "hig", "batch_size": 128, "update_s": 1.33, "memory_gb": 6.8},
    {"problem": "dipole", "optimizer": "adam", "batch_size": 256, "update_s": 5.3, "memory_gb": None},
    {"problem": "dipole", "optimizer": "hig", "batch_size": 16, "update_s": 14.8, "memory_gb": 9.9},
]
