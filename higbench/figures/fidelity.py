"""Per claim: the budget it needs to show, the seeds a comparison needs, and the root cause
of a "not"/"partly" verdict, with the evidence (short targeted runs on the 2-core machine
this project was built on, or the authors' own code run there: ``reference.py``).

Applied to the registry's claims by ``registry.claims()``. A check may still return its
own cause (a 4th element) when the evidence is in the runs themselves.

Categories (``registry.CAUSES``): budget, deviation, unspecified, disagreement, bug, seeds.
"""

from __future__ import annotations

PAPER = 1800.0  # claims on final levels after the paper's hour: half of it at least


# Budgets sized by updates rather than seconds. A claim about the level the paper reached
# after its hour is a claim about what that many updates achieve; higbench's cost per update
# on this CPU differs from the paper's GPU (and differently for each optimizer), so such a
# claim needs the paper's update count at higbench's per-update time, not 3600 s:
#
#     seconds here = 3600 / (paper's s per update) * (higbench's s per update here)
#
# Paper, tables 3-5 (GPU): oscillator HIG b=128 0.146 s, Adam b=512 0.081 s; Poisson HIG
# b=64 13.8 s; dipole HIG b=16 0.60 s, Adam b=256 0.40 s. GN's update is the same
# computation as HIG's (another exponent), so GN is given HIG's count. higbench, one core
# each (as the figures run them: threads=1, two jobs on two cores; docs/benchmarks.md,
# sitting A and the 300 s run on an idle machine): oscillator HIG b=128 26-35 ms (30 ms
# taken), Adam b=512 3.3-4.5 ms (4.5 ms taken); dipole HIG b=16 43.6 ms; Poisson HIG b=64
# 11.4 s. Under other load the per-update times grow (oscillator HIG b=128 39 ms at load
# 4-7), so a budget sized this way is a lower bound.
def paper_hour_here(paper_update_s: float, here_update_s: float) -> float:
    """Training seconds in which higbench makes the paper's hour of updates (rounded up to 10 s)."""
    return float(-(-3600.0 / paper_update_s * here_update_s // 10) * 10)


OSC_HIG_HOUR = paper_hour_here(0.146, 0.030)  # 24,658 updates: 740 s
OSC_ADAM_HOUR = paper_hour_here(0.081, 0.0045)  # 44,444 updates: 200 s
DIPOLE_HIG_HOUR = paper_hour_here(0.60, 0.0436)  # 6,000 updates: 270 s
POISSON_HIG_HOUR = paper_hour_here(13.8, 11.4)  # 261 updates at b=64: 2,980 s

FIDELITY: dict[str, dict] = {
    "toy-1": {
        "min_seconds": 20,
        "cause": (
            "disagreement",
            "Adam at the paper's eta=0.3 (appendix B.1, both gamma) reaches a noise floor within 5 s and stays there: "
            "90 s probes (3 seeds, load 3.6-6.4 on 2 cores) give test losses jumping between 3e-3 and 5e-2 from 5 s "
            "to 90 s (17-23k updates), 1.5/1.6/2.3 decades at the end, no trend from 30 s to 90 s; a longer budget does "
            "not help. A smaller eta does reach the paper's ~3 decades: at 30 s eta=0.03 2.8 decades (1.0e-3), eta=0.01 "
            "2.8 (1.1e-3), both still falling (eta=0.1 sticks at 0.46, seed 0). GN and HIG pass at the paper's settings",
        ),
    },
    "toy-2": {
        "min_seconds": 30,
        "min_seeds": 3,
        "cause": (
            "disagreement",
            "90 s probes at the spec's settings (seed 0, load 5-7): Adam (eta=0.3) passes 0.2 at 5 s and goes on to "
            "5.2e-2 (10 s), 8.7e-3 (20 s), then a noisy plateau at 4-7e-3 from 40 s to 90 s; GN reaches 5.7e-2 at "
            "20 s and stays exactly there to 90 s. Both stall, but 40x (Adam) and 3-4x (GN) below the paper's ~0.2. "
            "The paper's picture appears with a smaller Adam learning rate: at 30 s the re-tuned Adam runs sit at "
            "0.26-0.27 (eta=0.003) and 0.10-0.23 (eta=0.03), 3 seeds each",
        ),
    },
    "toy-3": {
        "min_seconds": 20,
        "min_seeds": 3,
        "cause": (
            "budget",
            "how far HIG gets ahead within 30 s depends on its updates per second, and HIG is the one still falling: "
            "at 30 s on an idle machine (quick preset) HIG 7.9e-4 vs Adam 4.1e-3 (5.2x); re-measured at load 3.4-5.8 "
            "(3 seeds, 30 s): HIG 1.5/3.1/4.4e-3 after 3,345-4,798 updates vs Adam (eta=0.3) 2.9/3.6/3.8e-3 and GN "
            "9.2e-3-5.9e-2 -- HIG lowest by median (3.1e-3 vs 3.6e-3) but by less than 2x. HIG keeps falling (seed 0: "
            "3.8e-3 at 20 s, 1.6e-3 at 30 s; seed 1 run for 60 s: 2.3e-3 at 30 s, 8.5e-4 at 60 s, 7,475 updates) "
            "while Adam sits on its noise floor (4.3e-3 at 20 s, 4.0e-3 at 30 s): the standard preset's 60 s "
            "leave HIG ~4x ahead even under load",
        ),
    },
    "toy-4": {"min_seconds": 20, "min_seeds": 3},
    "osc-1": {
        "min_seconds": OSC_ADAM_HOUR,
        "cause": (
            "budget",
            "Adam's ~1e-4 is its level after the paper's hour, 44,400 updates at 0.081 s (b=512); higbench makes them "
            "in ~200 s (4.5 ms per update on one idle core), while the authors' TensorFlow code on this CPU kind "
            "(0.034 s per update) reaches only 4.2e-4 at 240 s (reference.py)",
        ),
    },
    "osc-2": {
        "min_seconds": OSC_HIG_HOUR,
        "cause": (
            "budget",
            "GN's 1e-6 is its level after the paper's hour: ~24,700 updates (0.146 s per b=128 update in the paper), "
            "~740 s here. Within 120 s (load 4-7, 2 cores) GN's best stable seed (7) falls to 8.0e-6 at b=128 (2,079 "
            "updates, 59 ms each) and 1.2e-5 at b=32 (7,889 updates), still falling; of 8 searched seeds 7 diverge "
            "or end above their start at 15 s",
        ),
    },
    "osc-3": {
        "min_seconds": OSC_HIG_HOUR,
        "min_seeds": 3,
        "cause": (
            "budget",
            "HIG's 1e-7 is its level after the paper's hour: ~24,700 updates at 0.146 s (b=128), ~740 s here at "
            "26-35 ms per update on one idle core. Measured so far: 2.2e-6 at 300 s (11,638 updates, idle machine, "
            "docs/benchmarks.md), 2.4e-5 at 120 s (2,545 updates, load 4-7), still falling",
        ),
    },
    "osc-4": {
        # The crossing's time is hardware-bound (HIG/Adam cost per update: 1.8 in the paper, 7-10 here);
        # a run must at least last past the paper's ~3 minutes to judge it.
        "min_seconds": 180,
        "min_seeds": 3,
        "cause": (
            "disagreement",
            "HIG passes Adam (paper setting) much earlier here than the paper's ~3 min: in the quick preset (idle "
            "machine, 120 s) from t = 8 s on, after ~300 HIG updates where the paper's 3 minutes are ~1,230 HIG "
            "updates (0.146 s each); it passes both re-tuned Adam settings (b=2048) by t = 16 s. The time of a "
            "crossing does not carry over between machines: HIG's update costs 1.8 Adam updates in the paper and "
            "7-10 here",
        ),
    },
    "osc-5": {
        "min_seconds": 120,
        "cause": (
            "deviation",
            "at a fixed wall clock a smaller batch buys more updates on this CPU than on the paper's GPU: HIG b=32 "
            "costs 13.7 ms per update, b=128 39.1 ms (2.9x; the paper's table 3: 0.087 vs 0.146 s, 1.7x). 120 s "
            "probes from one seed each (load 4-7, 2 cores): HIG b=32 makes 7,879 updates to 1.1e-5, b=128 2,545 "
            "updates to 2.4e-5 (b=32 lower at equal time), but at equal update counts b=128 is lower: 6.2e-5 vs "
            "2.2e-4 at 1,000 updates, 3.2e-5 vs 1.2e-4 at 2,000. GN (seed 7): b=128 lower both ways (8.0e-6 in "
            "2,079 updates vs 1.2e-5 in 7,889 at b=32; at 1,000 updates 1.5e-5 vs 8.5e-5). The paper's trend holds "
            "per update; per second on this CPU it holds for GN and not for HIG",
        ),
    },
    "poi-1": {
        # The paper's hour of b=64 HIG updates (261 at 13.8 s) takes ~3,000 s here (11.4 s each).
        "min_seconds": max(PAPER, POISSON_HIG_HOUR),
        "cause": ("budget", "Adam falls 440 -> 65 in 60 s and to 26 in 60 s more (1.2 decades in 2 min); still falling"),
    },
    "poi-2": {
        "min_seconds": 600,
        "min_seeds": 3,
        "cause": (
            "deviation",
            "HIG runs at b=16 (quick) instead of 64: one b=64 update takes ~30 s on 2 loaded cores (2 updates in "
            "62 s, 64.8 -> 64.2). From the same Adam weights (60 s, 440 -> 64.8), with the reference's batch-sum "
            "gradient at b=16: eta=0.02 makes 63 updates in 60 s to 59.9 while Adam continued reaches 25.6; in 20 s "
            "eta=0.005 -> 64.2, 0.1 -> 93 (rises), 0.5 -> 1.4e6: no eta of this grid lets 1-2 s HIG updates keep up "
            "with Adam's ~20 updates/s within minutes",
        ),
    },
    "poi-3": {"min_seconds": 300},
    "poi-4": {"min_seconds": 60, "min_seeds": 3},
    "dip-1": {
        # The plateau is over within ~30 s here (Adam eta=1e-4, b=16, ~2,500 updates), so 60 s show it.
        # The rule measures its duration (it once asked for a share of the run, which shrinks with the budget).
        "min_seconds": 60,
        "min_seeds": 3,
        "cause": (
            "bug",
            "fixed in the rule after the runs of this report: it asked for >= 20% of the run's time near 0.5, a share "
            "that shrinks with the budget; it now asks for >= 10 s and twice HIG's time. A 90 s probe (seed 0, "
            "load 4-5) shows the plateau plainly: Adam (eta=1e-4, b=16) sits at 0.43-0.48 from "
            "4 s to 24 s (600-2,900 updates) and leaves it at ~28 s (27% of 90 s, 9% of a 270 s run); HIG leaves the "
            "initial loss within ~12 s without a plateau. The duration of the plateau, not its share, is the measure",
        ),
    },
    "dip-2": {
        "min_seconds": 60,
        "min_seeds": 3,
        "cause": (
            "unspecified",
            "the paper does not say how often fig. 4c evaluates; the rule now looks at the initial stage only "
            "(evaluations with loss >= 0.4; it once took the median "
            "over the whole run, where both losses fall together once Adam has left its plateau). There, Adam's "
            "HE/LE is well above 3 (5.3, median of 3 seeds, quick preset; 5.2 in a 90 s probe, where it fell 8.6, "
            "7.0, 5.7, 4.8, 3.9, 2.9 through the plateau and LE even rose 0.05 -> 0.11 before HE fell, as the paper "
            "describes). HIG passes that stage in ~130 updates, so only 1-2 of its evaluations fall in it: 1.9 in "
            "the probe (one seed) but 10.0 in the quick runs (3 seeds). Whether HIG minimises both components "
            "uniformly needs evaluations more often than every ~4 s during its first updates",
        ),
    },
    "dip-3": {"min_seconds": 60, "min_seeds": 3},
    "dip-4": {
        "min_seconds": DIPOLE_HIG_HOUR,
        "cause": (
            "budget",
            "the pure-physics limit ~1e-6 is the end point of the paper's hour-long runs: ~6,000 HIG updates at "
            "0.60 s (b=16), ~270 s here at 44 ms per update (idle core). A 90 s probe (seed 0, eta=0.5, load 4-5, "
            "62 ms per update) reached 1.3e-6 after 1,386 updates",
        ),
    },
    "dip-5": {
        "min_seconds": 60,
        "cause": (
            "seeds",
            "one seed per setting: the eta=0.01 Adam run is the lowest at 10% of the budget in every quick run so "
            "far, but whether it also ends worst at 60 s flipped between two quick runs of the same settings "
            "(worst in the first, not in the second): the end ordering of the eta grid is within run-to-run spread",
        ),
    },
    "dip-6": {"min_seconds": 120},
    "cnn-1": {
        "min_seconds": 120,
        "min_seeds": 3,
        "cause": (
            "budget",
            "HIG sits ~50 updates at loss 1.0 (zero overlap with the target, where the gradient of 1-|<psi,target>|^2 "
            "vanishes) and then leaves it: at 20 s best HIG 1.0 vs Adam 4.4e-2, at 120 s HIG 4.9e-5 vs a tuned "
            "Adam's 8.5e-5 (measured in November 2026 with the quick preset at 120 s)",
        ),
    },
    "abl-1": {
        "min_seconds": 120,
        "cause": (
            "budget",
            "beta < 0 multiplies HIG's step by max(s)^beta; max(s) of the oscillator's J (512 x 2956) is 44 at "
            "initialisation, so beta=-0.5 is eta x 0.15. 120 s probes (load 4-5): beta=0 at 30/60/120 s 8.6e-3/3.9e-3/"
            "1.5e-3, beta=-0.5 0.64/0.51/0.32, still falling steadily: a slower start, not a different end point "
            "within what 2 minutes can show (the paper's runs are an hour)",
        ),
    },
    "abl-2": {"min_seconds": 30},
    "abl-3": {
        "min_seconds": 120,
        "cause": (
            "budget",
            "at GN's best stable seed and 30 s, tau=1e-5/1e-7/1e-10 end at 0.25/0.45/0.35 (67/15/28 updates: tau < "
            "1e-5 needs the SVD route, several times slower per update); no divergence within 30 s",
        ),
    },
}


def apply(claims: dict) -> None:
    for cid, settings in FIDELITY.items():
        if cid in claims:
            for key, value in settings.items():
                setattr(claims[cid], key, value)
