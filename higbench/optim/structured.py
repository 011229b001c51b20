"""Structured derivatives for y_i = P(x_i, f(z_i; theta)): solver part and network part apart.

The stacked Jacobian is J = blockdiag(A_1 .. A_b) @ N with the solver Jacobians
A_i = dy_i/du_i (|y| x |u| each) and the network Jacobian N (rows du_i/dtheta). Samples are
independent, so

* ``solver_jacobian`` gets every A_i at once from |y| batched reverse passes through the
  solver at the batch size b: the k-th pass seeds output component k of *every* sample and
  returns row k of every A_i (``is_grads_batched``: one vmapped backward pass). No per-sample
  loop, no Jacobian of the whole batch w.r.t. the whole batch.
* the network part never needs du_i/dtheta (|u| rows per sample, 384 for the dipole): only
  the |y| rows of A_i @ du_i/dtheta, which are vector-Jacobian products of the network.

Two network routes, both exposing the same four operations (``gram`` K = J J^T,
``matrix`` J itself, ``transpose_apply`` J^T c, ``apply`` J v):

* ``MLPJacobian`` (stacks of ``nn.Linear`` and elementwise activations): the row of J for
  (sample i, output k) and layer l's weight is the outer product D_l[i,k] (x) h_{l-1,i} of
  the back-propagated signal and the layer input, so

      K = sum_l (D_l D_l^T) o (H_{l-1} H_{l-1}^T + 1)   (o: Hadamard, the "+1" is the bias)

  (an empirical NTK) without ever forming J; J^T c is one backward sweep of the
  signals weighted by c, and J v one forward sweep (the Krylov route's products K v =
  J (J^T v)). Memory: rows x rows for K plus rows x width per layer.
* ``GenericJacobian`` (any network, e.g. the dipole CNN): J = vmap over samples of jacrev of
  theta -> A_i @ f(theta, z_i) (torch.func), materialised (rows x |theta|).

Everything after the solver Jacobian is computed in ``dtype`` (the optimizer's precision,
float64 by default) from the float64 parameters' values, so the structured rows agree with
the naive torch.func rows (``higbench.optim.jacobians``) to the precision of the model dtype.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
from torch import nn
from torch.func import functional_call, jacrev, vmap

SOLVER_JACOBIAN_METHODS = ("batched", "loop", "replicate")


# ---------------------------------------------------------------------------------------
# Solver part: A_i = dy_i / du_i for all samples at once
# ---------------------------------------------------------------------------------------


def solver_jacobian(
    physics: Callable[..., torch.Tensor],
    inputs: torch.Tensor | None,
    u: torch.Tensor,
    method: str = "batched",
    physics_jacobian: Callable[..., tuple[torch.Tensor, torch.Tensor] | None] | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Outputs y (b, m) and solver Jacobians A (b, m, |u|) of y = physics(inputs, u).

    ``physics(inputs, u)`` (or ``physics(u)`` when ``inputs`` is None) must treat samples
    independently (row i of y depends on row i of u and inputs only). ``u`` (b, ...) is
    detached here; the returned y and A carry no graph. Methods:

    * ``batched``: one forward pass, then one vmapped backward pass seeding output component
      k on every sample for k = 1..m (``torch.autograd.grad(..., is_grads_batched=True)``);
      falls back to ``loop`` if an operation of the solver has no batching rule.
    * ``loop``: the same m backward passes one after another (retain_graph).
    * ``replicate``: the batch replicated m times (b*m samples) in one forward and one
      backward pass, copy k seeded with component k.

    With ``batched``, ``physics_jacobian(inputs, u)`` (the problem's, ``Problem.physics_jacobian``)
    may answer directly: (y, A) (e.g. from a hand-written adjoint sweep with m seeds per
    sample), or None to use autograd.
    """
    if method not in SOLVER_JACOBIAN_METHODS:
        raise ValueError(f"method={method!r}: expected one of {SOLVER_JACOBIAN_METHODS}")
    if method == "batched" and physics_jacobian is not None:
        found = physics_jacobian(inputs, u.detach())
        if found is not None:
            y, A = found
            return y.reshape(u.shape[0], -1).detach(), A.reshape(u.shape[0], y[0].numel(), -1)
    b = u.shape[0]
    u_flat_size = u[0].numel()

    def call(x, v):
        return physics(v) if x is None else physics(x, v)

    with torch.enable_grad():
        if method == "replicate":
            with torch.no_grad():
                m = call(None if inputs is None else inputs[:1], u[:1].detach()).reshape(1, -1).shape[1]
            ur = u.detach().repeat(m, *([1] * (u.ndim - 1))).requires_grad_(True)
            xr = None if inputs is None else inputs.repeat(m, *([1] * (inputs.ndim - 1)))
            yr = call(xr, ur).reshape(m * b, -1)
            if not yr.requires_grad:  # y does not depend on u at all
                return yr[:b].detach(), yr.new_zeros(b, m, u_flat_size)
            seed = torch.eye(m, dtype=yr.dtype, device=yr.device).repeat_interleave(b, dim=0)
            (grad,) = torch.autograd.grad(yr, ur, seed, materialize_grads=True)
            A = grad.reshape(m, b, u_flat_size).transpose(0, 1)
            return yr[:b].detach(), A
        leaf = u.detach().requires_grad_(True)
        y = call(inputs, leaf)
        y2 = y.reshape(b, -1)
        m = y2.shape[1]
        if not y2.requires_grad:  # y does not depend on u at all
            return y2.detach(), y2.new_zeros(b, m, u_flat_size)
        if method == "batched":
            try:
                return y2.detach(), output_jacobian(y2, leaf)
            except RuntimeError:  # an op without a vmap rule: do the passes one by one
                pass
        rows = []
        for k in range(m):
            seed = torch.zeros_like(y2)
            seed[:, k] = 1.0
            (grad,) = torch.autograd.grad(y2, leaf, seed, retain_graph=k < m - 1, materialize_grads=True)
            rows.append(grad.reshape(b, u_flat_size))
        return y2.detach(), torch.stack(rows, dim=1)


