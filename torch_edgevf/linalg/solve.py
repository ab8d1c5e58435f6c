r"""Differentiable sparse solves, plain and constrained.

For :math:`x = A^{-1} b` and an upstream gradient :math:`g = \partial L / \partial \bar x`
(PyTorch's conjugate Wirtinger convention), the backward pass is one adjoint solve with
the same factor,

.. math::
    \lambda = A^{-H} g, \qquad
    \frac{\partial L}{\partial \bar b} = \lambda, \qquad
    \frac{\partial L}{\partial \bar A_{ij}} = -\lambda_i \, \bar x_j
    \quad \text{for } (i, j) \text{ in the pattern of } A,

summed over the columns of a block right-hand side (real part for real inputs).  The
gradient with respect to ``A`` is a dense ``(nnz,)`` vector aligned with the coalesced
values of ``A``; a dense ``(N, N)`` matrix is never formed.
"""

from __future__ import annotations

import torch

from .._dtypes import complex_dtype
from ._utils import (
    SparseData,
    as_sparse,
    check_finite,
    check_rhs,
    from_numpy,
    pattern_outer,
    to_numpy,
)
from .factor import factorize


def _pattern_outer(left: torch.Tensor, right: torch.Tensor, data: SparseData) -> torch.Tensor:
    r"""Entries :math:`\sum_c l_{ic} \bar r_{jc}` of :math:`l r^H` on the pattern of ``data``."""
    return pattern_outer(left, right, data).to(left.device)


