r"""Differentiable matrix exponential actions for heat diffusion (thesis 3.2) and transport (5.1).

:func:`expm_multiply` computes :math:`y = \exp(-t M^{-1} A) z_0`: heat diffusion with
:math:`A = L_c`, backward transport with :math:`A = -D_\omega`.  With :math:`K = M^{-1}A`,
:math:`B = -tK`, :math:`g = \partial L/\partial \bar y`,
:math:`v(s) = e^{sB} z_0` and :math:`u(s) = e^{(1-s)B^H} g`, the backward pass is

.. math::
    \frac{\partial L}{\partial \bar z_0} = e^{B^H} g, \qquad
    \frac{\partial L}{\partial t} = -\mathrm{Re}\, \langle g, K y \rangle,

.. math::
    \frac{\partial L}{\partial \bar A_{ij}} = -t \int_0^1 (M^{-1}u)_i \, \bar v_j \, ds,
    \qquad
    \frac{\partial L}{\partial M_{ij}} = t \, \mathrm{Re} \int_0^1 (M^{-1}u)_i \,
    \overline{(K v)_j} \, ds,

on the patterns of :math:`A` and :math:`M`.  The first two are exact.  The pattern
entries of the Fréchet derivative :math:`\int_0^1 u v^H ds` are integrated with
composite 8-point Gauss-Legendre quadrature on panels over which :math:`\|B\|_1 \le 4`,
which bounds the relative quadrature error by about ``1e-13`` for any spectrum (the
augmented block exponential :math:`\exp\begin{pmatrix} B & E \\ 0 & B\end{pmatrix}`
gives the Fréchet derivative in *one direction* :math:`E`; the gradient on all ``nnz``
pattern entries would need one such product per entry).  Cost of the matrix gradients:
about ``8 * ceil(||B||_1 / 4)`` short exponential actions each way; memory: one vector
per panel (checkpoints of :math:`v`).

:func:`implicit_euler` is the cheaper, first-order alternative: ``steps`` steps of
:math:`z \leftarrow (M + hA)^{-1} M z`, :math:`h = t/\text{steps}`, with one factorization,
differentiable through :func:`~torch_edgevf.linalg.solve`.

Precision follows the inputs: SciPy's ``expm_multiply`` runs in the dtype of the
operator and vector (float32 stays float32).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import torch

from .._dtypes import complex_dtype, real_dtype
from ._utils import (
    SparseData,
    as_matrix_pair,
    check_finite,
    check_rhs,
    from_numpy,
    to_numpy,
)
from .factor import factorize
from .solve import SparseSolver

_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(8)
_PANEL_NORM = 4.0


class _Generator:
    """The operator :math:`K = M^{-1} A` and its adjoint, with exponential actions."""

    def __init__(self, A: sp.csc_matrix, M: sp.csc_matrix, m_diagonal: bool):
        self.A, self.M = A.tocsr(), M
        if m_diagonal:
            inv = sp.diags(1.0 / M.diagonal())
            self.minv = lambda x: inv @ x
            self.K = (inv @ self.A).tocsr()
            self.KH = self.K.conj().T.tocsr()
            self.trace = float(np.real(self.K.diagonal().sum()))
        else:
            self._mf = factorize(M, "auto")
            self.minv = self._mf.solve
            self.K = self._operator(adjoint=False)
            self.KH = self._operator(adjoint=True)
            self.trace = float(np.real(self.A.diagonal() / M.diagonal()).sum())
        self.norm1 = self._norm1()

    def _operator(self, adjoint: bool) -> sla.LinearOperator:
        AH = self.A.conj().T.tocsr()
        fwd = lambda x: self.minv(self.A @ x)  # noqa: E731
        bwd = lambda x: AH @ self.minv(x)  # noqa: E731
        mv, rmv = (bwd, fwd) if adjoint else (fwd, bwd)
        return sla.LinearOperator(
            self.A.shape, matvec=mv, rmatvec=rmv, matmat=mv, rmatmat=rmv, dtype=self.A.dtype
        )

    def _norm1(self) -> float:
        if isinstance(self.K, sla.LinearOperator):
            return float(sla.onenormest(self.K))
        return float(abs(self.K).sum(axis=0).max()) if self.K.nnz else 0.0

    def expm(self, s: float, x: np.ndarray, adjoint: bool = False) -> np.ndarray:
        """:math:`\\exp(-s K) x` (or with :math:`K^H`)."""
        if s == 0.0 or not x.size:
            return x.copy()
        op = self.KH if adjoint else self.K
        return sla.expm_multiply(-s * op, x, traceA=-s * self.trace)


def _quadrature_nodes(c: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Composite Gauss-Legendre nodes/weights on [0, 1] and the number of panels."""
    panels = max(1, math.ceil(c / _PANEL_NORM))
    edges = np.linspace(0.0, 1.0, panels + 1)
    h = np.diff(edges)
    nodes = (edges[:-1, None] + h[:, None] * (_GL_NODES + 1) / 2).ravel()
    weights = (h[:, None] * _GL_WEIGHTS / 2).ravel()
    return nodes, weights, panels