def output_jacobian(y: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
    """A (b, m, |u|) with A_i = dy_i/du_i, for y (b, m) computed from u (b, ...) in a graph.

    One vmapped backward pass: seed k puts component k on every sample at once (samples
    independent), so row k of every A_i comes back together. The graph is kept.
    """
    b, m = y.shape
    seed = torch.eye(m, dtype=y.dtype, device=y.device)[:, None, :].expand(m, b, m)
    (grad,) = torch.autograd.grad(y, u, seed, is_grads_batched=True, retain_graph=True, materialize_grads=True)
    return grad.reshape(m, b, -1).transpose(0, 1)


# ---------------------------------------------------------------------------------------
# Network part
# ---------------------------------------------------------------------------------------


def _param_positions(model: nn.Module, params: Sequence[torch.Tensor]) -> list[tuple[str, torch.Tensor, int]]:
    """(name, tensor, position in ``params``) of the model's trainable parameters.

    ``params`` (the optimizer's order) must be exactly the model's trainable parameters.
    """
    index = {id(p): i for i, p in enumerate(params)}
    named = [(n, p) for n, p in model.named_parameters() if p.requires_grad]
    if len(named) != len(params) or any(id(p) not in index for _, p in named):
        raise ValueError("the optimizer's parameters must be exactly the model's trainable parameters")
    return [(n, p, index[id(p)]) for n, p in named]


def _offsets(params: Sequence[torch.Tensor]) -> list[int]:
    out, total = [], 0
    for p in params:
        out.append(total)
        total += p.numel()
    return out


class StructuredJacobian:
    """J (rows = b*m, |theta|) of the stacked per-sample outputs, rows sample-major.

    Columns follow ``params`` (the optimizer's parameter order).
    """

    rows: int
    n_params: int

    def gram(self) -> torch.Tensor:
        """K = J J^T (rows, rows)."""
        raise NotImplementedError

    def matrix(self) -> torch.Tensor:
        """J itself (rows, |theta|)."""
        raise NotImplementedError

    def transpose_apply(self, c: torch.Tensor) -> torch.Tensor:
        """J^T c for c (rows,), flat (|theta|,)."""
        raise NotImplementedError

    def apply(self, v: torch.Tensor) -> torch.Tensor:
        """J v for v (|theta|,), flat (rows,)."""
        raise NotImplementedError

    def gram_apply(self, v: torch.Tensor) -> torch.Tensor:
        """K v = J (J^T v) for v (rows,), K never formed (the Krylov route's product)."""
        return self.apply(self.transpose_apply(v))


class GenericJacobian(StructuredJacobian):
    """Materialised J = blockdiag(A_i) N for any network, through torch.func (per-sample VJPs)."""

    def __init__(
        self, model: nn.Module, params: Sequence[torch.Tensor], net_inputs: torch.Tensor, A: torch.Tensor, dtype: torch.dtype
    ):
        placed = _param_positions(model, params)
        b, m, n = A.shape
        values = {name: p.detach().to(dtype) for name, p, _ in placed}
        buffers = {name: t.to(dtype) if t.is_floating_point() else t for name, t in model.named_buffers()}
        z = net_inputs.detach().to(dtype)
        A = A.to(dtype)

        def contracted(theta, z_i, a_i):
            u = functional_call(model, {**theta, **buffers}, (z_i.unsqueeze(0),))
            return a_i @ u.reshape(-1)

        jac = vmap(jacrev(contracted), in_dims=(None, 0, 0))(values, z, A)  # name -> (b, m, *shape)
        blocks: list[torch.Tensor | None] = [None] * len(params)
        for name, p, pos in placed:
            blocks[pos] = jac[name].reshape(b * m, p.numel())
        self.J = torch.cat(blocks, dim=1)  # type: ignore[arg-type]
        self.rows, self.n_params = self.J.shape

    def gram(self) -> torch.Tensor:
        return self.J @ self.J.T

    def matrix(self) -> torch.Tensor:
        return self.J

    def transpose_apply(self, c: torch.Tensor) -> torch.Tensor:
        return self.J.T @ c.to(self.J.dtype)

    def apply(self, v: torch.Tensor) -> torch.Tensor:
        return self.J @ v.to(self.J.dtype)


# Elementwise activations with their derivative from (input, output).
_ACTIVATION_DERIVATIVES: dict[type, Callable[[torch.Tensor, torch.Tensor], torch.Tensor]] = {
    nn.Tanh: lambda x, y: 1.0 - y * y,
    nn.ReLU: lambda x, y: (x > 0).to(x.dtype),
    nn.Sigmoid: lambda x, y: y * (1.0 - y),
    nn.Identity: lambda x, y: torch.ones_like(x),
}


def mlp_layers(model: nn.Module) -> list[nn.Module] | None:
    """The layers of an ``nn.Sequential`` of ``nn.Linear`` and supported activations, else None.

    None also when a Linear's parameters are partly frozen or there is no Linear at all.
    """
    if not isinstance(model, nn.Sequential):
        return None
    layers = list(model)
    linears = [m for m in layers if isinstance(m, nn.Linear)]
    if not linears:
        return None
    for m in layers:
        if isinstance(m, nn.Linear):
            if not m.weight.requires_grad or (m.bias is not None and not m.bias.requires_grad):
                return None
        elif type(m) not in _ACTIVATION_DERIVATIVES:
            return None
    return layers


class MLPJacobian(StructuredJacobian):
    """J of an MLP through its per-layer factors (back-propagated signals x layer inputs).

    Nothing of size rows x |theta| is formed for ``gram`` and ``transpose_apply``.
    """

    def __init__(
        self, model: nn.Module, params: Sequence[torch.Tensor], net_inputs: torch.Tensor, A: torch.Tensor, dtype: torch.dtype
    ):
        layers = mlp_layers(model)
        if layers is None:
            raise ValueError("MLPJacobian needs an nn.Sequential of nn.Linear and elementwise activations")
        placed = _param_positions(model, params)
        if net_inputs.ndim != 2:
            raise ValueError(f"MLPJacobian needs net inputs of shape (b, features), got {tuple(net_inputs.shape)}")
        self.params = list(params)
        self.position = {id(p): pos for _, p, pos in placed}
        self.offsets = _offsets(params)
        self.n_params = sum(p.numel() for p in params)
        b, m, _ = A.shape
        self.b, self.m, self.rows = b, m, b * m
        self.dtype = dtype
        with torch.no_grad():
            # Forward in ``dtype``: inputs of every Linear, derivatives of every activation.
            h = net_inputs.to(dtype)
            steps: list[tuple[str, object]] = []
            for layer in layers:
                if isinstance(layer, nn.Linear):
                    steps.append(("linear", (layer, h)))
                    W = layer.weight.to(dtype)
                    h = h @ W.T if layer.bias is None else torch.addmm(layer.bias.to(dtype), h, W.T)
                else:
                    out = layer(h)
                    steps.append(("act", _ACTIVATION_DERIVATIVES[type(layer)](h, out)))
                    h = out
            if h.shape[1] != A.shape[2]:
                raise ValueError(f"network output has {h.shape[1]} values per sample, the solver Jacobian expects {A.shape[2]}")
            # Backward: the signal S (b, m, width) = A_i @ d u_i / d(activations).
            S = A.to(dtype)
            self.layers: list[tuple[nn.Linear, torch.Tensor, torch.Tensor]] = []  # (layer, D (b,m,out), H (b,in))
            for kind, item in reversed(steps):
                if kind == "act":
                    S = S * item[:, None, :]  # type: ignore[index]
                else:
                    layer, h_in = item  # type: ignore[misc]
                    self.layers.append((layer, S.contiguous(), h_in))  # contiguous: fast batched products
                    S = S @ layer.weight.to(dtype)
            self.layers.reverse()

    def gram(self) -> torch.Tensor:
        b, m, R = self.b, self.m, self.rows
        K = torch.zeros(R, R, dtype=self.dtype, device=self.layers[0][1].device)
        K4 = K.view(b, m, b, m)
        for layer, D, H in self.layers:
            G = H @ H.T
            if layer.bias is not None:
                G += 1.0
            D2 = D.reshape(R, -1)
            K4.addcmul_((D2 @ D2.T).view(b, m, b, m), G[:, None, :, None])
        return K

    def matrix(self) -> torch.Tensor:
        J = torch.empty(self.rows, self.n_params, dtype=self.dtype, device=self.layers[0][1].device)
        for layer, D, H in self.layers:
            D2 = D.reshape(self.rows, -1)
            w = self._slice(layer.weight)
            J[:, w] = (D[:, :, :, None] * H[:, None, None, :]).reshape(self.rows, -1)
            if layer.bias is not None:
                J[:, self._slice(layer.bias)] = D2
        return J

    def transpose_apply(self, c: torch.Tensor) -> torch.Tensor:
        out = torch.empty(self.n_params, dtype=self.dtype, device=c.device)
        c = c.to(self.dtype).reshape(self.b, self.m)
        for layer, D, H in self.layers:
            e = torch.bmm(c[:, None, :], D)[:, 0, :]  # (b, out): sum_k c_ik D_l[i, k]
            out[self._slice(layer.weight)] = (e.T @ H).reshape(-1)
            if layer.bias is not None:
                out[self._slice(layer.bias)] = e.sum(0)
        return out

    def apply(self, v: torch.Tensor) -> torch.Tensor:
        # Row (i, k) of layer l's block is D_l[i,k] (x) [h_{l-1,i}, 1]: its product with
        # (V_l, v_bias) is D_l[i,k] . (V_l h_{l-1,i} + v_bias), one sweep over the layers.
        v = v.to(self.dtype)
        out = torch.zeros(self.b, self.m, dtype=self.dtype, device=v.device)
        for layer, D, H in self.layers:
            z = H @ v[self._slice(layer.weight)].view(layer.weight.shape).T  # (b, out)
            if layer.bias is not None:
                z += v[self._slice(layer.bias)]
            out += torch.bmm(D, z[:, :, None])[:, :, 0]
        return out.reshape(-1)

    def gram_apply(self, v: torch.Tensor) -> torch.Tensor:
        # Layer l's part of K is (D_l D_l^T) o G_l with G_l = H_{l-1} H_{l-1}^T + 1 (b x b):
        # K v = sum_l D_l . (G_l (v . D_l)), never through parameter space. All layers' D
        # side by side (one copy, made once) so each sweep is one batched product: the
        # sweeps are memory-bound, this reads the factors twice per product.
        if not hasattr(self, "_sweep"):
            D = torch.cat([D for _, D, _ in self.layers], dim=2)  # (b, m, sum of widths)
            G = [(H @ H.T + (1.0 if layer.bias is not None else 0.0)) for layer, _, H in self.layers]
            self._sweep = D, G, [D_l.shape[2] for _, D_l, _ in self.layers]
        D, G, widths = self._sweep
        e = torch.bmm(v.to(self.dtype).reshape(self.b, 1, self.m), D)[:, 0, :]  # (b, sum of widths)
        z = torch.cat([G_l @ e_l for G_l, e_l in zip(G, e.split(widths, dim=1))], dim=1)
        return torch.bmm(D, z[:, :, None]).reshape(-1)

    def _slice(self, p: torch.Tensor) -> slice:
        start = self.offsets[self.position[id(p)]]
        return slice(start, start + p.numel())


def mlp_factor_values(model: nn.Module) -> int | None:
    """Values per row of J that ``MLPJacobian`` holds for the Krylov route (None: not an MLP).

    Per row the back-propagated signals of every layer, twice (per layer and side by side
    for ``gram_apply``), plus the layer inputs, counted per row (an upper bound: they are
    per sample).
    """
    layers = mlp_layers(model)
    if layers is None:
        return None
    linears = [m for m in layers if isinstance(m, nn.Linear)]
    return sum(2 * m.out_features + m.in_features for m in linears)


def network_jacobian(
    model: nn.Module,
    params: Sequence[torch.Tensor],
    net_inputs: torch.Tensor,
    A: torch.Tensor,
    dtype: torch.dtype = torch.float64,
    route: str = "auto",
) -> StructuredJacobian:
    """J = blockdiag(A_i) @ du/dtheta. route: ``mlp`` (factors), ``generic`` (torch.func) or ``auto``."""
    if route not in ("auto", "mlp", "generic"):
        raise ValueError(f"route={route!r}: expected auto, mlp or generic")
    if route == "mlp" or (route == "auto" and mlp_layers(model) is not None and net_inputs.ndim == 2):
        return MLPJacobian(model, params, net_inputs, A, dtype)
    return GenericJacobian(model, params, net_inputs, A, dtype)


class GraphJacobian(StructuredJacobian):
    """J from an autograd graph u(theta) (b, |u|) and solver Jacobians A: for closures.

    The rows of J are the |y| * b vector-Jacobian products of u with cotangents A_i[k] placed
    on sample i, done as one vmapped backward pass; nothing about the network is assumed
    except per-sample independence.
    """

    def __init__(self, u: torch.Tensor, params: Sequence[torch.Tensor], A: torch.Tensor, dtype: torch.dtype):
        b, m, n = A.shape
        R = b * m
        seed = torch.zeros(R, b, n, dtype=u.dtype, device=u.device)
        seed.view(b, m, b, n).diagonal(dim1=0, dim2=2).copy_(A.to(u.dtype).permute(1, 2, 0))
        grads = torch.autograd.grad(u.reshape(b, n), list(params), seed, is_grads_batched=True, allow_unused=True)
        self.J = torch.cat(
            [
                (g if g is not None else torch.zeros(R, *p.shape, dtype=u.dtype, device=u.device)).reshape(R, -1)
                for g, p in zip(grads, params)
            ],
            dim=1,
        ).to(dtype)
        self.rows, self.n_params = self.J.shape

    gram = GenericJacobian.gram
    matrix = GenericJacobian.matrix
    transpose_apply = GenericJacobian.transpose_apply
    apply = GenericJacobian.apply
