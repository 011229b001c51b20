"""Physics of the quantum dipole solver: unitarity, stationary eigenstates, dense reference, autograd.

Every test that time-steps runs on both implementations (``problem.solver``): the reference
torch solver and the compiled loop with its hand-derived adjoint (``simulate`` fixture).
"""

import math

import pytest
import torch

from higbench.physics import dipole as D
from higbench.physics import dipole_fast

F64 = torch.float64


@pytest.fixture(params=["reference", "fast"])
def simulate(request):
    return {"reference": D.simulate, "fast": dipole_fast.simulate}[request.param]


def gen(seed):
    return torch.Generator().manual_seed(seed)


def random_states(b, seed=0, dtype=F64):
    psi = torch.randn(b, 14, 2, generator=gen(seed), dtype=F64)
    return (psi / psi.square().sum((-2, -1), keepdim=True).sqrt()).to(dtype)


def ground(b, dtype=F64):
    return D.eigenstate(1, dtype).expand(b, 14, 2)


def norm2(psi):
    return psi.square().sum((-2, -1))


def test_grid_and_shapes(simulate):
    x = D.grid()
    assert x.shape == (14,)
    torch.testing.assert_close(x, torch.arange(1, 15, dtype=F64) * 2 / 15)
    psi0, u = random_states(3), torch.randn(3, 5, dtype=F64)
    out = simulate(psi0, u)
    traj = simulate(psi0, u, return_trajectory=True)
    assert out.shape == (3, 14, 2) and traj.shape == (3, 6, 14, 2)
    torch.testing.assert_close(traj[:, 0], psi0, atol=0, rtol=0)
    torch.testing.assert_close(traj[:, -1], out, atol=0, rtol=0)
    assert simulate(psi0.float(), u.float()).dtype == torch.float32


def test_eigenstates_orthonormal_and_eigenvectors_of_d2():
    phis = torch.stack([D.eigenstate(n) for n in range(1, 15)])  # (14, 14, 2)
    assert (phis[..., 1] == 0).all()
    gram = D.overlap(phis[:, None], phis[None, :])
    torch.testing.assert_close(gram, torch.eye(14, dtype=torch.complex128), atol=1e-13, rtol=0)
    m = D.crank_nicolson_matrix(torch.zeros((), dtype=F64), dt=2.0)  # 1 + i(-D2)
    neg_d2 = ((m - torch.eye(14)) / 1j).real
    for n in (1, 2, 3, 14):
        lam = 4 / D.DX**2 * math.sin(math.pi * n / 30) ** 2
        torch.testing.assert_close(neg_d2 @ D.eigenstate(n)[:, 0], lam * D.eigenstate(n)[:, 0])


@pytest.mark.parametrize("scale", [1.0, 30.0, 1e4])
def test_matches_dense_solve(simulate, scale):
    psi0, u = random_states(4, seed=1), scale * torch.randn(4, 40, generator=gen(2), dtype=F64)
    torch.testing.assert_close(simulate(psi0, u), D.simulate_dense(psi0, u), atol=1e-12, rtol=0)


@pytest.mark.parametrize("dtype,tol", [(F64, 1e-12), (torch.float32, 1e-5)])
def test_norm_conserved(simulate, dtype, tol):
    psi0 = random_states(8, seed=3, dtype=dtype)
    u = 5.0 * torch.randn(8, 384, generator=gen(4), dtype=F64).to(dtype)
    traj = simulate(psi0, u, return_trajectory=True)
    drift = (norm2(traj) / norm2(psi0)[:, None] - 1.0).abs().max().item()
    assert drift < tol


def test_float32_survives_huge_controls(simulate):
    # The semiseparable factors are scaled from the middle of the grid so they stay finite.
    psi0, u = random_states(4, seed=19, dtype=torch.float32), 1e6 * torch.randn(4, 20, generator=gen(20))
    out = simulate(psi0, u)
    assert torch.isfinite(out).all()
    torch.testing.assert_close(out.double(), D.simulate_dense(psi0.double(), u.double()), atol=1e-5, rtol=0)


@pytest.mark.parametrize("n", [1, 2, 3])
def test_eigenstates_stationary(simulate, n):
    # Without control CN multiplies phi_n by the exact phase ((1 - i a lam) / (1 + i a lam))^steps.
    phi = D.eigenstate(n).expand(2, 14, 2)
    out = simulate(phi, torch.zeros(2, 384, dtype=F64))
    ov = D.overlap(phi, out)
    torch.testing.assert_close(ov.abs(), torch.ones(2, dtype=F64), atol=1e-10, rtol=0)
    lam, a = 4 / D.DX**2 * math.sin(math.pi * n / 30) ** 2, D.DT / 2
    phase = ((1 - 1j * a * lam) / (1 + 1j * a * lam)) ** 384
    torch.testing.assert_close(ov, torch.full((2,), phase, dtype=torch.complex128), atol=1e-10, rtol=0)


