r"""The driver of :func:`~torch_edgevf.linalg.eigsh`, on NumPy and SciPy arrays.

What is around the Lanczos engine (:mod:`.lanczos`): the pair normalised by powers of two
(:func:`normalize_pair`), the default shift (:func:`default_shift`), the choice and the
checks of the dense path (:func:`dense_is_faster`, :func:`eig_dense`), and
:func:`shift_invert_eigsh`, which factors :math:`A - \sigma M` (scaled by :math:`M^{-1/2}`
for a diagonal :math:`M`), runs the engine and ends with a Rayleigh-Ritz step on
:math:`(A, M)`.

Phase convention (:func:`fix_phase`): each eigenvector is scaled by a unit number so that
its entry of largest modulus is real and positive (a sign for real problems).
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from .factor import factorize
from .lanczos import Unreliable, _better_of, _Inner, _lanczos, _smallest_pair

logger = logging.getLogger(__package__ + ".lanczos")  # the iteration log, under the engine's name

__all__ = [
    "METHODS",
    "PairScaling",
    "default_shift",
    "dense_is_faster",
    "eig_dense",
    "fix_phase",
    "normalize_pair",
    "shift_invert_eigsh",
]


#: residual bound of the dense path, in units of sqrt(eps) times the eigenvalue scale
_DENSE_RESIDUAL = 100.0


METHODS = ("auto", "lanczos", "dense")
_DENSE_MAX = 300
_DENSE_MAX_MANY = 4000  # (a dense complex matrix of this size: 256 MB)
_MAX_BLOCK = 6
#: from this many eigenpairs on, the Lanczos block starts at its largest size: with a large
#: basis, fewer solves of more vectors each cost less (128 pairs of the Laplacian of a
#: 5,000-vertex RNA surface: 12-18% less time; 32 pairs: 15% more)
_LARGE_K = 64
_SHIFT_EPS = 1e-5


def dense_is_faster(n, k):
    """``method="auto"``: dense ``eigh`` for ``n <= 300``, or where ``k`` is a large part of
    ``n`` (``n <= 8 k``, the Lanczos basis ``3 k`` then at least three eighths of ``n``) up
    to ``n = 4000``, where a dense decomposition of the whole matrix costs less than the
    Lanczos basis and its reorthogonalization."""
    return n <= _DENSE_MAX or (n <= 8 * k and n <= _DENSE_MAX_MANY)


# ----------------------------------------------------------------------------- forward


def diagonal_ratio(A: sp.spmatrix, M: sp.spmatrix) -> np.ndarray:
    """``|A_ii| / |M_ii|`` per row (``M_ii`` floored at the smallest normal number): its
    median is about the top of a mesh's spectrum, its outliers mark nearly degenerate faces."""
    return np.abs(A.diagonal()) / np.maximum(np.abs(M.diagonal()), np.finfo(M.dtype).tiny)


def default_shift(A: sp.spmatrix, M: sp.spmatrix) -> float:
    """Small negative shift :math:`-\\epsilon\\, \\mathrm{median}_i A_{ii}/M_{ii}`.

    :math:`\\epsilon = 10^{-5}` in double precision (``1e-3`` in single).  The median, not
    the maximum: one needle face makes ``max A_ii / M_ii`` many orders of magnitude above
    the low spectrum, and shift-invert Lanczos then stalls.  The median ratio is of the
    order of the top of the spectrum, so :math:`\\epsilon` bounds the condition number of
    :math:`A - \\sigma M` for a singular ``A`` (about :math:`1/\\epsilon`); the smaller it is,
    the closer the shift to the wanted eigenvalues and the faster the convergence.
    """
    ratio = diagonal_ratio(A, M)
    scale = float(np.median(ratio)) if ratio.size else 1.0
    eps = 1e-3 if np.finfo(A.dtype).bits <= 32 else _SHIFT_EPS
    return -eps * (scale if scale > 0 else 1.0)


def ldexp(x: np.ndarray, e: int) -> np.ndarray:
    """``x * 2**e``, real or complex, dtype kept: exact wherever the result is a normal number."""
    x = np.asarray(x)
    if np.iscomplexobj(x):
        out = np.empty_like(x)
        out.real = np.ldexp(x.real, e)
        out.imag = np.ldexp(x.imag, e)
        return out
    return np.ldexp(x, e).astype(x.dtype, copy=False)


def binary_exponent(x: float) -> int:
    """The binary exponent ``e`` with ``x = f 2^e``, ``1/2 <= |f| < 1`` (0 for 0, inf or NaN)."""
    return int(np.frexp(x)[1]) if x != 0 and np.isfinite(x) else 0


