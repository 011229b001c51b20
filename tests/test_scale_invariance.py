"""The scale-invariance chapter's claims on its 2-D toy (scripts/scale_invariance.py), checked numerically.

L = 1/2 |P(x) - y*|^2, P(x) = (x1, alpha x2): SIP's trajectory in y is the same for every
alpha; GD's step in y2 scales with alpha^2; GN rescales the gradient along x2 by 1/alpha^2;
HIG's step in y2 scales with alpha^(1/2). docs/scale-invariance.md is the script's output.
"""

import importlib.util
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("scale_invariance", ROOT / "scripts" / "scale_invariance.py")
si = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(si)

ALPHAS = (0.01, 0.1, 1.0, 10.0)


@pytest.mark.parametrize("method", ["sip", "gn"])
def test_inverting_updates_have_the_same_trajectory_for_every_alpha(method):
    reference = si.trajectory(method, 1.0)
    for alpha in ALPHAS:
        torch.testing.assert_close(si.trajectory(method, alpha), reference, rtol=1e-12, atol=1e-12)
    assert reference[-1].abs().max() < 1e-2  # and it converges: (1 - eta)^10


@pytest.mark.parametrize("alpha", ALPHAS)
def test_gd_step_in_y2_scales_with_alpha_squared(alpha):
    m = si.measure("gd", alpha)
    assert m["dy2_per_r2"] == pytest.approx(-si.ETA * alpha**2, rel=1e-9)
    assert m["dx2_per_grad"] == pytest.approx(si.ETA, rel=1e-9)  # plain gradient: no rescaling


@pytest.mark.parametrize("alpha", ALPHAS)
def test_gn_rescales_the_gradient_by_one_over_alpha_squared(alpha):
    m = si.measure("gn", alpha)
    assert m["dx2_per_grad"] == pytest.approx(si.ETA / alpha**2, rel=1e-10)
    assert m["dy2_per_r2"] == pytest.approx(-si.ETA, rel=1e-10)


@pytest.mark.parametrize("alpha", ALPHAS)
def test_hig_step_in_y2_scales_with_the_square_root_of_alpha(alpha):
    assert si.measure("hig", alpha)["dy2_per_r2"] == pytest.approx(-si.ETA * alpha**0.5, rel=1e-10)


def test_sip_step_is_the_inverse_of_a_newton_step_in_y():
    """By hand at alpha = 0.1: y0 = (1, 1), y* = (0, 0), eta = 1/2: y1 = (1/2, 1/2), x1 = (1/2, 5)."""
    x0 = torch.tensor([1.0, 10.0], dtype=torch.float64)
    dx = si.update("sip", x0, 0.1, torch.zeros(2, dtype=torch.float64), eta=0.5)
    torch.testing.assert_close(x0 + dx, torch.tensor([0.5, 5.0], dtype=torch.float64))


def test_the_docs_table_is_the_scripts_output():
    assert si.table() in (ROOT / "docs" / "scale-invariance.md").read_text()