def test_control_drives_transitions(simulate):
    # A constant field mixes the eigenstates: the ground-state population must change.
    out = simulate(ground(1), torch.full((1, 384), 10.0, dtype=F64))
    assert (D.overlap(ground(1), out).abs() < 0.99).all()


def test_complex64_matches_complex128(simulate):
    psi0, u = random_states(8, seed=5), 3.0 * torch.randn(8, 384, generator=gen(6), dtype=F64)
    out64 = simulate(psi0, u)
    out32 = simulate(psi0.float(), u.float())
    torch.testing.assert_close(out32.double(), out64, atol=1e-4, rtol=0)


def test_batch_independence(simulate):
    psi0, u = random_states(5, seed=7), torch.randn(5, 12, generator=gen(8), dtype=F64)
    full = simulate(psi0, u)
    for i in (0, 3):
        torch.testing.assert_close(simulate(psi0[i : i + 1], u[i : i + 1])[0], full[i], atol=1e-15, rtol=0)
    jac = torch.autograd.functional.jacobian(lambda v: simulate(psi0, v), u)  # (b, 14, 2, b, steps)
    off = jac.clone()
    off[range(5), :, :, range(5)] = 0.0
    assert off.abs().max() == 0.0 and jac.abs().max() > 0.0


def test_gradcheck(simulate):
    psi0 = random_states(1, seed=9).requires_grad_()
    u = torch.randn(1, 3, generator=gen(10), dtype=F64).requires_grad_()
    assert torch.autograd.gradcheck(simulate, (psi0, u))
    psi0, u = random_states(2, seed=15).requires_grad_(), torch.randn(2, 4, generator=gen(16), dtype=F64).requires_grad_()
    assert torch.autograd.gradcheck(lambda p, v: D.fidelity_loss(simulate(p, v), ground(2)), (psi0, u))


def test_torch_func_per_sample_jacobian(simulate):
    # The HIG Jacobian code runs the physics under vmap(jacrev(...)) with a batch of one.
    psi0, u = random_states(3, seed=11), torch.randn(3, 6, generator=gen(12), dtype=F64)

    def single(p, v):
        return simulate(p[None], v[None])[0].reshape(-1)

    jac = torch.func.vmap(torch.func.jacrev(single, argnums=1))(psi0, u)  # (b, 28, steps)
    full = torch.autograd.functional.jacobian(lambda v: simulate(psi0, v).reshape(3, -1), u)
    torch.testing.assert_close(jac, full[range(3), :, range(3)])


@pytest.mark.parametrize("which", ["fidelity", "low_energy"])
@pytest.mark.parametrize("argnum", [0, 1])
def test_torch_func_loss_jacobian(which, argnum):
    # conj() of a complex tensor on the autograd path breaks vmap (no batching rule for _neg_view).
    loss = D.fidelity_loss if which == "fidelity" else lambda p, t: D.energy_overlap_loss(p, t, 2)
    a, b = random_states(3, seed=17), random_states(3, seed=18)
    jac = torch.func.vmap(torch.func.jacrev(lambda p, t: loss(p[None], t[None])[0], argnums=argnum))(a, b)
    full = torch.autograd.functional.jacobian(lambda x: loss(*((x, b) if argnum == 0 else (a, x))).sum(), (a, b)[argnum])
    torch.testing.assert_close(jac, full)


def test_overlap_and_losses():
    a, b = random_states(4, seed=13), random_states(4, seed=14)
    za, zb = D.to_complex(a), D.to_complex(b)
    torch.testing.assert_close(D.overlap(a, b), (za.conj() * zb).sum(-1))
    torch.testing.assert_close(D.overlap(b, a), D.overlap(a, b).conj())
    torch.testing.assert_close(D.to_real(za), a, atol=0, rtol=0)
    torch.testing.assert_close(D.fidelity_loss(a, a), torch.zeros(4, dtype=F64), atol=1e-14, rtol=0)
    rotated = D.to_real(za * torch.exp(torch.tensor(0.7j, dtype=torch.complex128)))  # global phase
    torch.testing.assert_close(D.fidelity_loss(rotated, a), torch.zeros(4, dtype=F64), atol=1e-14, rtol=0)
    torch.testing.assert_close(D.fidelity_loss(ground(1), D.eigenstate(2)[None]), torch.ones(1, dtype=F64))
    # Target a phi_2 + b phi_3: the low/high-energy losses compare populations of phi_2 / phi_3.
    target = (0.6 * D.eigenstate(2) + 0.8 * D.eigenstate(3))[None]
    pred = (0.8 * D.eigenstate(2) + 0.6 * D.eigenstate(3))[None]
    torch.testing.assert_close(D.energy_overlap_loss(pred, target, 2), torch.tensor([0.04], dtype=F64))
    torch.testing.assert_close(D.energy_overlap_loss(pred, target, 3), torch.tensor([0.04], dtype=F64))
    torch.testing.assert_close(D.energy_overlap_loss(target, target, 2), torch.zeros(1, dtype=F64), atol=1e-15, rtol=0)
