"""Validation and conversion helpers shared by the linear-algebra routines.

Every public routine of :mod:`torch_edgevf.linalg` validates its tensors here, once, and
works afterwards on a :class:`SparseData`: the coalesced indices and the values of a
square sparse matrix.  The values keep their autograd history (``A.coalesce().values()``
is differentiable), so the custom autograd Functions take the *values* as input and
return the gradient on the sparsity pattern only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import torch

from .._dtypes import real_dtype

_FLOAT_DTYPES = (torch.float32, torch.float64, torch.complex64, torch.complex128)


@dataclass(frozen=True)
class SparseData:
    """Coalesced COO data of a square sparse matrix.

    Attributes
    ----------
    indices : (2, nnz) int64 tensor
        Row and column of every stored entry, sorted row-major, no duplicates.
    values : (nnz,) tensor
        The stored entries; keeps the autograd history of the input matrix.
    n : int
        The matrix is ``(n, n)``.
    """

    indices: torch.Tensor
    values: torch.Tensor
    n: int

    @property
    def row(self) -> torch.Tensor:
        return self.indices[0]

    @property
    def col(self) -> torch.Tensor:
        return self.indices[1]

    @property
    def dtype(self) -> torch.dtype:
        return self.values.dtype

    @property
    def is_complex(self) -> bool:
        return self.values.is_complex()

    def is_diagonal(self) -> bool:
        return bool(torch.equal(self.row, self.col))

    def to_scipy(self) -> sp.csr_matrix:
        """The matrix as a SciPy CSR matrix (detached, on the CPU, same dtype).

        Built directly from the coalesced (row-major, duplicate-free) indices: no sort,
        a third of the time of SciPy's COO conversion.
        """
        idx = self.indices.cpu().numpy()
        vals = self.values.detach().cpu().resolve_conj().resolve_neg().numpy()
        indptr = np.zeros(self.n + 1, dtype=idx.dtype)
        np.cumsum(np.bincount(idx[0], minlength=self.n), out=indptr[1:])
        return sp.csr_matrix((vals, idx[1], indptr), shape=(self.n, self.n))

    def matmul(self, x: torch.Tensor) -> torch.Tensor:
        """Differentiable product ``A @ x`` for ``x`` of shape ``(n,)`` or ``(n, C)``."""
        vals = self.values if x.dim() == 1 else self.values[:, None]
        dtype = torch.promote_types(self.dtype, x.dtype)
        prod = vals.to(dtype) * x.to(dtype)[self.col]
        out = torch.zeros((self.n,) + tuple(x.shape[1:]), dtype=dtype, device=x.device)
        return out.index_add(0, self.row, prod)


_OUTER_CHUNK = 1 << 18


def pattern_outer(left: torch.Tensor, right: torch.Tensor, data: SparseData) -> torch.Tensor:
    r"""Entries :math:`\sum_c l_{ic} \bar r_{jc}` of :math:`l r^H` on the pattern of ``data``.

    ``left`` and ``right`` are ``(N,)`` or ``(N, C)``; the result is ``(nnz,)``, aligned
    with ``data.values``.  The rows are gathered in chunks of about ``2**18`` numbers, so
    that no ``(nnz, C)`` temporary is formed (on the CPU through NumPy, whose gathers and
    fused multiply-sum are several times faster here than the equivalent torch ops).
    Not differentiable (used inside backward passes).
    """
    dtype = torch.promote_types(left.dtype, right.dtype)
    if left.device.type != "cpu":
        prod = left.to(dtype)[data.row] * right.to(dtype)[data.col].conj()
        return prod if prod.dim() == 1 else prod.sum(-1)
    row = data.indices[0].numpy()
    col = data.indices[1].numpy()
    np_dtype = torch.empty(0, dtype=dtype).numpy().dtype
    lft = to_numpy(left).astype(np_dtype, copy=False)
    rgt = np.conj(to_numpy(right)).astype(np_dtype, copy=False)
    if lft.ndim == 1:
        return torch.from_numpy(np.take(lft, row) * np.take(rgt, col))
    lft, rgt = np.ascontiguousarray(lft), np.ascontiguousarray(rgt)
    out = np.empty(row.size, dtype=np_dtype)
    step = max(1, _OUTER_CHUNK // max(1, lft.shape[1]))
    for s in range(0, row.size, step):
        a = np.take(lft, row[s : s + step], axis=0)
        b = np.take(rgt, col[s : s + step], axis=0)
        np.einsum("nk,nk->n", a, b, out=out[s : s + step])
    return torch.from_numpy(out)


class _SparseMatrix(torch.autograd.Function):
    """``torch.sparse_coo_tensor`` on coalesced indices, with a gather-only backward."""

    @staticmethod
    def forward(ctx, indices, values, size):
        ctx.indices, ctx.size = indices, size
        return torch.sparse_coo_tensor(indices, values, size, is_coalesced=True, check_invariants=False)

    @staticmethod
    def backward(ctx, grad):
        idx = ctx.indices
        if grad.layout == torch.sparse_coo:
            gi = grad._indices()
            if grad.is_coalesced() and (gi.data_ptr() == idx.data_ptr() or torch.equal(gi, idx)):
                return None, grad._values(), None  # same pattern: the values are the gradient
            mask = torch.sparse_coo_tensor(
                idx,
                torch.ones(idx.shape[1], dtype=grad.dtype, device=idx.device),
                ctx.size,
                is_coalesced=True,
                check_invariants=False,
            )
            return None, grad.coalesce().sparse_mask(mask)._values(), None
        if grad.layout != torch.strided:
            grad = grad.to_dense()
        return None, grad[idx[0], idx[1]], None


def sparse_matrix(
    indices: torch.Tensor, values: torch.Tensor, size, *, assume_sorted: bool = False
) -> torch.Tensor:
    """Sparse COO matrix from ``indices`` (2, nnz) and ``values`` (nnz,), with a cheap backward.

    Same result as ``torch.sparse_coo_tensor(indices, values, size).coalesce()``.  When
    the indices are already coalesced (sorted row-major, no duplicates; checked here in
    O(nnz)), the backward to ``values`` is a plain read of the gradient on the pattern,
    where torch's own constructor backward runs a ``sparse_mask`` that costs several
    sparse solves.  Use it to build
    matrices that are then differentiated through :func:`~torch_edgevf.linalg.solve` or
    :func:`~torch_edgevf.linalg.eigsh`.

    ``assume_sorted=True`` skips the shape and order checks: the caller guarantees
    coalesced indices (the fixed sparsity patterns of :mod:`torch_edgevf.operators`).
    """
    n_rows, n_cols = int(size[0]), int(size[1])
    if assume_sorted:
        return _SparseMatrix.apply(indices, values, (n_rows, n_cols))
    if (
        indices.dim() != 2
        or indices.shape[0] != 2
        or values.dim() != 1
        or values.shape[0] != indices.shape[1]
    ):
        raise ValueError(
            f"indices must be (2, nnz) and values (nnz,), got {tuple(indices.shape)} "
            f"and {tuple(values.shape)}"
        )
    lin = indices[0] * n_cols + indices[1]
    if lin.numel() > 1 and not bool((lin[1:] > lin[:-1]).all()):
        return torch.sparse_coo_tensor(indices, values, (n_rows, n_cols)).coalesce()
    return _SparseMatrix.apply(indices, values, (n_rows, n_cols))


def check_finite(x: torch.Tensor, name: str) -> None:
    """Raise ``ValueError`` if ``x`` holds NaN or Inf.

    On the CPU through NumPy, which checks complex arrays faster than ``torch.isfinite``.
    """
    x = x.detach()
    if x.device.type == "cpu" and x.dtype in _FLOAT_DTYPES:
        finite = bool(np.isfinite(x.resolve_conj().resolve_neg().numpy()).all())
    else:
        finite = bool(torch.isfinite(x).all())
    if not finite:
        raise ValueError(f"{name} contains NaN or Inf")


def _check_dtype(x: torch.Tensor, name: str) -> None:
    if x.dtype not in _FLOAT_DTYPES:
        raise ValueError(f"{name} must be float32, float64, complex64 or complex128, got {x.dtype}")


def as_sparse(A: torch.Tensor, name: str = "A") -> SparseData:
    """Validate a square sparse matrix and return its coalesced data.

    Parameters
    ----------
    A : (N, N) tensor
        Sparse COO (preferred), sparse CSR/CSC or dense.  Floating or complex dtype.
    name : str
        Used in error messages.

    Raises
    ------
    TypeError
        If ``A`` is not a tensor.
    ValueError
        If ``A`` is not a square matrix, has an unsupported dtype, dense (hybrid)
        dimensions, or NaN/Inf entries.
    """
    if not isinstance(A, torch.Tensor):
        raise TypeError(f"{name} must be a torch tensor, got {type(A).__name__}")
    if A.dim() != 2:
        raise ValueError(f"{name} must be a 2-D matrix, got shape {tuple(A.shape)}")
    if A.shape[0] != A.shape[1]:
        raise ValueError(f"{name} must be square, got shape {tuple(A.shape)}")
    _check_dtype(A, name)
    if A.layout == torch.strided:
        A = A.to_sparse()
    elif A.layout != torch.sparse_coo:
        A = A.to_sparse_coo()
    if A.dense_dim() != 0:
        raise ValueError(f"{name} must not have dense (hybrid) dimensions")
    A = A.coalesce()
    values = A.values()
    check_finite(values, name)
    return SparseData(A.indices(), values, int(A.shape[0]))


def as_matrix_pair(A: torch.Tensor, M: torch.Tensor | None) -> tuple[SparseData, SparseData]:
    """Validate the pair ``(A, M)`` of a generalized problem ``A x = lambda M x``.

    ``A`` is a square sparse matrix (:func:`as_sparse`); ``M`` a real mass matrix of the
    same size and precision, sparse or as its diagonal, the identity when None.
    """
    a_data = as_sparse(A, "A")
    n = a_data.n
    if M is None:
        M = torch.ones(n, dtype=real_dtype(a_data.dtype), device=a_data.values.device)
    m_data = as_diagonal_or_sparse(M, n, "M")
    if real_dtype(m_data.dtype) != real_dtype(a_data.dtype):
        raise ValueError(f"M has dtype {m_data.dtype} but A has dtype {a_data.dtype}")
    return a_data, m_data


def to_scipy(A: torch.Tensor, name: str = "A") -> sp.csr_matrix:
    """A square torch sparse (or dense) matrix as a SciPy CSR matrix (detached, CPU, same dtype)."""
    return as_sparse(A, name).to_scipy()


def as_diagonal_or_sparse(M: torch.Tensor, n: int, name: str = "M") -> SparseData:
    """Validate a real mass matrix, given sparse ``(N, N)`` or as its diagonal ``(N,)``."""
    if isinstance(M, torch.Tensor) and M.dim() == 1 and M.layout == torch.strided:
        _check_dtype(M, name)
        idx = torch.arange(M.shape[0], device=M.device).expand(2, -1)
        data = SparseData(idx, M, int(M.shape[0]))
        check_finite(M, name)
    else:
        data = as_sparse(M, name)
    if data.n != n:
        raise ValueError(f"{name} has size {data.n} but A has size {n}")
    if data.is_complex:
        raise ValueError(f"{name} must be real, got {data.dtype}")
    return data


def check_rhs(b: torch.Tensor, n: int, dtype: torch.dtype, name: str = "b") -> None:
    """Validate a right-hand side ``(N,)`` or ``(N, C)`` against a matrix of size ``n``."""
    if not isinstance(b, torch.Tensor):
        raise TypeError(f"{name} must be a torch tensor, got {type(b).__name__}")
    if b.dim() not in (1, 2) or b.shape[0] != n:
        raise ValueError(f"{name} must have shape ({n},) or ({n}, C), got {tuple(b.shape)}")
    _check_dtype(b, name)
    if real_dtype(b.dtype) != real_dtype(dtype):
        raise ValueError(
            f"{name} has dtype {b.dtype} but the matrix has dtype {dtype}; "
            "use the same precision (float32/complex64 or float64/complex128)"
        )
    check_finite(b, name)


def is_hermitian(K: sp.spmatrix, rtol: float | None = None) -> bool:
    """Whether the SciPy matrix ``K`` equals its conjugate transpose up to ``rtol``."""
    if rtol is None:
        rtol = 100 * float(np.finfo(K.dtype).eps)
    scale = abs(K).max() if K.nnz else 0.0
    diff = K - K.conj().T
    return (abs(diff).max() if diff.nnz else 0.0) <= rtol * scale


def to_numpy(x: torch.Tensor) -> np.ndarray:
    """Detached NumPy view/copy of ``x`` (on the CPU, conjugation resolved)."""
    return x.detach().cpu().resolve_conj().resolve_neg().numpy()


def from_numpy(x: np.ndarray, like: torch.Tensor, dtype: torch.dtype | None = None) -> torch.Tensor:
    """Tensor from a NumPy array on the device of ``like`` with ``dtype``."""
    return torch.from_numpy(np.ascontiguousarray(x)).to(device=like.device, dtype=dtype)


def blas_single_thread(fn):
    """Run ``fn`` with one BLAS thread.

    The dense steps of the iterative solvers work on tall, thin blocks, where BLAS threads
    only add synchronisation, and on a busy machine, or beside torch's own OpenMP threads,
    oversubscribed BLAS threads wait for each other.
    """
    import functools

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with _blas_controller().limit(limits=1, user_api="blas"):
            return fn(*args, **kwargs)

    return wrapper


_CONTROLLER = None


def _blas_controller():
    """One ``threadpoolctl.ThreadpoolController`` for the process.

    ``threadpool_limits`` inspects every loaded shared library on each call (as long as a
    small solve); the controller does it once.  BLAS is loaded with
    NumPy/SciPy, long before the first call.
    """
    global _CONTROLLER
    if _CONTROLLER is None:
        from threadpoolctl import ThreadpoolController

        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER
