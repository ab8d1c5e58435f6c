r"""The NumPy engine of :func:`~torch_edgevf.linalg.eigsh`: smallest eigenpairs of :math:`A x = \lambda M x`.

Shift-invert block Lanczos with thick restarts on :math:`T = (A - \sigma M)^{-1} M`, which is
self-adjoint in the :math:`M` inner product; :math:`A - \sigma M` is factored once with
:func:`~torch_edgevf.linalg.factor.factorize` (Cholesky type for :math:`\sigma` below the
spectrum).  Complex Hermitian problems get a Hermitian Lanczos, not the non-Hermitian
Arnoldi that SciPy's ``eigsh`` falls back to for complex input.  The default shift is
slightly negative, :math:`\sigma = -10^{-5} s` (``1e-3 s`` in single precision), with
:math:`s = \mathrm{median}_i A_{ii} / M_{ii}`, so that :math:`A - \sigma M` is positive
definite for the (often singular) positive semidefinite Laplacians
(:func:`~.shift_invert.default_shift`; :mod:`.shift_invert` is the driver around this engine).
A final Rayleigh-Ritz step on :math:`(A, M)` makes the eigenvectors :math:`M`-orthonormal:
:math:`X^H M X = I`.

The iteration (:func:`_lanczos`): for a diagonal :math:`M` (lumped masses) it runs in the
coordinates :math:`M^{1/2} x` with the Euclidean inner product; the basis is
orthogonalized by classical Gram-Schmidt in BLAS ``gemm`` calls on a Fortran-ordered
basis: every block against the last two, and every other block a full pass that also
completes the previous block, with the Lanczos relation corrected exactly
(:func:`_deferred_pass`), so that the basis is read twice per two blocks, not per block.
Convergence is tested on a schedule (:class:`_TestSchedule`): as often as the dense
eigendecomposition of the projected matrix is cheap against a step, and never later than
half the steps that the observed rate of convergence predicts are left; a residual is
accepted below ``tol |theta|``, or at the rounding floor ``10 eps ||T||`` for ``k > 1``.
The block size starts at 2 and doubles, up to 6, each time the Ritz values show a
cluster of as many equal values as the block has columns (a multiple eigenvalue:
symmetric meshes).  ``k = 1`` has its own path,
:func:`_smallest_pair`: inverse iteration with the factor, accelerated by Rayleigh-Ritz
on its iterates, with selective instead of full reorthogonalization.  Small problems, and
those where ``k`` is a large part of ``N``, are solved dense
(:func:`~.shift_invert.dense_is_faster`).

Nothing here knows torch: arrays in, arrays out.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg
from scipy.linalg.blas import get_blas_funcs
from scipy.linalg.lapack import get_lapack_funcs

logger = logging.getLogger(__name__)


class Unreliable(RuntimeError):
    """Eigenpairs that cannot be trusted: not returned."""


class NoConvergence(Unreliable):
    """Lanczos stopped at ``maxiter`` restarts before its Ritz residuals met ``tol``."""

    def __init__(self, maxiter: int, residual: float):
        super().__init__(f"Lanczos did not converge in {maxiter} restarts (residual {residual:.1e})")
        self.maxiter, self.residual = maxiter, residual


__all__ = ["NoConvergence", "Unreliable"]

_CLUSTER_RTOL = 1e-5
_STEV = get_lapack_funcs("stev", dtype=np.float64)


class _Inner:
    """The :math:`M` inner product on NumPy blocks (Euclidean when ``mmul`` is ``None``).

    Blocks are Fortran-ordered ``(n, b)`` arrays; the products are single BLAS ``gemm``
    calls on them (conjugate transpose inside BLAS, in-place updates), so no ``(n, m)``
    temporary is ever made: orthogonalization is bound by one read of the basis per pass.
    """

    def __init__(self, dtype, mmul=None):
        self.dtype = np.dtype(dtype)
        self.mmul = mmul
        self.gemm, self.gemv = get_blas_funcs(("gemm", "gemv"), dtype=self.dtype)
        self.trans = 2 if self.dtype.kind == "c" else 1
        self.eps = float(np.finfo(self.dtype).eps)

    def dot(self, V, W):
        """``V^H M W`` (``V`` has M-orthonormal or arbitrary columns).

        One or two columns in ``W``: one ``gemv`` per column, which OpenBLAS runs faster
        than a ``gemm`` with a conjugated factor.  For blocks of more than two columns as
        ``((M W)^H V)^H``: OpenBLAS's kernel for a transposed *small* left factor reads the
        basis faster than the direct product.
        """
        MW = W if self.mmul is None else self.mmul(W)
        if MW.shape[1] <= 2 and V.shape[1] and MW.dtype == self.dtype:
            return self._gemv_columns(V, MW, self.trans)
        return self.gemm(1.0, MW, V, trans_a=self.trans).conj().T

    def _gemv_columns(self, V, X, trans=0):
        """``op(V) X`` (``op``: none, or conjugate transpose for ``trans``), one ``gemv`` per column."""
        out = np.empty((V.shape[1] if trans else V.shape[0], X.shape[1]), dtype=self.dtype, order="F")
        for i in range(X.shape[1]):
            out[:, i] = self.gemv(1.0, V, X[:, i], trans=trans)
        return out

    def combine(self, V, S):
        """``V S`` as a new Fortran-ordered block (``gemv`` per column for one or two)."""
        S = np.asarray(S, dtype=self.dtype)
        if S.shape[1] > 2 or not V.shape[1]:
            return self.gemm(1.0, V, S)
        return self._gemv_columns(V, S)

    def gram(self, W):
        G = self.dot(W, W)
        return (G + G.conj().T) / 2

    def subtract(self, W, V, C):
        """``W - V C``, in place when ``W`` is Fortran-ordered."""
        if W.shape[1] <= 2 and V.shape[1] and W.flags.f_contiguous and W.dtype == self.dtype:
            for i in range(W.shape[1]):  # in place on the contiguous column (gemv: see dot)
                y = self.gemv(-1.0, V, C[:, i], beta=1.0, y=W[:, i], overwrite_y=True)
                if y.ctypes.data != W[:, i].ctypes.data:
                    W[:, i] = y
            return W
        return self.gemm(-1.0, V, C, beta=1.0, c=W, overwrite_c=True)


def _orthonormalize(W, V, inner: _Inner, rng, lo=0, out=None, gram=None, _depth=0):
    """M-orthonormalize the block ``W`` against the M-orthonormal basis ``V`` and within itself.

    Returns ``(Q, C, R)`` with ``W = V C + Q R``, ``Q^H M Q = I`` and ``V^H M Q = 0``.

    Classical Gram-Schmidt with the DGKS criterion: an optional first pass against the
    columns ``V[:, lo:]`` (the Lanczos recurrence; it removes the large components), then
    full passes against ``V`` until no column loses more than half its squared norm in a
    pass (one pass nearly always, at most three).  The block is then orthonormalized
    through the eigendecomposition of its Gram matrix; if that is ill conditioned the
    whole procedure runs once more on the result.  Directions lost to rank deficiency
    (``W`` numerically inside ``span V``) are replaced by random ones, with zero rows of
    ``R``.  ``out``, a Fortran-ordered ``(n, b)`` array (a slice of the basis), receives
    ``Q`` in place.  ``gram``, if given, is ``W``'s Gram matrix.
    """
    W = np.asfortranarray(W, dtype=inner.dtype)
    b, cols = W.shape[1], V.shape[1]
    C = np.zeros((cols, b), dtype=inner.dtype)
    G = inner.gram(W) if gram is None else gram
    before = G.diagonal().real.copy()
    scale = max(float(before.max()), np.finfo(float).tiny)
    if cols:
        if 0 < lo < cols:
            Vl = V[:, lo:]
            Cl = inner.dot(Vl, W)
            W = inner.subtract(W, Vl, Cl)
            C[lo:] += Cl
            before = inner.gram(W).diagonal().real.copy()
        for _ in range(3):
            Ci = inner.dot(V, W)
            W = inner.subtract(W, V, Ci)
            C += Ci
            removed = np.einsum("ij,ij->j", Ci.conj(), Ci).real
            if np.all(removed <= 0.5 * before):
                break
            before = inner.gram(W).diagonal().real.copy()
        G = inner.gram(W)
    d, U = scipy.linalg.eigh(G)
    d = np.maximum(d, 0.0)
    good = d > (1e3 * inner.eps) ** 2 * scale
    if good.all():
        sd = np.sqrt(d)
        if out is not None:
            Q = inner.gemm(1.0, W, U / sd, c=out, overwrite_c=True)
        else:
            Q = inner.gemm(1.0, W, U / sd)
        R = sd[:, None] * U.conj().T
    else:
        ng = int(good.sum())
        sd = np.sqrt(d[good])
        Qg = inner.gemm(1.0, W, U[:, good] / sd)
        fresh = rng.standard_normal((W.shape[0], b - ng)).astype(inner.dtype)
        Qf, _, _ = _orthonormalize(
            fresh, np.asfortranarray(np.concatenate([V, Qg], axis=1)), inner, rng, _depth=_depth + 1
        )
        Q = np.asfortranarray(np.concatenate([Qg, Qf], axis=1))
        R = np.zeros((b, b), dtype=inner.dtype)
        R[:ng] = sd[:, None] * U[:, good].conj().T
        d = d[good]
    if d.size and d.min() < 1e-4 * d.max() and _depth < 2:
        # within-block cancellation: the normalized columns may have regained components
        # along V; one more round (rare)
        Q, C2, R2 = _orthonormalize(Q, V, inner, rng, _depth=_depth + 1)
        C, R = C + C2 @ R, R2 @ R
    if out is not None and not np.may_share_memory(Q, out):
        out[...] = Q
        Q = out
    return Q, C, R


def _rotate(V, cols, S, q, rows=4096):
    """``V[:, :q] = V[:, :cols] @ S[:, :q]`` in place, by row blocks (no ``(n, q)`` temporary)."""
    Sq = np.ascontiguousarray(S[:cols, :q])
    for r in range(0, V.shape[0], rows):
        V[r : r + rows, :q] = V[r : r + rows, :cols] @ Sq


def _largest_cluster(theta, resid, tol):
    """Size of the largest group of (nearly) equal, well converged Ritz values.

    A block Lanczos of block size ``b`` finds ``min(mult, b)`` copies of an eigenvalue of
    multiplicity ``mult`` (exactly so in exact arithmetic): a cluster of ``b`` equal Ritz
    values is the visible trace of a possibly larger multiplicity.
    """
    conv = resid <= max(np.sqrt(tol), 1e3 * tol) * np.abs(theta)
    vals = theta[conv]
    if vals.size < 2:
        return int(vals.size)
    rel = np.abs(np.diff(vals)) <= _CLUSTER_RTOL * np.abs(vals[1:])
    best = run = 1
    for same in rel:
        run = run + 1 if same else 1
        best = max(best, run)
    return best


def _lanczos(
    op, inner: _Inner, n, k, *, block, ncv, tol, maxiter, v0, keep=None, max_block=None, strict=False
):
    """Block thick-restart Lanczos for the ``k`` largest eigenvalues of ``op`` (M-self-adjoint).

    ``op`` maps a Fortran-ordered ``(n, b)`` block to a block.  The basis holds at most
    ``ncv`` columns; a restart keeps the ``keep`` leading Ritz vectors (default half the
    basis, at least ``k``).  Convergence -- Ritz residual ``||T y - theta y||_M <= tol
    |theta|`` for the ``k`` leading pairs, read off the last block of the Lanczos
    relation -- is tested on the schedule of :class:`_TestSchedule` (after every block
    or every few blocks, closer together as convergence nears), so that the basis is
    filled only as far as needed.

    ``strict``: raise :class:`NoConvergence` at ``maxiter`` restarts; else log a warning
    and return the Ritz pairs as they are.

    Full reorthogonalization, deferred to every other block (see :func:`_deferred_pass`):
    a step either orthogonalizes its new block against the last two blocks only, leaving
    it *pending*, or -- the next step -- removes the components of both the pending block
    and its image along the rest of the basis in one pass, with the Lanczos relation
    corrected exactly.  The basis is read twice per two blocks instead of twice per
    block; orthogonality stays at working precision (a pending block is off by one
    step's rounding, about ``1e-15``).

    The block size bounds the multiplicity of the eigenvalues that are found for sure.
    With ``max_block > block`` the block doubles (up to ``max_block``) whenever the
    converged Ritz values show a cluster of as many equal values as the block has columns
    (a possibly larger multiplicity, see :func:`_largest_cluster`): a thick restart whose
    new block is the residual block completed with random directions.  Doubling rather
    than jumping to ``max_block``: a larger block lowers the Krylov degree reached per
    solve, so multiplicities of 2 and 3 (rotational and cube symmetries) converge in
    fewer solves with a block of 4 than of 6, and a block of 4 that fills with equal
    values (a multiplicity of 4 or more) grows again.  Convergence is then accepted only after at least
    as many further solves as before the growth, so that the missing copies have time to
    appear.  Returns Ritz values ``theta`` (k,) descending, Ritz vectors (n, k), and the
    number of columns ``op`` was applied to.
    """
    b = block
    max_block = max(block, max_block or block)
    m = min(max(ncv, k + 2 * max_block), n - max_block)
    p = max(k, m // 2) if keep is None else keep
    rng = np.random.default_rng(0)
    V = np.empty((n, m), dtype=inner.dtype, order="F")
    H = np.zeros((m, m), dtype=inner.dtype)
    start = np.asarray(v0, dtype=inner.dtype).reshape(n, -1)[:, :b]
    if start.shape[1] < b:
        start = np.concatenate(
            [start, rng.standard_normal((n, b - start.shape[1])).astype(inner.dtype)], axis=1
        )
    V[:, :b], _, _ = _orthonormalize(start, V[:, :0], inner, rng)
    cols, lo, n_op, restarts, settle = b, 0, 0, 0, 0
    pending = False  # V[:, cols - b: cols] is orthogonal to the last two blocks only
    tests = _TestSchedule(n)  # when to test convergence
    while True:
        W = op(V[:, cols - b : cols])
        n_op += b
        slot = V[:, cols : cols + b] if cols + b <= m else None
        if pending:
            Q, C, R = _deferred_pass(W, V, H, cols, b, lo, inner, rng, out=slot)
            pending = False
        else:
            local = _local_pass(W, V[:, lo:cols], inner, rng, out=slot) if lo > 0 else None
            if local is None:
                # first block after a (re)start (coupled to the whole basis), or a near
                # breakdown: the full procedure now
                Q, C, R = _orthonormalize(W, V[:, :cols], inner, rng, lo=lo, out=slot)
            else:
                Q, Cl, R = local
                C = np.zeros((cols, b), dtype=inner.dtype)
                C[lo:] = Cl
                pending = True
                if not _well_conditioned(R):
                    # nearly dependent columns, or directions replaced by random ones:
                    # orthogonal to the whole basis now
                    Q, C, R = _complete(Q, C, R, V[:, :cols], inner, rng, out=slot)
                    pending = False
        H[:cols, cols - b : cols] = C
        grow = False
        if cols >= k and (cols + b > m or tests.due(cols, n_op, b)):  # (a full basis: the restart needs S)
            theta, S, coupling = _ritz(H, cols, b, R)
            resid = np.linalg.norm(coupling, axis=0)
            grow = b < max_block and _largest_cluster(theta[:k], resid[:k], tol) >= b
            # tol |theta|, or the rounding floor eps ||T|| (theta[0]) where that is larger
            bound = np.maximum(tol * np.abs(theta[:k]), _FLOOR * inner.eps * abs(theta[0]))
            if not grow and n_op >= settle and np.all(resid[:k] <= bound):
                break
            tests.record(resid[:k] / bound, n_op, b)
        if cols + b <= m and not grow:
            H[cols : cols + b, cols - b : cols] = R  # (Q is already V[:, cols: cols + b])
            lo = cols - b
            cols += b
            continue
        if restarts == maxiter:
            residual = float(np.max(resid[:k] / np.abs(theta[:k])))
            if strict:
                raise NoConvergence(maxiter, residual)
            logger.warning("Lanczos did not converge in %d restarts (residual %.1e)", maxiter, residual)
            break
        restarts += 1
        if pending:  # the restart keeps Q: orthogonalize it fully first
            Q, C, R = _complete(Q, C, R, V[:, :cols], inner, rng, out=slot)
            H[:cols, cols - b : cols] = C
            pending = False
            theta, S, coupling = _ritz(H, cols, b, R)
        nb = min(max_block, 2 * b) if grow else b
        q = min(max(p, k), m - nb, cols)
        _rotate(V, cols, S, q)
        V[:, q : q + b] = Q  # (numpy buffers the copy if Q overlaps, as a view of V)
        H[:] = 0
        H[:q, :q] = np.diag(theta[:q])
        H[q : q + b, :q] = coupling[:, :q]
        if grow:
            logger.debug(
                "Lanczos: block size %d -> %d after %d solves (cluster of %d equal Ritz values)",
                b,
                nb,
                n_op,
                b,
            )
            fresh = rng.standard_normal((n, nb - b)).astype(inner.dtype)
            V[:, q + b : q + nb], _, _ = _orthonormalize(fresh, V[:, : q + b], inner, rng)
            settle = 2 * n_op
            b = nb
        cols, lo = q + b, 0
    return theta[:k], inner.combine(V[:, :cols], S[:, :k]), n_op


#: The block path's convergence floor, in units of ``eps ||T||`` (see ``eigsh``'s ``tol``).
_FLOOR = 10.0
_CHEAP_TEST_GAP = 4  # steps: the longest gap between cheap tests (see _TestSchedule)


class _TestSchedule:
    """When the block Lanczos loop tests convergence.

    A test is a dense eigendecomposition of the ``cols x cols`` projected matrix: about
    ``1.5 cols^2 / n`` times the cost of a step (a small solve and the reorthogonalization).
    Where that ratio exceeds one (many pairs on a small mesh) the tests are spaced so that
    they cost about as much as the steps; where it does not, they are at most
    ``_CHEAP_TEST_GAP`` steps apart.  Either way never beyond half the
    number of steps that the current rate of convergence predicts are left: the worst
    ``log10(residual / bound)`` of the wanted pairs (``bound``: ``tol |theta|`` or the
    floor, see ``_FLOOR``), and its fall per step between the last two tests.  Lanczos
    convergence accelerates, so the last gaps shrink to one step.  The schedule depends
    only on computed quantities, so runs are reproducible.
    """

    def __init__(self, n):
        self.n = n
        self.last = None  # (solves, worst log10 ratio) at the last test
        self.predicted = np.inf  # steps after the last test, by the rate of convergence

    def due(self, cols, n_op, b):
        if self.last is None:
            return True
        by_cost = int(round(1.5 * cols * cols / self.n))
        gap = min(by_cost, self.predicted) if by_cost > 1 else min(self.predicted, _CHEAP_TEST_GAP)
        return n_op - self.last[0] >= b * gap

    def record(self, ratio, n_op, b):
        worst = float(np.log10(max(float(np.max(ratio)), 1e-300)))
        self.predicted = np.inf
        if self.last is not None and n_op > self.last[0]:
            slope = (self.last[1] - worst) / ((n_op - self.last[0]) / b)
            if slope > 0:
                self.predicted = max(1, int(0.5 * worst / slope))
        self.last = (n_op, worst)


def _ritz(H, cols, b, R):
    """Ritz values (descending), vectors of the projected ``H[:cols, :cols]``, and their coupling
    ``R S_last`` to the next block (its column norms are the Ritz residuals)."""
    theta, S = scipy.linalg.eigh((H[:cols, :cols] + H[:cols, :cols].conj().T) / 2)
    theta, S = theta[::-1], np.asfortranarray(S[:, ::-1])
    return theta, S, R @ S[cols - b : cols]


def _sq_norms(C):
    """Squared column norms of a small coefficient block."""
    return np.einsum("ij,ij->j", C.conj(), C).real


def _well_conditioned(R, rtol=1e-6):
    """Whether the block's normalisation ``R`` is far from singular (no near breakdown)."""
    sv = np.linalg.svd(R, compute_uv=False)
    return bool(sv.size and sv.min() > rtol * sv.max())


def _complete(Q, C, R, V, inner: _Inner, rng, out=None):
    """Finish a block ``W = V C + Q R`` whose ``Q`` is orthogonal to part of ``V`` only.

    Full passes of :func:`_orthonormalize` against all of ``V``: ``Q = V C_2 + Q_2 R_2``,
    so ``W = V (C + C_2 R) + Q_2 (R_2 R)``.
    """
    Q2, C2, R2 = _orthonormalize(np.array(Q, order="F"), V, inner, rng, out=out)
    return Q2, C + C2 @ R, R2 @ R


_CANCELLATION = 1e-8
#: Largest component of the pending block along the rest of the basis (in units of eps)
#: that :func:`_deferred_pass` corrects to first order; beyond it, the full procedure.
_PENDING_DRIFT = 50.0


def _local_pass(W, Vl, inner: _Inner, rng, out=None):
    """Orthogonalize ``W`` against the last two blocks ``Vl`` and within itself.

    One classical Gram-Schmidt pass; its error along the rest of the basis, about
    ``eps`` times the cancellation ratio, is removed by the next :func:`_deferred_pass`,
    which needs it small, not zero.  Returns ``(Q, C, R)`` with ``W = Vl C + Q R``, or
    ``None`` -- with ``W`` restored -- where a column lost more than ``1 - 1e-8`` of its
    squared norm (a near breakdown: what is left may be mostly rounding error, which
    only the full procedure handles).
    """
    W, C, G, breakdown = _against_last_blocks(W, Vl, inner)
    if breakdown:
        inner.subtract(W, Vl, -C)
        return None
    Q, _, R = _orthonormalize(W, Vl[:, :0], inner, rng, out=out, gram=G)
    return Q, C, R


def _against_last_blocks(W, Vl, inner: _Inner):
    """One Gram-Schmidt pass of ``W`` against ``Vl``: ``(W - Vl C, C, its Gram matrix, breakdown)``.

    ``breakdown``: some column lost more than ``1 - 1e-8`` of its squared norm (by
    Pythagoras, the norm before is the norm after plus that of ``C``).
    """
    W = np.asfortranarray(W, dtype=inner.dtype)
    C = inner.dot(Vl, W)
    W = inner.subtract(W, Vl, C)
    G = inner.gram(W)
    after = G.diagonal().real
    return W, C, G, bool(np.any(after <= _CANCELLATION * (after + _sq_norms(C))))


def _deferred_pass(W, V, H, cols, b, lo, inner: _Inner, rng, out=None):
    r"""One Lanczos step whose full reorthogonalization also completes the pending block.

    The basis ``V[:, :p]``, ``p = cols - b``, is orthonormal; its last block ``Q =
    V[:, p: cols]`` (pending) is orthogonal to the two blocks before it only, and ``W = T
    Q``.  After the pass against the last two blocks, ``W_l = W - V_l C_l``, one ``gemm``
    gives the components of both ``Q`` and ``W_l`` along ``V_o = V[:, :p]``, ``D = V_o^H
    [Q, W_l] = [d_1, d_2]``, and one more removes them.  The Lanczos relation is then
    restated for the corrected block :math:`Q' = Q - V_o d_1`: from :math:`T V_o = V_o
    H_{oo} + Q H_{qo}`,

    .. math::

        H_{oo} \leftarrow H_{oo} + d_1 H_{qo}, \qquad
        T Q' = W_l - V_o d_2 + V_o (C_o + d_2 + d_1 C_q - H_{oo} d_1) + Q' (C_q - H_{qo} d_1),

    exact up to terms of order :math:`|d_1| |d_2|`; ``H`` is updated in place, ``V[:, p:
    cols]`` receives :math:`Q'`.  Returns ``(Q_new, C, R)`` as :func:`_orthonormalize`
    does, with ``C`` the new column block of ``H``.

    :math:`d_1` is usually at rounding level, but not always: a Lanczos step loses
    orthogonality along well converged Ritz vectors by about ``eps / residual``, and on
    icospheres (many pairs, clusters) it reached 1e-11 within one step.  The new block was
    then no longer orthogonal to ``Q'`` (5e-11), ``H`` drifted from Hermitian (1e-12), and
    the pairs' true residuals far above their estimates.  So beyond ``_PENDING_DRIFT eps``
    the new block goes through the full procedure against the corrected basis, as on a near
    breakdown.
    """
    p = cols - b
    W, Cl, G, breakdown = _against_last_blocks(W, V[:, lo:cols], inner)
    before = G.diagonal().real
    X = np.empty((W.shape[0], 2 * b), dtype=inner.dtype, order="F")
    X[:, :b] = V[:, p:cols]
    X[:, b:] = W
    Vo = V[:, :p]
    D = inner.dot(Vo, X)
    X = inner.subtract(X, Vo, D)
    d1, d2 = D[:, :b], D[:, b:]
    V[:, p:cols] = X[:, :b]
    Hqo = H[p:cols, :p]
    H[:p, :p] += d1 @ Hqo
    Cq = Cl[p - lo :]
    C = np.zeros((cols, b), dtype=inner.dtype)
    C[lo:p] = Cl[: p - lo]
    C[:p] += d2 + d1 @ Cq - H[:p, :p] @ d1
    C[p:] = Cq - Hqo @ d1
    if breakdown or np.abs(d1).max() > _PENDING_DRIFT * inner.eps:
        # what is left of W may be mostly rounding error, or Q drifted far from the basis
        # (see _PENDING_DRIFT): the full procedure on T Q'
        # (= the part removed so far plus the rest), judged against its own norm
        W = inner.subtract(X[:, b:], V[:, :cols], -C)
        return _orthonormalize(W, V[:, :cols], inner, rng, lo=lo, out=out)
    removed = _sq_norms(d2)
    # the Gram matrix of the result, W_l - V_o d2 with V_o^H (W_l - V_o d2) = 0: G - d2^H d2
    Q, _, R = _orthonormalize(X[:, b:], V[:, :0], inner, rng, out=out, gram=G - d2.conj().T @ d2)
    if np.any(removed > 0.5 * before) or not _well_conditioned(R, 1e-2):
        # cancellation in the pass, or nearly dependent columns: another full pass (rare)
        Q, C, R = _complete(Q, C, R, V[:, :cols], inner, rng, out=out)
    return Q, C, R


def _smallest_pair(op, inner: _Inner, n, *, tol, maxiter, v0, ncv=None, strict=False):
    """The k = 1 fast path: inverse iteration with the factor, Rayleigh-Ritz accelerated.

    Each step is one solve with the existing factor (shift-invert inverse iteration);
    instead of keeping only the last iterate, the Rayleigh-Ritz step runs on all the
    iterates so far (their Krylov space, i.e. single-vector Lanczos), which converges like
    Chebyshev-accelerated inverse iteration.  It stops as soon as the Ritz residual of the
    leading pair is below ``tol |theta|``, tested after every solve.

    A step orthogonalizes against the last two vectors only (the three-term recurrence),
    plus selective orthogonalization (Parlett and Scott) against the Ritz vectors
    whose residual fell below ``sqrt(eps) theta_max``: by Paige's theorem the Lanczos
    vectors lose orthogonality only in their direction, so the basis stays semi-orthogonal
    and the Ritz pairs are accurate to working precision, without the full
    reorthogonalization (a pass over the whole basis per step) of the general path.  If
    ``ncv`` (default 24) steps do not suffice, the general thick-restart Lanczos takes over
    from the best Ritz vector.

    Returns ``(theta, Y, n_op)``; on convergence ``Y`` holds two candidates, the Ritz vector
    and the harmonic Ritz vector (:func:`_harmonic_ritz`, free), for the caller to keep
    the one with the smaller residual; after the fallback, the Ritz vector alone.
    ``strict``: as in :func:`_lanczos`.
    """
    m = max(3, min(ncv or 24, n - 2))
    rng = np.random.default_rng(0)
    V = np.empty((n, m), dtype=inner.dtype, order="F")
    alpha, betas = np.zeros(m), np.zeros(m)  # the tridiagonal Lanczos matrix
    start = np.asarray(v0, dtype=inner.dtype).reshape(n, -1)[:, :1]
    V[:, :1], _, _ = _orthonormalize(start, V[:, :0], inner, rng)
    good = np.zeros((n, 0), dtype=inner.dtype, order="F")  # selective orthogonalization set
    good_idx: list[int] = []
    sqrt_eps = np.sqrt(inner.eps)
    for j in range(m):
        w = np.asfortranarray(op(V[:, j : j + 1]), dtype=inner.dtype)
        lo = max(0, j - 1)
        Vl = V[:, lo : j + 1]
        c = inner.dot(Vl, w)
        w = inner.subtract(w, Vl, c)
        alpha[j] = c[-1, 0].real
        if good.shape[1]:
            w = inner.subtract(w, good, inner.dot(good, w))
        beta = float(np.sqrt(max(inner.gram(w)[0, 0].real, 0.0)))
        theta, S = _tridiagonal_eigh(alpha[: j + 1], betas[: max(j, 1)])
        resid = beta * np.abs(S[j])
        if resid[0] <= tol * abs(theta[0]):
            Y = inner.combine(V[:, : j + 1], S[:, :1])
            return (
                theta[:1],
                np.concatenate([Y, _harmonic_ritz(V, alpha, betas, j, w, beta, inner)], axis=1),
                j + 1,
            )
        if beta <= inner.eps * abs(theta[0]) or j + 1 == m:
            break
        # Ritz vectors that converged to sqrt(eps) join the selective orthogonalization set
        new = [int(i) for i in np.flatnonzero(resid <= sqrt_eps * abs(theta[0])) if i not in good_idx]
        if new:
            Y = inner.combine(V[:, : j + 1], S[:, new])
            good = np.asfortranarray(np.concatenate([good, Y], axis=1))
            good_idx += new  # Ritz pairs are tracked by rank (index 0: the leading pair)
            w = inner.subtract(w, Y, inner.dot(Y, w))
            beta = float(np.sqrt(max(inner.gram(w)[0, 0].real, 0.0)))
        np.multiply(w, 1.0 / beta, out=V[:, j + 1 : j + 2])
        betas[j] = beta
    # not converged in m steps (or an invariant subspace): the robust general path, from
    # the best Ritz vectors so far
    ncol = min(3, S.shape[1])
    start = inner.combine(V[:, : S.shape[0]], S[:, :ncol])
    theta, X, n_op = _lanczos(
        op,
        inner,
        n,
        1,
        block=1,
        ncv=m,
        tol=tol,
        maxiter=maxiter,
        v0=start,
        keep=min(3, m // 2),
        strict=strict,
    )
    return theta, X, n_op + S.shape[0]


def _harmonic_ritz(V, alpha, betas, j, w, beta, inner: _Inner):
    r"""The harmonic Ritz vector of the smallest eigenvalue of :math:`K = T^{-1}`, for free.

    With the Lanczos relation :math:`T V = V H + w e_j^T` (``w``: the unnormalized next
    vector, :math:`\|w\| = \beta`), the space :math:`W = T V` has the known images
    :math:`K W = V`, so the Rayleigh-Ritz step of :math:`K` on it needs no product with
    :math:`K`: :math:`W^H K W = H` and :math:`W^H W = H^2 + \beta^2 e_j e_j^T`.  Its
    smallest pair :math:`(\mu, s)` gives :math:`u = W s = V H s + s_j w`.  :math:`W`
    reaches one power of :math:`T` further than :math:`V`, and the step weighs the error by
    :math:`K` -- which is large on the directions that inverse iteration leaves for last
    -- so the residual of :math:`u` in the original problem is typically an order of
    magnitude below that of the Ritz vector.
    Selective orthogonalization drops small terms from the relation, so the caller
    compares the two vectors' true residuals and keeps the better one.
    """
    H = _tridiagonal(alpha[: j + 1], betas[:j])
    G = H @ H
    G[j, j] += beta * beta
    try:
        _, s = scipy.linalg.eigh(H, G, subset_by_index=[0, 0])
    except np.linalg.LinAlgError:  # (G numerically singular: no harmonic candidate)
        return np.zeros((V.shape[0], 0), dtype=inner.dtype)
    s = s[:, 0].astype(inner.dtype)
    u = inner.combine(V[:, : j + 1], (H @ s)[:, None])
    u[:, 0] += s[j] * w[:, 0]
    return u


def _better_of(Y, kmul, mmul=None):
    """The column of ``Y`` with the smaller relative residual ``||K y - rho M y|| / (|rho| ||M y||)``
    (``rho``: its Rayleigh quotient), as an ``(n, 1)`` block, and its image ``K y``."""
    best = None
    for i in range(Y.shape[1]):
        y = Y[:, i : i + 1]
        ky = kmul(y)
        my = y if mmul is None else mmul(y)
        rho = np.vdot(y, ky).real / np.vdot(y, my).real
        res = np.linalg.norm(ky - rho * my) / max(abs(rho) * np.linalg.norm(my), np.finfo(float).tiny)
        logger.debug("smallest pair: residual %.2e (%s Ritz vector)", res, "harmonic" if i else "plain")
        res = res if np.isfinite(res) else np.inf  # (a NaN residual never wins)
        if best is None or res < best[0]:
            best = (res, y, ky)
    return best[1], best[2]


def _tridiagonal_eigh(d, e):
    """Eigenpairs of the real symmetric tridiagonal matrix (diagonal ``d``, off-diagonal
    ``e[:len(d) - 1]``; ``e`` has at least one entry), *descending*.

    LAPACK ``stev``: a fifth of the time of ``eigh`` on the full matrix at the sizes of the
    smallest-pair path, where it runs after every solve.
    """
    theta, S, info = _STEV(d, e, compute_v=1)
    if info != 0:  # (QL/QR did not converge: never seen; the dense solver then)
        theta, S = scipy.linalg.eigh(_tridiagonal(d, e[: d.size - 1]))
    return theta[::-1], S[:, ::-1]


def _tridiagonal(d, e):
    """The dense symmetric tridiagonal matrix with diagonal ``d`` and off-diagonal ``e``."""
    return np.diag(d) + np.diag(e, 1) + np.diag(e, -1)