def _pattern(left, right, data: SparseData):
    idx = data.indices.cpu().numpy()
    prod = left[idx[0]] * right[idx[1]].conj()
    return prod if prod.ndim == 1 else prod.sum(-1)


def _matrix_gradients(gen: _Generator, t: float, z0, g, a_data, m_data, need_a, need_m):
    """Quadrature of the pattern entries of the Fréchet derivative (module docstring)."""
    nodes, weights, panels = _quadrature_nodes(abs(t) * gen.norm1)
    per = len(_GL_NODES)
    # checkpoints v(s) at the first node of every panel
    checkpoints, v, s_prev = [], z0, 0.0
    for p in range(panels):
        v = gen.expm(t * (nodes[p * per] - s_prev), v)
        s_prev = nodes[p * per]
        checkpoints.append(v)
    grad_a = 0.0
    grad_m = 0.0
    u, s_next = g, 1.0
    for p in reversed(range(panels)):
        vs, v, s_prev = [checkpoints[p]], checkpoints[p], nodes[p * per]
        for q in range(1, per):
            v = gen.expm(t * (nodes[p * per + q] - s_prev), v)
            s_prev = nodes[p * per + q]
            vs.append(v)
        for q in reversed(range(per)):
            s = nodes[p * per + q]
            u = gen.expm(t * (s_next - s), u, adjoint=True)
            s_next = s
            mu = gen.minv(u) * weights[p * per + q]
            if need_a:
                grad_a = grad_a - t * _pattern(mu, vs[q], a_data)
            if need_m:
                grad_m = grad_m + t * np.real(_pattern(mu, gen.K @ vs[q], m_data))
    return grad_a, grad_m


class _ExpmMultiply(torch.autograd.Function):
    @staticmethod
    def forward(ctx, a_values, m_values, z0, t, a_data, m_data):
        gen = _Generator(a_data.to_scipy(), m_data.to_scipy(), m_data.is_diagonal())
        tf = float(t)
        y_np = gen.expm(tf, to_numpy(z0))
        dtype = complex_dtype(a_data.dtype) if (z0.is_complex() or a_data.is_complex) else a_data.dtype
        y = from_numpy(y_np, z0, dtype)
        ctx.gen, ctx.a_data, ctx.m_data = gen, a_data, m_data
        ctx.save_for_backward(z0, t, y)
        return y

    @staticmethod
    def backward(ctx, g):
        z0, t, y = ctx.saved_tensors
        gen, tf = ctx.gen, float(t)
        g_np, y_np = to_numpy(g), to_numpy(y)
        grad_a = grad_m = grad_z0 = grad_t = None
        if ctx.needs_input_grad[2]:
            gz = from_numpy(gen.expm(tf, g_np, adjoint=True), g, y.dtype)
            grad_z0 = gz if z0.is_complex() else gz.real.to(z0.dtype)
        if ctx.needs_input_grad[3]:
            ky = gen.K @ y_np
            grad_t = -torch.tensor(float(np.real(np.vdot(g_np, ky))), dtype=t.dtype, device=t.device)
        need_a, need_m = ctx.needs_input_grad[0], ctx.needs_input_grad[1]
        if need_a or need_m:
            ga, gm = _matrix_gradients(
                gen, tf, to_numpy(z0).astype(y_np.dtype), g_np, ctx.a_data, ctx.m_data, need_a, need_m
            )
            if need_a:
                ga = from_numpy(np.asarray(ga), g, y.dtype)
                grad_a = ga if ctx.a_data.is_complex else ga.real.to(ctx.a_data.dtype)
            if need_m:
                grad_m = from_numpy(np.asarray(gm), g, ctx.m_data.dtype)
        return grad_a, grad_m, grad_z0, grad_t, None, None


