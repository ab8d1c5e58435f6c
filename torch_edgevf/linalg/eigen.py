r"""Differentiable generalized Hermitian eigenpairs :math:`A x = \lambda M x` (thesis 3.1).

Forward
-------
Shift-invert block Lanczos with thick restarts on :math:`T = (A - \sigma M)^{-1} M`, which is
self-adjoint in the :math:`M` inner product; :math:`A - \sigma M` is factored once with
:func:`~torch_edgevf.linalg.factor.factorize` (Cholesky type for :math:`\sigma` below the
spectrum).  Complex Hermitian problems get a Hermitian Lanczos, not the non-Hermitian
Arnoldi that SciPy's ``eigsh`` falls back to for complex input.  The default shift is
slightly negative, :math:`\sigma = -10^{-6} s` (``1e-3 s`` in single precision), with
:math:`s = \max_i A_{ii} / M_{ii}`, so that :math:`A - \sigma M` is positive definite
for the (often singular) positive semidefinite Laplacians.  A final Rayleigh-Ritz step on
:math:`(A, M)` makes the eigenvectors :math:`M`-orthonormal: :math:`X^H M X = I`.

Phase convention: each eigenvector is scaled by a unit number so that its entry of
largest modulus is real and positive (a sign for real problems).  This makes the result
a well-defined function of the matrices where that entry is unique; losses that are
invariant to the phase (``|x|^2``, projectors :math:`x x^H`) are recommended.

Backward
--------
Eigenvalues, with :math:`X^H M X = I`:
:math:`d\lambda_i = x_i^H (dA - \lambda_i \, dM) x_i`, returned on the patterns of
:math:`A` and :math:`M`.

Eigenvectors: with :math:`G = \partial L / \partial \bar X` (corrected for the phase
convention), the loss reaches the matrices through

* the computed subspace, :math:`F_{ji} = x_j^H g_i / (\lambda_i - \lambda_j)`,
  :math:`j \ne i`, and the normalisation :math:`-\tfrac12 \mathrm{Re}(x_i^H g_i)
  \, x_i^H dM x_i`;
* its :math:`M`-orthogonal complement: :math:`w_i` solving
  :math:`(A - \lambda_i M) w_i = (I - M X X^H) g_i` with :math:`X^H M w_i = 0`, by
  conjugate gradients on the complement (where :math:`A - \lambda_i M` is positive
  definite) preconditioned with the factor of :math:`A - \sigma M`.

Both terms are exact: gradcheck passes for any smooth loss of the phase-fixed vectors.
(Near-)degenerate eigenvalues (:math:`|\lambda_i - \lambda_j| \le` ``degeneracy_rtol``
:math:`\max|\lambda|`) inside the computed set are supported for losses invariant to
rotations within the degenerate eigenspace (the skew part of :math:`X_D^H G_D` vanishes);
otherwise the gradient does not exist and backward raises ``ValueError``.  The
complement solve converges slowly when :math:`\lambda_{k+1} \approx \lambda_k`; ask for
``k`` so that a spectral gap follows the last wanted eigenvalue.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import torch

from ._utils import (
    SparseData,
    as_diagonal_or_sparse,
    as_sparse,
    blas_single_thread,
    from_numpy,
    real_dtype,
    to_numpy,
)
from .factor import factorize

logger = logging.getLogger(__name__)

METHODS = ("auto", "lanczos", "dense")
_DENSE_MAX = 300


class EigenPairs(NamedTuple):
    """Result of :func:`eigsh`: ``values`` (k,) ascending, ``vectors`` (N, k)."""

    values: torch.Tensor
    vectors: torch.Tensor


# ----------------------------------------------------------------------------- forward


def default_shift(A: sp.spmatrix, M: sp.spmatrix) -> float:
    """Small negative shift :math:`-\\epsilon\\, \\mathrm{median}_i A_{ii}/M_{ii}` (``eps`` by precision).

    The median, not the maximum: one needle face makes ``max A_ii / M_ii`` many orders of
    magnitude above the low spectrum, and shift-invert Lanczos then stalls.
    """
    ratio = np.abs(A.diagonal()) / np.maximum(np.abs(M.diagonal()), np.finfo(M.dtype).tiny)
    scale = float(np.median(ratio)) if ratio.size else 1.0
    eps = 1e-3 if np.finfo(A.dtype).bits <= 32 else 1e-4
    return -eps * (scale if scale > 0 else 1.0)


def _orthonormalize(W, V, MV, M, rng):
    """M-orthonormalize ``W`` against ``V`` and within itself, twice for stability.

    Returns ``(Q, MQ, C, R)`` with ``W = V C + Q R``, ``Q^H M Q = I``, ``V^H M Q = 0``.
    """
    Q, MQ, C, R = _orthonormalize_once(W, V, MV, M, rng)
    Q, MQ, C2, R2 = _orthonormalize_once(Q, V, MV, M, rng)
    return Q, MQ, C + C2 @ R, R2 @ R


def _orthonormalize_once(W, V, MV, M, rng):
    """M-orthogonalize the block ``W`` against ``V`` (two passes) and within itself.

    Returns ``(Q, MQ, C, R)`` with ``W = V C + Q R``, ``Q^H M Q = I``, ``V^H M Q = 0``.
    Directions lost to rank deficiency are replaced by random ones (with ``R`` zero there).
    """
    C = MV.conj().T @ W
    W = W - V @ C
    C2 = MV.conj().T @ W
    W = W - V @ C2
    C = C + C2
    MW = M @ W
    d, U = scipy.linalg.eigh(W.conj().T @ MW)
    d = np.maximum(d.real, 0.0)
    good = d > 1e-24 * max(d.max(), 1e-300)
    if not good.all():
        fresh = rng.standard_normal((W.shape[0], int((~good).sum()))).astype(W.dtype)
        Wg = W @ U[:, good] / np.sqrt(d[good])
        basis = np.concatenate([V, Wg], axis=1)
        mbasis = np.concatenate([MV, M @ Wg], axis=1)
        for _ in range(2):
            fresh = fresh - basis @ (mbasis.conj().T @ fresh)
        Q, MQ = np.concatenate([Wg, fresh], axis=1), None
        R = np.zeros((W.shape[1], W.shape[1]), dtype=W.dtype)
        R[: int(good.sum())] = (np.sqrt(d[good])[:, None] * U[:, good].conj().T)
        MQ = M @ Q
        G = Q.conj().T @ MQ  # re-normalize the fresh directions
        Lc = np.linalg.cholesky((G + G.conj().T) / 2)
        T = np.linalg.inv(Lc).conj().T
        return Q @ T, MQ @ T, C, np.linalg.solve(T, R)
    scale = 1.0 / np.sqrt(d)
    return W @ (U * scale), MW @ (U * scale), C, np.sqrt(d)[:, None] * U.conj().T


def _lanczos(op, M, n, k, dtype, *, ncv, block, tol, maxiter, v0):
    """Block thick-restart Lanczos for the ``k`` largest eigenvalues of ``op`` (M-self-adjoint).

    The block size ``block`` bounds the multiplicity of the eigenvalues it can resolve
    (symmetric meshes have clusters of up to 5 or 6 equal eigenvalues).  Returns Ritz
    values ``theta`` (k,) descending, Ritz vectors (n, k), and the number of solves.
    """
    b = block
    m = b * max(-(-ncv // b), -(-(k + 2 * b) // b))
    m = min(m, b * (n // b) - b) if n > 2 * b else m
    p = m - b * max(1, (m - k) // (2 * b))
    rng = np.random.default_rng(0)
    V = np.zeros((n, m + b), dtype=dtype)
    MV = np.zeros_like(V)
    H = np.zeros((m, m), dtype=dtype)
    start = np.asarray(v0, dtype=dtype).reshape(n, -1)
    if start.shape[1] < b:
        extra = rng.standard_normal((n, b - start.shape[1])).astype(dtype)
        start = np.concatenate([start, extra], axis=1)
    V[:, :b], MV[:, :b], _, _ = _orthonormalize(start[:, :b], V[:, :0], MV[:, :0], M, rng)
    cols, n_op = b, 0
    for _ in range(maxiter):
        while cols <= m:
            W = op(MV[:, cols - b: cols])
            n_op += b
            Q, MQ, C, R = _orthonormalize(W, V[:, :cols], MV[:, :cols], M, rng)
            H[:cols, cols - b: cols] = C
            if cols + b <= m:
                H[cols: cols + b, cols - b: cols] = R
            else:
                B = R
            V[:, cols: cols + b], MV[:, cols: cols + b] = Q, MQ
            cols += b
        theta, S = scipy.linalg.eigh((H + H.conj().T) / 2)
        theta, S = theta[::-1], S[:, ::-1]
        resid = np.linalg.norm(B @ S[m - b: m, :k], axis=0)
        if np.all(resid <= tol * np.abs(theta[:k])):
            break
        V[:, :p] = V[:, :m] @ S[:, :p]
        MV[:, :p] = MV[:, :m] @ S[:, :p]
        V[:, p: p + b], MV[:, p: p + b] = V[:, m:], MV[:, m:]
        H[:] = 0
        H[:p, :p] = np.diag(theta[:p])
        H[p: p + b, :p] = B @ S[m - b: m, :p]
        cols = p + b
    else:
        logger.warning("Lanczos did not converge in %d restarts (residual %.1e)", maxiter, resid.max())
    return theta[:k], V[:, :m] @ S[:, :k], n_op


def _rayleigh_ritz(A, M, X):
    """Eigenpairs of the projected pencil ``(X^H A X, X^H M X)``, ascending."""
    ha, hm = X.conj().T @ (A @ X), X.conj().T @ (M @ X)
    lam, C = scipy.linalg.eigh((ha + ha.conj().T) / 2, (hm + hm.conj().T) / 2)
    return lam, X @ C


def _fix_phase(X: np.ndarray) -> np.ndarray:
    """Scale each column so that its largest-modulus entry is real positive."""
    p = np.argmax(np.abs(X), axis=0)
    pivot = X[p, np.arange(X.shape[1])]
    return X * (np.abs(pivot) / pivot)


def _eig_dense(A, M, k):
    lam, X = scipy.linalg.eigh(A.toarray(), M.toarray(), subset_by_index=[0, k - 1])
    return lam, X


# ---------------------------------------------------------------------------- backward


def _pattern_outer(left, right, data: SparseData):
    return (left[data.row] * right[data.col].conj()).sum(-1)


def _to_input(grad, values):
    return grad if values.is_complex() else grad.real.to(values.dtype)


def _complement_solve(A, M, X, lam, R, precond, tol, maxiter):
    """Solve ``(A - lam_i M) w_i = r_i`` with ``X^H M w_i = 0`` by projected PCG.

    ``R`` (n, k) must satisfy ``X^H R = 0``; ``precond(R)`` applies ``(A - sigma M)^{-1}``.
    """
    MX = M @ X

    def project(Z):  # onto the M-orthogonal complement of X
        return Z - X @ (MX.conj().T @ Z)

    def apply(P):
        Q = A @ P - (M @ P) * lam
        return Q - MX @ (X.conj().T @ Q)

    W = np.zeros_like(R)
    norm0 = np.linalg.norm(R, axis=0)
    active = norm0 > 0
    Z = project(precond(R))
    P = Z.copy()
    rz = np.sum(R.conj() * Z, axis=0)
    for it in range(maxiter):
        Q = apply(P)
        alpha = np.where(active, rz / np.where(active, np.sum(P.conj() * Q, axis=0), 1), 0)
        W += P * alpha
        R = R - Q * alpha
        active &= np.linalg.norm(R, axis=0) > tol * norm0
        if not active.any():
            break
        Z = project(precond(R))
        rz_new = np.sum(R.conj() * Z, axis=0)
        P = Z + P * np.where(active, rz_new / np.where(rz != 0, rz, 1), 0)
        rz = rz_new
    else:
        logger.warning(
            "eigenvector backward: complement CG did not converge in %d iterations "
            "(small gap after the k-th eigenvalue?)", maxiter)
    return W


class _Eigsh(torch.autograd.Function):
    @staticmethod
    @blas_single_thread
    def forward(ctx, a_values, m_values, a_data, m_data, k, sigma, method, tol, maxiter, ncv,
                v0, degeneracy_rtol, block_size):
        A = a_data.to_scipy()
        M = m_data.to_scipy().astype(A.real.dtype)
        if sigma is None:
            sigma = default_shift(A, M)
        ctx.factor = None
        if method == "auto":
            method = "dense" if A.shape[0] <= _DENSE_MAX else "lanczos"
        if method == "dense":
            lam, X = _eig_dense(A, M, k)
        else:
            K = (A - sigma * M).tocsc()
            ctx.factor = factorize(K, "auto", hermitian=True)
            v0 = np.random.default_rng(0).standard_normal(A.shape[0]) if v0 is None else v0
            block = block_size or min(k, 6)
            _, X, n_op = _lanczos(ctx.factor.solve, M, A.shape[0], k, A.dtype, ncv=ncv or 2 * k + block,
                                  block=block, tol=tol, maxiter=maxiter, v0=v0)
            logger.debug("Lanczos: %d solves for k=%d", n_op, k)
            lam, X = _rayleigh_ritz(A, M, X)
        X = _fix_phase(X)
        ctx.A, ctx.M, ctx.sigma, ctx.degeneracy_rtol = A, M, sigma, degeneracy_rtol
        ctx.a_data, ctx.m_data = a_data, m_data
        ctx.set_materialize_grads(False)
        lam_t = from_numpy(lam, a_values, real_dtype(a_values.dtype))
        X_t = from_numpy(X, a_values, a_values.dtype)
        ctx.save_for_backward(lam_t, X_t)
        return lam_t, X_t

    @staticmethod
    @blas_single_thread
    def backward(ctx, g_lam, g_X):
        lam, X = ctx.saved_tensors
        U = torch.zeros_like(X)
        norm_term = torch.zeros_like(lam)
        if g_lam is not None:
            U = U + X * g_lam.to(X.dtype)
        if g_X is not None and bool(g_X.ne(0).any()):
            U_vec, norm_term = _eigenvector_adjoint(ctx, lam, X, g_X)
            U = U + U_vec
        grad_a = grad_m = None
        if ctx.needs_input_grad[0]:
            grad_a = _to_input(_pattern_outer(U, X, ctx.a_data), ctx.a_data.values)
        if ctx.needs_input_grad[1]:
            left = -U * lam.to(X.dtype) - 0.5 * X * norm_term.to(X.dtype)
            grad_m = _pattern_outer(left, X, ctx.m_data).real.to(ctx.m_data.dtype)
        return (grad_a, grad_m) + (None,) * 11


def _phase_corrected(X: torch.Tensor, G: torch.Tensor) -> torch.Tensor:
    """Upstream gradient of the unnormalised-phase vectors (see module docstring)."""
    if not X.is_complex():
        return G
    cols = torch.arange(X.shape[1])
    p = X.abs().argmax(dim=0)
    coef = (G.conj() * X).sum(0).imag / X[p, cols].real
    G = G.clone()
    G[p, cols] = G[p, cols] + 1j * coef
    return G


def _eigenvector_adjoint(ctx, lam, X, G):
    """Left vectors ``U`` (n, k) and normalisation weights (k,) of the eigenvector backward."""
    G = _phase_corrected(X, G.to(X.dtype))
    XG = X.conj().T @ G  # (k, k): (X^H G)_{ji} = x_j^H g_i
    diff = lam[None, :] - lam[:, None]  # diff[j, i] = lam_i - lam_j
    scale = max(float(lam.abs().max()), float(torch.finfo(lam.dtype).tiny))
    degenerate = diff.abs() <= ctx.degeneracy_rtol * scale
    degenerate.fill_diagonal_(False)
    skew = (XG - XG.conj().T).abs() * degenerate
    if bool((skew > 1e-6 * (XG.abs().max() + 1e-300)).any()):
        raise ValueError(
            "eigenvector gradient is undefined: the loss depends on the basis chosen inside "
            "a degenerate eigenspace; use a loss invariant to rotations within it "
            "(e.g. of the projector X X^H) or perturb the problem")
    F = torch.where(degenerate, torch.zeros_like(XG), XG / torch.where(degenerate, 1.0, diff).fill_diagonal_(1.0).to(XG.dtype))
    F.fill_diagonal_(0)
    U = X @ F
    W = _complement_adjoint(ctx, lam, X, G)
    return U - W, XG.diagonal().real


def _complement_adjoint(ctx, lam, X, G):
    n, k = X.shape
    if k >= n:
        return torch.zeros_like(X)
    A, M = ctx.A, ctx.M
    Xn, Gn, lam_n = to_numpy(X), to_numpy(G), to_numpy(lam)
    R = Gn - (M @ Xn) @ (Xn.conj().T @ Gn)
    if ctx.factor is None:
        ctx.factor = factorize((A - ctx.sigma * M).tocsc(), "auto", hermitian=True)
    eps = float(np.finfo(A.dtype).eps)
    W = _complement_solve(A, M, Xn, lam_n, R, ctx.factor.solve, tol=max(1e-12, 10 * eps),
                          maxiter=max(100, min(n, 1000)))
    return from_numpy(W, X, X.dtype)


# ------------------------------------------------------------------------------ public


def eigsh(
    A: torch.Tensor,
    M: torch.Tensor | None = None,
    k: int = 6,
    sigma: float | None = None,
    *,
    method: str = "auto",
    tol: float | None = None,
    maxiter: int = 1000,
    ncv: int | None = None,
    v0: np.ndarray | None = None,
    degeneracy_rtol: float | None = None,
    block_size: int | None = None,
) -> EigenPairs:
    r"""The ``k`` smallest eigenpairs of :math:`A x = \lambda M x`, differentiable.

    Parameters
    ----------
    A : (N, N) sparse tensor
        Hermitian positive semidefinite, real or complex (e.g. :math:`L_c`).
    M : (N, N) sparse tensor or (N,) tensor, optional
        Real symmetric positive definite mass matrix, or its diagonal; identity if None.
    k : int
        Number of eigenpairs, ``1 <= k < N``.
    sigma : float, optional
        Shift for shift-invert; must lie below the spectrum for the Cholesky path.
        Default: see :func:`default_shift`.
    method : {"auto", "lanczos", "dense"}
        ``"dense"`` uses ``scipy.linalg.eigh`` (``auto`` for ``N <= 300``).
    tol : float, optional
        Relative Ritz residual of the shift-inverted operator; default ``1e-12``
        (float64) or ``1e-6`` (float32).
    maxiter, ncv, v0
        Lanczos restarts, basis size (default ``2k + block_size``), start vector(s).
    block_size : int, optional
        Lanczos block size, default ``min(k, 6)``: eigenvalues of multiplicity up to the
        block size are all found (symmetric meshes such as icospheres have clusters of
        up to 5 or 6); blocks also use the faster multi-right-hand-side solves.
    degeneracy_rtol : float, optional
        Relative gap under which two eigenvalues count as degenerate in the eigenvector
        backward; default ``sqrt(eps)``.

    Returns
    -------
    EigenPairs
        ``values`` (k,) real, ascending; ``vectors`` (N, k), :math:`X^H M X = I`, each
        column's largest-modulus entry real positive.  Dtypes follow ``A``.
    """
    a_data = as_sparse(A, "A")
    n = a_data.n
    if M is None:
        M = torch.ones(n, dtype=real_dtype(a_data.dtype), device=a_data.values.device)
    m_data = as_diagonal_or_sparse(M, n, "M")
    if real_dtype(m_data.dtype) != real_dtype(a_data.dtype):
        raise ValueError(f"M has dtype {m_data.dtype} but A has dtype {a_data.dtype}")
    if not isinstance(k, int) or not 1 <= k < n:
        raise ValueError(f"k must be an integer with 1 <= k < N = {n}, got {k}")
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    eps = float(torch.finfo(a_data.dtype).eps)
    tol = (1e-12 if eps < 1e-10 else 1e-6) if tol is None else tol
    degeneracy_rtol = eps ** 0.5 if degeneracy_rtol is None else degeneracy_rtol
    lam, X = _Eigsh.apply(a_data.values, m_data.values, a_data, m_data, k, sigma, method, tol,
                          maxiter, ncv, v0, degeneracy_rtol, block_size)
    return EigenPairs(lam, X)