def _as_input_dtype(grad: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """Real part when ``like`` is real (the gradient with respect to a real input)."""
    return grad if like.is_complex() else grad.real.to(like.dtype)


class _Solve(torch.autograd.Function):
    """``x = A^{-1} b`` (or ``A^{-H} b``) with a precomputed factor of ``A``."""

    @staticmethod
    def forward(ctx, values, b, solver: SparseSolver, adjoint: bool):
        dtype = complex_dtype(solver.dtype) if b.is_complex() else solver.dtype
        x = from_numpy(solver.factor.solve(to_numpy(b), adjoint), b, dtype)
        ctx.solver, ctx.adjoint = solver, adjoint
        ctx.save_for_backward(values, b, x)
        return x

    @staticmethod
    def backward(ctx, g):
        values, b, x = ctx.saved_tensors
        solver = ctx.solver
        lam = from_numpy(solver.factor.solve(to_numpy(g), not ctx.adjoint), g, x.dtype)
        grad_values = grad_b = None
        if ctx.needs_input_grad[0]:
            # (the sign goes on an (N,) vector, not on the (nnz,) result)
            if ctx.adjoint:  # x = A^{-H} b:  dL/dA_ij = -x_i conj(lam_j)
                grad_values = _pattern_outer(-x, lam, solver.data)
            else:
                grad_values = _pattern_outer(-lam, x, solver.data)
            grad_values = _as_input_dtype(grad_values, values)
        if ctx.needs_input_grad[1]:
            grad_b = _as_input_dtype(lam, b)
        return grad_values, grad_b, None, None


def solve(
    A: torch.Tensor | SparseSolver,
    b: torch.Tensor,
    *,
    adjoint: bool = False,
    method: str = "auto",
    hermitian: bool | None = None,
) -> torch.Tensor:
    r"""Solve :math:`A x = b` (or :math:`A^H x = b`), differentiably.

    Parameters
    ----------
    A : (N, N) sparse tensor or SparseSolver
        A sparse matrix (factored here) or a prefactored :class:`SparseSolver`, whose
        factor is then reused both forward and backward.
    b : (N,) or (N, C) tensor
        Right-hand side(s), same precision as ``A``; may be complex for a real ``A``.
    adjoint : bool
        Solve with :math:`A^H` instead of :math:`A`.
    method, hermitian
        Passed to :class:`SparseSolver` when ``A`` is a tensor.

    Returns
    -------
    x : (N,) or (N, C) tensor
        Dtype of ``A``, complex if ``b`` is complex.

    Raises
    ------
    ValueError
        Non-square ``A``, mismatched shapes or precisions, NaN/Inf inputs, a singular
        ``A``, or ``method="cholesky"`` with an indefinite or non-Hermitian ``A``.
    """
    solver = A if isinstance(A, SparseSolver) else SparseSolver(A, method, hermitian)
    check_rhs(b, solver.n, solver.dtype)
    return _Solve.apply(solver.data.values, b, solver, adjoint)


def _restrict(data: SparseData, rows: torch.Tensor, cols: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Block ``A[rows][:, cols]``: ``(indices (2, nnz'), values (nnz',))``, values differentiable."""
    new_row = torch.full((data.n,), -1, dtype=torch.long, device=data.indices.device)
    new_col = new_row.clone()
    new_row[rows] = torch.arange(rows.numel(), device=rows.device)
    new_col[cols] = torch.arange(cols.numel(), device=cols.device)
    r, c = new_row[data.row], new_col[data.col]
    keep = (r >= 0) & (c >= 0)
    return torch.stack([r[keep], c[keep]]), data.values[keep]


def _block_matmul(indices, values, x: torch.Tensor, rows: int) -> torch.Tensor:
    """Differentiable product of a rectangular sparse block with ``x`` (N,) or (N, C)."""
    vals = values if x.dim() == 1 else values[:, None]
    dtype = torch.promote_types(values.dtype, x.dtype)
    out = torch.zeros((rows,) + tuple(x.shape[1:]), dtype=dtype, device=x.device)
    return out.index_add(0, indices[0], vals.to(dtype) * x.to(dtype)[indices[1]])


def _check_index(idx: torch.Tensor, n: int, name: str) -> torch.Tensor:
    if not isinstance(idx, torch.Tensor) or idx.dtype != torch.long or idx.dim() != 1:
        raise ValueError(f"{name} must be a 1-D int64 tensor")
    if idx.numel() and (int(idx.min()) < 0 or int(idx.max()) >= n):
        raise ValueError(f"{name} has entries outside [0, {n})")
    if torch.unique(idx).numel() != idx.numel():
        raise ValueError(f"{name} has repeated entries")
    return idx


def solve_fixed(
    A: torch.Tensor,
    b: torch.Tensor,
    fixed_idx: torch.Tensor,
    fixed_values: torch.Tensor,
    *,
    method: str = "auto",
) -> torch.Tensor:
    r"""Solve :math:`A x = b` with :math:`x_C` prescribed, by elimination.

    With :math:`F` the free and :math:`C` the fixed unknowns,

    .. math::
        A_{FF} \, x_F = b_F - A_{FC} \, x_C, \qquad x_C = \text{fixed\_values},

    and the rows :math:`C` of the system are dropped.  Differentiable with respect to
    ``A``'s values, ``b`` and ``fixed_values`` (through :func:`solve`).

    Parameters
    ----------
    A : (N, N) sparse tensor
    b : (N,) or (N, C) tensor
    fixed_idx : (K,) int64 tensor
        Distinct indices of the prescribed unknowns.
    fixed_values : (K,) or (K, C) tensor
        Their values (broadcast to the columns of ``b``).

    Returns
    -------
    x : (N,) or (N, C) tensor, with ``x[fixed_idx] == fixed_values``.
    """
    data = as_sparse(A, "A")
    check_rhs(b, data.n, data.dtype)
    fixed = _check_index(fixed_idx, data.n, "fixed_idx")
    check_finite(fixed_values, "fixed_values")
    if fixed_values.shape[0] != fixed.numel():
        raise ValueError(f"fixed_values has {fixed_values.shape[0]} rows but fixed_idx has {fixed.numel()}")
    is_free = torch.ones(data.n, dtype=torch.bool, device=fixed.device)
    is_free[fixed] = False
    free = torch.nonzero(is_free).squeeze(1)
    dtype = torch.promote_types(torch.promote_types(data.dtype, b.dtype), fixed_values.dtype)
    xc = fixed_values.to(dtype)
    if b.dim() == 2 and xc.dim() == 1:
        xc = xc[:, None].expand(-1, b.shape[1])
    fc_idx, fc_val = _restrict(data, free, fixed)
    rhs = b.to(dtype)[free] - _block_matmul(fc_idx, fc_val, xc, free.numel())
    ff_idx, ff_val = _restrict(data, free, free)
    a_ff = torch.sparse_coo_tensor(ff_idx, ff_val, (free.numel(), free.numel()), is_coalesced=True)
    x_f = solve(a_ff, rhs, method=method)
    x = torch.zeros(b.shape, dtype=x_f.dtype, device=b.device)
    return x.index_put((free,), x_f).index_put((fixed,), xc.to(x_f.dtype))


def solve_constrained(
    A: torch.Tensor,
    b: torch.Tensor,
    C: torch.Tensor,
    d: torch.Tensor,
    *,
    return_multipliers: bool = False,
):
    r"""Solve :math:`A x = b` subject to :math:`C x = d` through the KKT system.

    .. math::
        \begin{pmatrix} A & C^H \\ C & 0 \end{pmatrix}
        \begin{pmatrix} x \\ \mu \end{pmatrix} =
        \begin{pmatrix} b \\ d \end{pmatrix}

    For Hermitian positive definite ``A`` this minimises :math:`\tfrac12 x^H A x -
    \mathrm{Re}(b^H x)` over :math:`C x = d`.  The KKT matrix is indefinite and is
    factored with SuperLU (LU).  Differentiable with respect to the values of ``A`` and
    ``C``, ``b`` and ``d``.

    Parameters
    ----------
    A : (N, N) sparse tensor
    b : (N,) or (N, K) tensor
    C : (m, N) sparse tensor
        Full row rank; same dtype family as ``A``.
    d : (m,) or (m, K) tensor
    return_multipliers : bool
        Also return :math:`\mu` of shape (m,) or (m, K).
    """
    data = as_sparse(A, "A")
    check_rhs(b, data.n, data.dtype)
    if not isinstance(C, torch.Tensor) or C.dim() != 2 or C.shape[1] != data.n:
        raise ValueError(f"C must be a (m, {data.n}) matrix, got {getattr(C, 'shape', None)}")
    Cs = (C if C.layout == torch.sparse_coo else C.to_sparse()).coalesce()
    m = int(Cs.shape[0])
    if d.shape[:1] != (m,) or d.dim() != b.dim():
        raise ValueError(f"d must have shape ({m},) or ({m}, K) like b, got {tuple(d.shape)}")
    dtype = torch.promote_types(
        torch.promote_types(data.dtype, Cs.dtype), torch.promote_types(b.dtype, d.dtype)
    )
    ci, cv = Cs.indices(), Cs.values().to(dtype)
    shift = torch.tensor([[data.n], [0]], device=ci.device)
    idx = torch.cat([data.indices, ci + shift, ci.flip(0) + shift.flip(0)], dim=1)
    vals = torch.cat([data.values.to(dtype), cv, cv.conj()])
    kkt = torch.sparse_coo_tensor(idx, vals, (data.n + m, data.n + m))
    sol = solve(kkt, torch.cat([b.to(dtype), d.to(dtype)]), method="lu")
    x, mu = sol[: data.n], sol[data.n :]
    return (x, mu) if return_multipliers else x


class SparseSolver:
    r"""A sparse matrix factored once, for many solves.

    Parameters
    ----------
    A : (N, N) sparse tensor
        Real or complex; coalesced COO preferred.  Its values may require grad: solves
        through :func:`torch_edgevf.linalg.solve` (or :meth:`solve`) then differentiate
        with respect to them, on the sparsity pattern.
    method : {"auto", "cholesky", "lu"}
        See :func:`factorize`.  ``"auto"`` uses a Cholesky-type factorization for
        Hermitian positive definite ``A`` (CHOLMOD if installed, else SuperLU symmetric
        mode) and SuperLU LU otherwise.
    hermitian : bool, optional
        Declare ``A`` Hermitian (``A = A^H``); detected when ``None``.  For a Hermitian
        matrix the adjoint solve reuses the factor as is.

    Attributes
    ----------
    backend : str
        ``"cholmod"``, ``"cholmod-cvxopt"``, ``"superlu-hermitian"`` or ``"superlu"`` (``"cholespy"``
        only in the eigensolver).
    hermitian : bool

    Examples
    --------
    >>> solver = SparseSolver(L + 1e-3 * M)     # doctest: +SKIP
    >>> x = solver.solve(b)                      # doctest: +SKIP
    """

    def __init__(self, A: torch.Tensor, method: str = "auto", hermitian: bool | None = None):
        self.data = as_sparse(A, "A")
        self.factor = factorize(self.data.to_scipy(), method, hermitian)
        self.hermitian = self.factor.hermitian or bool(hermitian)
        self.backend = self.factor.backend

    @property
    def n(self) -> int:
        return self.data.n

    @property
    def shape(self) -> tuple[int, int]:
        return (self.data.n, self.data.n)

    @property
    def dtype(self) -> torch.dtype:
        return self.data.dtype

    def solve(self, b: torch.Tensor) -> torch.Tensor:
        """``x = A^{-1} b`` for ``b`` of shape (N,) or (N, C); differentiable."""
        return solve(self, b)

    def solve_adjoint(self, b: torch.Tensor) -> torch.Tensor:
        """``x = A^{-H} b`` with the same factor; differentiable."""
        return solve(self, b, adjoint=True)

    def __repr__(self) -> str:
        return f"SparseSolver(n={self.n}, dtype={self.dtype}, backend={self.backend!r})"