def _prepare(A, M, z0, t) -> tuple[SparseData, SparseData, torch.Tensor]:
    a_data, m_data = as_matrix_pair(A, M)
    n = a_data.n
    check_rhs(z0, n, a_data.dtype, "z0")
    t = torch.as_tensor(t, dtype=real_dtype(a_data.dtype), device=z0.device)
    if t.numel() != 1 or t.is_complex():
        raise ValueError(f"t must be a real scalar, got shape {tuple(t.shape)}")
    check_finite(t, "t")
    return a_data, m_data, t.reshape(())


def expm_multiply(
    A: torch.Tensor, M: torch.Tensor | None, z0: torch.Tensor, t: float | torch.Tensor
) -> torch.Tensor:
    r"""Heat/transport flow :math:`z(t) = \exp(-t M^{-1} A) z_0`, differentiable.

    Parameters
    ----------
    A : (N, N) sparse tensor
        Real or complex, not necessarily Hermitian (e.g. :math:`L_c`, or :math:`-D_\omega`).
    M : (N, N) sparse tensor, (N,) tensor or None
        Real symmetric positive definite mass matrix, its diagonal (e.g. :math:`M_z`), or
        the identity.
    z0 : (N,) or (N, C) tensor
        Initial values, same precision as ``A``.
    t : float or 0-d tensor
        Time; gradients flow to it when it is a tensor requiring grad.

    Returns
    -------
    z : (N,) or (N, C) tensor
        Complex if ``A`` or ``z0`` is complex.

    Notes
    -----
    Gradients with respect to ``z0`` and ``t`` are exact; with respect to the values of
    ``A`` and ``M`` they use quadrature accurate to about ``1e-13`` relative (see the
    module docstring), costing ``O(t ||M^{-1}A||_1)`` exponential actions.
    """
    a_data, m_data, t = _prepare(A, M, z0, t)
    return _ExpmMultiply.apply(a_data.values, m_data.values, z0, t, a_data, m_data)


def implicit_euler(
    A: torch.Tensor,
    M: torch.Tensor | None,
    z0: torch.Tensor,
    t: float | torch.Tensor,
    steps: int = 1,
) -> torch.Tensor:
    r"""``steps`` backward-Euler steps of :math:`M \dot z = -A z` up to time ``t``.

    .. math::
        z_{k+1} = (M + hA)^{-1} M z_k, \qquad h = t / \text{steps}

    One factorization of :math:`M + hA` serves all steps and their backward passes.
    Differentiable with respect to the values of ``A`` and ``M``, ``z0`` and ``t``.

    Parameters
    ----------
    A : (N, N) sparse tensor
    M : (N, N) sparse tensor, (N,) tensor or None
    z0 : (N,) or (N, C) tensor
    t : float or 0-d tensor
    steps : int
        Number of steps, ``>= 1``.
    """
    if not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps}")
    a_data, m_data, t = _prepare(A, M, z0, t)
    dtype = a_data.dtype
    h = (t / steps).to(dtype)
    idx = torch.cat([a_data.indices, m_data.indices], dim=1)
    vals = torch.cat([h * a_data.values, m_data.values.to(dtype)])
    K = torch.sparse_coo_tensor(idx, vals, (a_data.n, a_data.n))
    solver = SparseSolver(K)
    z = z0
    for _ in range(steps):
        z = solver.solve(m_data.matmul(z))
    return z
