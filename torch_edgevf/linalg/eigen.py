r"""Differentiable generalized Hermitian eigenpairs :math:`A x = \lambda M x` (thesis 3.1).

Forward
-------
:mod:`~torch_edgevf.linalg.lanczos`: shift-invert block Lanczos on
:math:`(A - \sigma M)^{-1} M` with a factor of :math:`A - \sigma M`, dense for small
problems; eigenvectors :math:`M`-orthonormal, :math:`X^H M X = I`, each scaled so that
its entry of largest modulus is real and positive.  This makes the result a well-defined
function of the matrices where that entry is unique; losses that are invariant to the
phase (``|x|^2``, projectors :math:`x x^H`) are recommended.

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
import torch

from .._dtypes import real_dtype
from . import components, shift_invert
from ._utils import (
    SparseData,
    as_matrix_pair,
    blas_single_thread,
    from_numpy,
    pattern_outer,
    to_numpy,
)
from .factor import factorize
from .shift_invert import METHODS, default_shift

logger = logging.getLogger(__name__)
#: A_ii / M_ii this many times the median marks rows of an ill-conditioned pencil
_ILL_CONDITIONED = 1e8

__all__ = ["EigenPairs", "eigsh", "default_shift"]


class EigenPairs(NamedTuple):
    """Result of :func:`eigsh`: ``values`` (k,) ascending, ``vectors`` (N, k)."""

    values: torch.Tensor
    vectors: torch.Tensor


# ---------------------------------------------------------------------------- backward


def _pattern_outer(left, right, data: SparseData):
    return pattern_outer(left, right, data).to(left.device)


def _to_input(grad, values):
    return grad if values.is_complex() else grad.real.to(values.dtype)


def _unreliable_message(A, M, e) -> str:
    """Why the eigenpairs are not returned, and the rows to look at when one is to blame."""
    ratio = shift_invert.diagonal_ratio(A, M)
    median = float(np.median(ratio)) if ratio.size else 0.0
    msg = f"eigsh: {e}; the eigenpairs would be wrong, so none are returned"
    if median > 0 and ratio.max() > _ILL_CONDITIONED * median:
        rows = np.argsort(ratio)[::-1][: min(5, int((ratio > _ILL_CONDITIONED * median).sum()))]
        msg += (
            f". Rows {rows.tolist()} have A_ii / M_ii up to {ratio.max() / median:.1e} times the "
            "median: nearly degenerate faces (needles, caps) at those vertices or edges make the low "
            "eigenpairs ill-conditioned; repair the mesh (torch_edgevf.mesh.repair) or use the "
            "intrinsic Delaunay Laplacian"
        )
    else:
        msg += "; raise maxiter or tol (arguments of eigsh, smoothest_field and FieldDesigner.smoothest)"
    return msg


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
    for _ in range(maxiter):
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
            "(small gap after the k-th eigenvalue?)",
            maxiter,
        )
    return W


class _SolveOptions(NamedTuple):
    """The options of :func:`eigsh` that the forward pass takes (no gradient)."""

    k: int
    sigma: float | None
    method: str
    tol: float
    maxiter: int | None
    ncv: int | None
    v0: object
    degeneracy_rtol: float
    block_size: int | None


class _Eigsh(torch.autograd.Function):
    @staticmethod
    @blas_single_thread
    def forward(ctx, a_values, m_values, a_data, m_data, options: _SolveOptions):
        k, sigma, method, tol, maxiter, ncv, v0, degeneracy_rtol, block_size = options
        A = a_data.to_scipy()
        M = m_data.to_scipy().astype(A.real.dtype)
        # the pencil divided by powers of two (exact): the same numbers at every scale
        A, M, scaling = shift_invert.normalize_pair(A, M)
        sigma = default_shift(A, M) if sigma is None else scaling.normalized_shift(sigma)
        ctx.factor = None
        if method == "auto":
            method = "dense" if shift_invert.dense_is_faster(A.shape[0], k) else "lanczos"
        try:
            rows = None if method == "dense" else components.blocks(A, M)
            if method == "dense":
                lam, X = shift_invert.eig_dense(A, M, k)
            elif rows is not None:  # independent blocks (a mesh in pieces): one solve each
                lam, X = components.eigsh_by_blocks(
                    A, M, sigma, k, rows, tol=tol, maxiter=maxiter, ncv=ncv, v0=v0, block_size=block_size
                )
                if lam.size < k:
                    raise ValueError(
                        f"eigsh: k = {k} eigenpairs asked for, but the pencil has {lam.size}: "
                        f"{A.shape[0] - sum(r.size for r in rows)} rows have no mass"
                    )
            else:
                lam, X, ctx.factor = shift_invert.shift_invert_eigsh(
                    A, M, sigma, k, tol=tol, maxiter=maxiter, ncv=ncv, v0=v0, block_size=block_size
                )
        except shift_invert.Unreliable as e:
            raise ValueError(_unreliable_message(A, M, e)) from None
        lam, X = scaling.values(lam), scaling.vectors(shift_invert.fix_phase(X))
        # the backward's complement solve runs on the normalised pair too
        ctx.A, ctx.M, ctx.sigma, ctx.degeneracy_rtol = A, M, sigma, degeneracy_rtol
        ctx.scaling = scaling
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
        return grad_a, grad_m, None, None, None


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
    if bool((skew > 1e-6 * XG.abs().max().clamp_min(torch.finfo(lam.dtype).tiny)).any()):
        raise ValueError(
            "eigenvector gradient is undefined: the loss depends on the basis chosen inside "
            "a degenerate eigenspace; use a loss invariant to rotations within it "
            "(e.g. of the projector X X^H) or perturb the problem"
        )
    F = torch.where(
        degenerate,
        torch.zeros_like(XG),
        XG / torch.where(degenerate, 1.0, diff).fill_diagonal_(1.0).to(XG.dtype),
    )
    F.fill_diagonal_(0)
    U = X @ F
    W = _complement_adjoint(ctx, lam, X, G)
    return U - W, XG.diagonal().real


def _complement_adjoint(ctx, lam, X, G):
    n, k = X.shape
    if k >= n:
        return torch.zeros_like(X)
    # on the normalised pair A = 2^a A', M = 2^m M' (shift_invert.PairScaling): with X = 2^(-m/2) X'
    # and lam = 2^(a - m) lam', (A - lam_i M) w_i = r_i is 2^a (A' - lam'_i M') w_i = r_i
    # and M X X^H = M' X' X'^H, so w_i = 2^-a w'_i; r is divided by a power of two too,
    # so that the CG's inner products neither under- nor overflow
    A, M, scaling = ctx.A, ctx.M, ctx.scaling
    Xn = scaling.normalized_vectors(to_numpy(X))
    lam_n = scaling.normalized_values(to_numpy(lam))
    Gn = to_numpy(G)
    R = Gn - (M @ Xn) @ (Xn.conj().T @ Gn)
    r_exp = shift_invert.binary_exponent(float(np.max(np.abs(R)))) if R.size else 0
    if ctx.factor is None:
        ctx.factor = factorize((A - ctx.sigma * M).tocsc(), "auto", hermitian=True, many_solves=True)
    eps = float(np.finfo(A.dtype).eps)
    W = _complement_solve(
        A,
        M,
        Xn,
        lam_n,
        shift_invert.ldexp(R, -r_exp),
        ctx.factor.solve,
        tol=max(1e-12, 10 * eps),
        maxiter=max(100, min(n, 1000)),
    )
    return from_numpy(shift_invert.ldexp(W, r_exp - scaling.a_exp), X, X.dtype)


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
        ``"dense"`` uses ``scipy.linalg.eigh`` (``auto`` for ``N <= 300``, and for
        ``N <= min(6 k, 4000)``, where the Lanczos basis would hold half of ``N``).
    tol : float, optional
        Relative Ritz residual of the shift-inverted operator; default ``1e-13``
        (float64) or ``1e-6`` (float32): the last digits are cheap once the basis holds
        them.  For ``k > 1`` a residual of ``10 eps ||T||`` (``T``: the shift-inverted
        operator) is accepted too, the rounding floor: with a singular ``A`` (the
        Laplace-Beltrami operator) the small default shift makes ``||T||`` about ``1e5``
        times the wanted ``theta``, which could not reach ``tol |theta|``.
    maxiter, ncv, v0
        Lanczos restarts, basis size (default ``max(3k, 2k + 2 min(k, 6))``, capped by ``N``;
        24 for ``k = 1``), start vector(s).
    block_size : int, optional
        Fixed Lanczos block size.  Eigenvalues of multiplicity up to the block size are
        all found.  Default: adaptive, ``min(k, 2)`` doubling, up to ``min(k, 6)``, each
        time a block's worth of converged Ritz values coincide -- the trace that a block
        Lanczos leaves of a higher multiplicity -- so that the clusters of up to 5 or 6
        equal eigenvalues of symmetric meshes (icospheres) are found, while meshes
        without multiple eigenvalues keep the cheaper small block; from ``k = 64`` on,
        the largest block from the start (with a large basis, fewer solves of more
        vectors each are cheaper).  ``k = 1`` (without
        ``block_size``) uses the single-vector fast path (Rayleigh-Ritz accelerated
        inverse iteration), stopping on the same residual tolerance; it returns the better
        of the Ritz and the harmonic Ritz vector, whose residual in ``A x = lambda M x`` is
        typically an order of magnitude lower.
    degeneracy_rtol : float, optional
        Relative gap under which two eigenvalues count as degenerate in the eigenvector
        backward; default ``sqrt(eps)``.

    Returns
    -------
    EigenPairs
        ``values`` (k,) real, ascending; ``vectors`` (N, k), :math:`X^H M X = I`, each
        column's largest-modulus entry real positive.  Dtypes follow ``A``.
    """
    a_data, m_data = as_matrix_pair(A, M)
    n = a_data.n
    if not isinstance(k, int) or not 1 <= k < n:
        raise ValueError(f"k must be an integer with 1 <= k < N = {n}, got {k}")
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    eps = float(torch.finfo(a_data.dtype).eps)
    tol = (1e-13 if eps < 1e-10 else 1e-6) if tol is None else tol
    degeneracy_rtol = eps**0.5 if degeneracy_rtol is None else degeneracy_rtol
    options = _SolveOptions(k, sigma, method, tol, maxiter, ncv, v0, degeneracy_rtol, block_size)
    lam, X = _Eigsh.apply(a_data.values, m_data.values, a_data, m_data, options)
    return EigenPairs(lam, X)