class PairScaling(NamedTuple):
    r"""The powers of two of :func:`normalize_pair`: :math:`A = 2^a A'`, :math:`M = 2^m M'`, ``m`` even.

    :math:`A x = \lambda M x` if and only if :math:`A' x = \lambda' M' x` with
    :math:`\lambda = 2^{a - m} \lambda'`; :math:`M'`-orthonormal vectors :math:`X'` give the
    :math:`M`-orthonormal :math:`X = 2^{-m/2} X'`.
    """

    a_exp: int
    m_exp: int

    def values(self, lam_n: np.ndarray) -> np.ndarray:
        """Eigenvalues of ``(A, M)`` from those of the normalised pair."""
        return ldexp(lam_n, self.a_exp - self.m_exp)

    def vectors(self, X_n: np.ndarray) -> np.ndarray:
        """``M``-orthonormal eigenvectors from ``M'``-orthonormal ones."""
        return ldexp(X_n, -self.m_exp // 2)

    def normalized_values(self, lam: np.ndarray) -> np.ndarray:
        return ldexp(lam, self.m_exp - self.a_exp)

    def normalized_vectors(self, X: np.ndarray) -> np.ndarray:
        return ldexp(X, self.m_exp // 2)

    def normalized_shift(self, sigma: float) -> float:
        r"""The shift :math:`\sigma' = 2^{m - a} \sigma` of the normalised pair."""
        return float(np.ldexp(sigma, self.m_exp - self.a_exp))


def normalize_pair(A: sp.spmatrix, M: sp.spmatrix) -> tuple[sp.csr_matrix, sp.csr_matrix, PairScaling]:
    r"""The pencil divided by powers of two, :math:`A' = 2^{-a} A`, :math:`M' = 2^{-m} M`.

    ``m`` (even) brings :math:`\max |M_{ij}|` into :math:`[1/2, 2)`, ``a`` the median of
    :math:`|A'_{ii}| / |M'_{ii}|` (the scale of the spectrum, as in :func:`default_shift`)
    into :math:`[1/2, 1)`; where that median is 0, ``a`` scales :math:`\max |A_{ij}|`.  The
    scaling is exact in floating point, so the eigenproblem of a mesh scaled by :math:`s`
    -- :math:`L_c` unchanged, :math:`M_z \propto s^2`, eigenvalues :math:`\propto s^{-2}`
    -- is the same as at :math:`s = 1` up to a factor in :math:`[1/2, 2]` and the rounding
    of the operators: no inner product, squared norm or factor of the solver under- or
    overflows, and its tolerances, floors and shift act on the same numbers at every
    scale.  Undo it with :class:`PairScaling`.
    """
    A, M = sp.csr_matrix(A), sp.csr_matrix(M)
    m_max = float(np.max(np.abs(M.data))) if M.nnz else 0.0
    m_exp = 2 * (binary_exponent(m_max) // 2)
    Mn = M.copy()
    Mn.data = ldexp(M.data, -m_exp)
    md = np.abs(Mn.diagonal())
    ratio = np.abs(A.diagonal())[md > 0] / md[md > 0]
    scale = float(np.median(ratio)) if ratio.size else 0.0
    if not (scale > 0 and np.isfinite(scale)):
        scale = float(np.max(np.abs(A.data))) if A.nnz else 0.0
    a_exp = binary_exponent(scale)
    An = A.copy()
    An.data = ldexp(A.data, -a_exp)
    return An, Mn, PairScaling(a_exp, m_exp)


def _rayleigh_ritz(A, M, X):
    """Eigenpairs of the projected pencil ``(X^H A X, X^H M X)``, ascending."""
    ha, hm = X.conj().T @ (A @ X), X.conj().T @ (M @ X)
    lam, C = scipy.linalg.eigh((ha + ha.conj().T) / 2, (hm + hm.conj().T) / 2)
    return lam, X @ C


def fix_phase(X: np.ndarray) -> np.ndarray:
    """Scale each column so that its largest-modulus entry is real positive."""
    p = np.argmax(np.abs(X), axis=0)
    pivot = X[p, np.arange(X.shape[1])]
    return X * (np.abs(pivot) / pivot)


def eig_dense(A, M, k):
    """The ``k`` smallest eigenpairs of ``(A, M)`` by a dense decomposition.

    For a positive diagonal ``M`` (the lumped masses) the standard problem of
    :math:`M^{-1/2} A M^{-1/2}` with LAPACK's MRRR driver (``evr``), then :math:`X =
    M^{-1/2} U`: 1.3-1.4x faster than the generalized problem (128 pairs at ``n = 1,000``);
    else the generalized ``eigh``.
    """
    mdiag = _diagonal(M)
    if mdiag is None or not np.all(mdiag > 0):
        lam, X = scipy.linalg.eigh(A.toarray(), M.toarray(), subset_by_index=[0, k - 1])
        _check_dense(A, M, lam, X, None)
        return lam, X
    d = 1.0 / np.sqrt(mdiag.real)
    S = A.toarray()
    S *= d[:, None]
    S *= d[None, :]
    lam, U = scipy.linalg.eigh(S, subset_by_index=[0, k - 1], driver="evr", overwrite_a=True)
    U *= d[:, None]
    _check_dense(A, M, lam, U, d)
    return lam, U


def _check_dense(A, M, lam, X, d) -> None:
    r"""Raise :class:`Unreliable` if a residual exceeds ``100 sqrt(eps)`` of the eigenvalue scale.

    The residual :math:`\|A x - \lambda M x\|_{M^{-1}}` (``x`` :math:`M`-normalised) of
    each pair, against :math:`\max |\lambda|` over the pairs asked for (or the median of
    :math:`A_{ii} / M_{ii}` where that is larger, as for the constant mode alone, about the
    top of a mesh's spectrum). Rounding in a pencil whose entries span 15 orders of
    magnitude (a cap face's cotangent weight of ``1e13`` beside masses of ``1e-6``)
    leaves the low eigenvalues wrong by more than their size, and LAPACK's ``evr`` then
    returns pairs that are no eigenpairs, without a word. On the 380 PSB meshes the
    largest residual is ``0.13 sqrt(eps)``. A sparse product: cheap beside the
    decomposition.
    """
    R = A @ X - (M @ X) * lam
    if d is not None:  # positive diagonal M: the residual in the scaled coordinates, M^(-1/2) R
        res = np.linalg.norm(R * d[:, None], axis=0)
    else:
        res = np.sqrt(np.abs(np.sum(R.conj() * scipy.linalg.solve(M.toarray(), R, assume_a="pos"), axis=0)))
    scale = max(float(np.max(np.abs(lam))), float(np.median(diagonal_ratio(A, M))), np.finfo(lam.dtype).tiny)
    worst = float(np.max(res)) / scale
    if not worst <= _DENSE_RESIDUAL * np.sqrt(np.finfo(lam.dtype).eps):
        raise Unreliable(f"the dense solver left a residual of {worst:.1e} of the eigenvalue scale")


def _diagonal(M: sp.spmatrix):
    """The diagonal of ``M`` if ``M`` is diagonal, else ``None``."""
    M = M.tocsc()
    if M.nnz > M.shape[0] or np.any(np.diff(M.indptr) > 1):
        return None
    if M.nnz and not np.array_equal(M.indices, np.flatnonzero(np.diff(M.indptr))):
        return None
    return M.diagonal()


def _scaled_shifted(A, mdiag, d, sigma):
    r"""CSC :math:`D (A - \sigma M) D` for the diagonal :math:`M` (``mdiag``), :math:`D = M^{-1/2}` (``d``).

    Built on the CSR arrays of the Hermitian ``A``: scaled, shifted on the stored diagonal,
    and, conjugated, read as CSC arrays (those of :math:`K^H = K`), without SciPy's
    sparse sum and CSR-to-CSC conversion.  The entries are rounded as in
    ``((A - sigma M) D) D``, the shift before the scaling: the low eigenvalues come out of
    the cancellation of entries up to 1e5 times larger, so the rounding of the diagonal
    shows in them.
    """
    A = sp.csr_matrix(A)
    n = A.shape[0]
    rows = np.repeat(np.arange(n), np.diff(A.indptr))
    on_diag = rows == A.indices
    if np.count_nonzero(on_diag) != n or not A.has_canonical_format:  # (a diagonal entry missing)
        K = (A - sigma * sp.diags(mdiag, format="csr")).tocsc()
        K.data *= d[K.indices] * np.repeat(d, np.diff(K.indptr))
        return K
    scale = d[rows]
    scale *= d[A.indices]
    data = A.data * scale
    diag = np.flatnonzero(on_diag)
    data[diag] = (A.data[diag] - sigma * mdiag) * scale[diag]
    if np.iscomplexobj(data):
        np.conjugate(data, out=data)
    return sp.csc_matrix((data, A.indices, A.indptr), shape=A.shape)


class _ScaledFactor:
    """Solves with :math:`K = S \tilde K S` from a factor of :math:`\tilde K` (``S`` diagonal, ``s``)."""

    def __init__(self, factor, s):
        self.factor, self.s = factor, s

    def solve(self, b, adjoint=False):
        s = self.s if b.ndim == 1 else self.s[:, None]
        return self.factor.solve(b / s, adjoint) / s


def shift_invert_eigsh(A, M, sigma, k, *, tol, maxiter, ncv, v0, block_size):
    r"""The ``k`` smallest eigenpairs of ``(A, M)`` by shift-invert Lanczos.

    Lanczos runs on :math:`T = (A - \sigma M)^{-1} M`, self-adjoint in the :math:`M` inner
    product.  For a diagonal ``M`` (the lumped mass matrices) it runs in the coordinates
    :math:`y = M^{1/2} x`, on :math:`T = (\tilde A - \sigma I)^{-1}` with :math:`\tilde A =
    M^{-1/2} A M^{-1/2}`: the scaled matrix is factored, so that a step is a bare solve and
    the inner product Euclidean.  A final Rayleigh-Ritz step on :math:`(A, M)` gives the
    eigenvalues and :math:`M`-orthonormal vectors.  Returns ``(lam, X, factor)``, where
    ``factor.solve`` solves with :math:`A - \sigma M` (``None`` on the dense fallback).
    """
    n = A.shape[0]
    dtype = A.dtype
    max_block = block_size or min(k, _MAX_BLOCK)
    if n < k + 3 * max_block + 3:  # too small for a restarted Krylov basis
        return (*eig_dense(A, M, k), None)
    mdiag = _diagonal(M)
    # the smallest pair takes 10-20 solves: a cheaper factorization beats faster solves there
    # (cvxopt: supernodal instead of simplicial CHOLMOD; real matrices: SuperLU, not cholespy)
    many = k > 1 or block_size not in (None, 1)
    rng = np.random.default_rng(0)
    start = rng.standard_normal(n) if v0 is None else np.asarray(v0)
    start = start.reshape(n, -1)
    if mdiag is not None and np.all(mdiag > 0):
        s = np.sqrt(mdiag).astype(np.finfo(dtype).dtype)
        K = _scaled_shifted(A, mdiag, 1.0 / s, sigma)
        scaled = factorize(K, "auto", hermitian=True, many_solves=many)
        factor = _ScaledFactor(scaled, s)
        inner = _Inner(dtype)

        def op(Y):
            return np.asfortranarray(scaled.solve(Y))

        start = start * s[:, None]
    else:
        s = None
        K = (A - sigma * M).tocsc()
        factor = factorize(K, "auto", hermitian=True, many_solves=many)
        inner = _Inner(dtype, mmul=lambda W: np.asfortranarray(M @ W))

        def op(Y):
            return np.asfortranarray(factor.solve(M @ Y))

    if k == 1 and block_size in (None, 1):
        _, Y, n_op = _smallest_pair(op, inner, n, tol=tol, maxiter=maxiter, v0=start, ncv=ncv, strict=True)
        # the Ritz and the harmonic Ritz vector: the better one
        Y, KY = _better_of(Y, lambda Z: K @ Z, None if s is not None else lambda Z: M @ Z)
    else:
        KY = None
        if block_size:
            block = max_block = block_size
        else:
            max_block = min(k, _MAX_BLOCK)
            block = max_block if k >= _LARGE_K else min(k, 2)
        _, Y, n_op = _lanczos(
            op,
            inner,
            n,
            k,
            block=block,
            max_block=max_block,
            ncv=ncv or max(3 * k, 2 * k + 2 * max_block),
            tol=tol,
            maxiter=maxiter,
            v0=start,
            strict=True,
        )
    logger.debug("Lanczos: %d solves for k=%d", n_op, k)
    if s is None:
        return (*_rayleigh_ritz(A, M, Y), factor)
    # Rayleigh-Ritz in the scaled coordinates, with the matrix already at hand: for X =
    # S^-1 Y, X^H A X = Y^H (K + sigma I) Y and X^H M X = Y^H Y (K: the scaled S^-1 (A -
    # sigma M) S^-1); no new (n, k) arrays but the result
    G = inner.gram(Y)
    ha = Y.conj().T @ (K @ Y if KY is None else KY) + sigma * G
    lam, C = scipy.linalg.eigh((ha + ha.conj().T) / 2, G)  # (gram() is Hermitian already)
    X = inner.gemm(1.0, Y, C)
    X /= s[:, None]
    return lam, X, factor
