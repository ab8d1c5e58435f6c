r"""Sparse factorizations: factor once, solve many right-hand sides.

Back-ends
---------
``"cholmod"``
    Cholesky from SuiteSparse CHOLMOD through scikit-sparse (optional extra
    ``torch_edgevf[cholmod]``; needs ``apt-get install libsuitesparse-dev``), simplicial
    :math:`LDL^H` (see :data:`CHOLMOD_MODE`; positive definiteness is checked on ``D``).
    Real symmetric or complex Hermitian positive definite matrices, CHOLMOD's default
    fill-reducing ordering (AMD/METIS).  CHOLMOD works in double precision: float32 and
    complex64 matrices are factored in double and the solutions cast back.
``"superlu-hermitian"``
    SciPy SuperLU in *symmetric mode* (ordering ``MMD_AT_PLUS_A`` applied to rows and
    columns, diagonal pivots, no relaxed supernodes: see :data:`SYMMETRIC_MODE`): for a
    Hermitian positive definite matrix this is an
    :math:`LDL^H` factorization, so positive definiteness is checked on the pivots.  It
    is the Cholesky path when scikit-sparse is not installed (pip-only installs), and
    faster than SuperLU's default mode on the connection Laplacian.
``"cholmod-cvxopt"``
    CHOLMOD as bundled by cvxopt's PyPI wheels (optional extra ``torch_edgevf[cvxopt]``, no
    system library; cvxopt is GPL-3 licensed), real and complex Hermitian, used when
    scikit-sparse is absent: simplicial :math:`LDL^H` for the iterative solvers' many
    solves (positive definiteness checked on ``D``), supernodal :math:`LL^H` for one-off
    factorizations; it factors and solves faster than SuperLU symmetric mode.
``"cholespy"``
    CHOLMOD as bundled by cholespy (optional extra ``torch_edgevf[cholespy]``, PyPI wheels,
    no system library), real symmetric positive definite matrices only.  Used, when
    scikit-sparse is absent, for the real factorizations of the eigensolver, which makes
    dozens to hundreds of solves per factorization: cholespy's solves are faster than
    SuperLU's and its factorization slower, so one-off solves keep SuperLU.  (On an
    indefinite matrix its CHOLMOD prints a warning to stderr before
    ``NotPositiveDefiniteError`` is raised.)
``"superlu"``
    SciPy SuperLU, general mode (``COLAMD`` ordering, partial pivoting) for
    non-Hermitian and indefinite matrices.  Keeps float32/complex64.

Timings of the back-ends are in ``benchmarks/results/linalg_notes.md``.
"""

from __future__ import annotations

import functools
import logging

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from ._utils import _blas_controller, is_hermitian

logger = logging.getLogger(__name__)

METHODS = ("auto", "cholesky", "lu")

#: CHOLMOD factorization mode.  ``"simplicial"`` (an up-looking :math:`LDL^H` without
#: BLAS calls) rather than ``"supernodal"``: on the mesh operators its factor has about a
#: third fewer stored entries (no supernode padding) and its solves are faster, while the
#: supernodal kernels depend on the BLAS that CHOLMOD links.  The iterative solvers make
#: tens to hundreds of solves per factorization, so the solve speed decides.  Timings:
#: ``benchmarks/results/linalg_notes.md``.
CHOLMOD_MODE = "simplicial"


#: ``scipy.sparse.linalg.splu`` options of the symmetric mode (``"superlu-hermitian"``):
#: ordering ``MMD_AT_PLUS_A`` applied to rows and columns, diagonal pivots, and no relaxed
#: supernodes (``relax=1``).  In symmetric mode SuperLU does not postorder the elimination
#: tree, while its relaxed supernodes (small subtrees amalgamated into dense blocks) are
#: found on a postorder and mapped back to the column order; with the default relaxation
#: the dense panel updates, and so the factorization time, depend on the numbering of the
#: input rather than on the fill.  Without relaxation the time follows the fill for every
#: numbering; the fundamental supernodes SuperLU finds during the factorization are kept.
#: Timings: ``benchmarks/results/superlu_symmetric_mode.md`` and ``benchmarks/bench_linalg.py``.
SYMMETRIC_MODE = {
    "permc_spec": "MMD_AT_PLUS_A",
    "diag_pivot_thresh": 0.0,
    "relax": 1,
    "options": {"SymmetricMode": True},
}


@functools.cache
def cholmod_module():
    """``sksparse.cholmod`` if installed, else ``None`` (logged once)."""
    try:
        from sksparse import cholmod
    except ImportError:
        logger.info(
            "scikit-sparse (CHOLMOD) is not installed; Hermitian positive definite systems "
            "are factored with SciPy SuperLU in symmetric mode. Install the optional extra "
            "torch_edgevf[cholmod] (needs libsuitesparse-dev) for faster factorizations."
        )
        return None
    return cholmod


@functools.cache
def cvxopt_cholmod_module():
    """``cvxopt.cholmod`` if installed (and not hidden, see the test set-up), else ``None``."""
    try:
        import cvxopt
        from cvxopt import cholmod
    except ImportError:
        return None
    return cvxopt, cholmod


@functools.cache
def cholespy_module():
    """``cholespy`` if installed, else ``None``."""
    try:
        import cholespy
    except ImportError:
        return None
    return cholespy


class NotPositiveDefiniteError(ValueError):
    """Raised when a Cholesky factorization meets a non positive definite matrix."""


def _singular_error(detail: str = "") -> ValueError:
    return ValueError(f"the matrix is singular{': ' + detail if detail else ''}")


class _Factor:
    """A factorization of a square SciPy matrix ``K``; solves on NumPy arrays."""

    backend = ""
    hermitian = False

    def __init__(self, K: sp.csc_matrix):
        self.n = K.shape[0]
        self.dtype = K.dtype

    def _solve(self, b: np.ndarray, adjoint: bool) -> np.ndarray:
        raise NotImplementedError

    def solve(self, b: np.ndarray, adjoint: bool = False) -> np.ndarray:
        """Solve ``K x = b`` (``K^H x = b`` if ``adjoint``) for ``b`` of shape (N,) or (N, C)."""
        if np.iscomplexobj(b) and not np.iscomplexobj(np.empty(0, self.dtype)):
            x = self._solve(
                np.concatenate([b.real, b.imag], axis=-1)
                if b.ndim == 2
                else np.stack([b.real, b.imag], axis=1),
                adjoint,
            )
            half = x.shape[1] // 2
            x = x[:, :half] + 1j * x[:, half:]
            x = x if b.ndim == 2 else x[:, 0]
        else:
            x = self._solve(np.asarray(b, dtype=np.result_type(b, self.dtype)), adjoint)
        if not np.isfinite(x).all():
            raise _singular_error("the solution is not finite")
        return x


class _SuperLUFactor(_Factor):
    """SciPy SuperLU; ``hermitian=True`` uses symmetric mode with diagonal pivots."""

    def __init__(self, K: sp.csc_matrix, hermitian: bool = False, check_pd: bool = False):
        super().__init__(K)
        self.hermitian = hermitian
        self.backend = "superlu-hermitian" if hermitian else "superlu"
        kwargs = SYMMETRIC_MODE if hermitian else {}
        try:
            # SuperLU's dense kernels are small matrix-vector products: BLAS threads only
            # add synchronisation (on a busy machine, most of the time)
            with _blas_controller().limit(limits=1, user_api="blas"):
                self._lu = sla.splu(K, **kwargs)
        except RuntimeError as err:
            if "singular" in str(err).lower():
                raise _singular_error(str(err)) from err
            raise
        if check_pd and not self._positive_pivots():
            raise NotPositiveDefiniteError("the matrix is not positive definite")

    def _positive_pivots(self) -> bool:
        if not np.array_equal(self._lu.perm_r, self._lu.perm_c):
            return False
        d = self._lu.U.diagonal()
        # Hermitian pivots are real up to rounding, which is relative to the precision
        tol = max(1e-8, 64 * float(np.finfo(d.real.dtype).eps))
        return bool(np.all(d.real > 0) and np.all(np.abs(d.imag) <= tol * np.abs(d.real)))

    def _solve(self, b, adjoint):
        trans = "N" if not adjoint or self.hermitian else ("H" if np.iscomplexobj(b) else "T")
        return self._lu.solve(b, trans=trans)


class _CholmodFactor(_Factor):
    """CHOLMOD Cholesky (double precision), simplicial :math:`LDL^H` by default (see ``CHOLMOD_MODE``)."""

    backend = "cholmod"
    hermitian = True

    def __init__(self, K: sp.csc_matrix, cholmod):
        super().__init__(K)
        wide = np.complex128 if np.iscomplexobj(K.data) else np.float64
        try:
            self._f = cholmod.cholesky(K.astype(wide, copy=False), mode=CHOLMOD_MODE)
        except cholmod.CholmodNotPositiveDefiniteError as err:
            raise NotPositiveDefiniteError("the matrix is not positive definite") from err
        if CHOLMOD_MODE == "simplicial":
            # the simplicial factor is LDL^H: an indefinite matrix shows in the pivots D
            d = self._f.D()
            if not (np.all(d.real > 0) and np.all(np.abs(d.imag) <= 1e-8 * d.real)):
                raise NotPositiveDefiniteError("the matrix is not positive definite")

    def _solve(self, b, adjoint):
        wide = np.result_type(b, np.float64)
        return self._f(b.astype(wide, copy=False)).astype(np.result_type(b, self.dtype), copy=False)


class _CholespyFactor(_Factor):
    """cholespy's CHOLMOD Cholesky of a real symmetric positive definite matrix (double precision)."""

    backend = "cholespy"
    hermitian = True

    def __init__(self, K: sp.csc_matrix, cholespy):
        super().__init__(K)
        K = K.astype(np.float64, copy=False)
        try:
            self._f = cholespy.CholeskySolverD(
                self.n,
                K.indptr.astype(np.int32),
                K.indices.astype(np.int32),
                np.ascontiguousarray(K.data),
                cholespy.MatrixType.CSC,
            )
        except ValueError as err:  # "Matrix is not positive definite!"
            raise NotPositiveDefiniteError("the matrix is not positive definite") from err

    def _solve(self, b, adjoint):
        rhs = np.ascontiguousarray(b, dtype=np.float64)
        x = np.empty_like(rhs)
        self._f.solve(rhs, x)
        return x.astype(np.result_type(b, self.dtype), copy=False)


class _CvxoptCholmodFactor(_Factor):
    """CHOLMOD as bundled by cvxopt's PyPI wheels (real or complex, double precision).

    ``simplicial=True`` (the iterative solvers' many solves) gives :math:`LDL^H`, whose
    pivots ``D`` -- read with one diagonal solve -- certify positive definiteness;
    otherwise the supernodal :math:`LL^H`, which raises on a non positive definite
    matrix and factors faster on large meshes while solving slower.
    """

    backend = "cholmod-cvxopt"
    hermitian = True

    def __init__(self, K: sp.csc_matrix, cvxopt, cholmod, simplicial: bool = True):
        super().__init__(K)
        self._cvxopt, self._cholmod = cvxopt, cholmod
        self.simplicial = simplicial
        self._complex = np.iscomplexobj(K.data)
        self._tc = "z" if self._complex else "d"
        low = sp.tril(K, format="coo")
        data = low.data.astype(np.complex128 if self._complex else np.float64, copy=False)
        A = cvxopt.spmatrix(
            cvxopt.matrix(np.ascontiguousarray(data)),
            cvxopt.matrix(low.row.astype(np.int64)),
            cvxopt.matrix(low.col.astype(np.int64)),
            K.shape,
            self._tc,
        )
        cholmod.options["supernodal"] = 0 if simplicial else 2
        try:
            self._f = cholmod.symbolic(A, uplo="L")
            cholmod.numeric(A, self._f)
        except ArithmeticError as err:
            raise NotPositiveDefiniteError("the matrix is not positive definite") from err
        finally:
            cholmod.options.pop("supernodal", None)
        if simplicial:
            inv_d = cvxopt.matrix(np.ones(self.n, dtype=np.complex128 if self._complex else np.float64))
            cholmod.solve(self._f, inv_d, sys=6)  # D x = 1: x = 1 / d
            inv_d = np.array(inv_d)[:, 0]
            if not (
                np.all(np.isfinite(inv_d))
                and np.all(inv_d.real > 0)
                and np.all(np.abs(inv_d.imag) <= 1e-8 * inv_d.real)
            ):
                raise NotPositiveDefiniteError("the matrix is not positive definite")

    def _solve(self, b, adjoint):
        wide = np.complex128 if self._complex else np.float64
        B = self._cvxopt.matrix(np.asfortranarray(b.reshape(self.n, -1), dtype=wide))
        self._cholmod.solve(self._f, B)
        x = np.array(B)
        x = x if b.ndim == 2 else x[:, 0]
        return x.astype(np.result_type(b, self.dtype), copy=False)


def factorize(
    K: sp.spmatrix, method: str = "auto", hermitian: bool | None = None, many_solves: bool = False
) -> _Factor:
    """Factor the SciPy matrix ``K`` with the best available back-end.

    Parameters
    ----------
    K : (N, N) scipy sparse matrix
    method : {"auto", "cholesky", "lu"}
        ``"cholesky"`` requires a Hermitian positive definite ``K`` (``ValueError``
        otherwise); ``"lu"`` is SuperLU with partial pivoting; ``"auto"`` tries the
        Cholesky path on Hermitian matrices and falls back to LU when it fails.
    hermitian : bool, optional
        Skip the (cheap) check ``K == K^H`` when given.
    many_solves : bool
        The caller will solve many times with the factor (an iterative solver): without
        CHOLMOD, a real positive definite ``K`` is then factored with cholespy when it is
        installed (slower factorization, 3-4x faster solves than SuperLU).
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    K = sp.csc_matrix(K)
    if hermitian is None:
        hermitian = is_hermitian(K)
    if method == "cholesky" and not hermitian:
        raise ValueError("method='cholesky' needs a Hermitian (symmetric) matrix")
    if method in ("auto", "cholesky") and hermitian:
        try:
            return _cholesky(K, many_solves)
        except NotPositiveDefiniteError:
            if method == "cholesky":
                raise
            logger.debug("Cholesky failed (matrix not positive definite); using LU")
    return _SuperLUFactor(K, hermitian=False)


def _cholesky(K: sp.csc_matrix, many_solves: bool = False) -> _Factor:
    cholmod = cholmod_module()
    if cholmod is not None:
        return _CholmodFactor(K, cholmod)
    cvx = cvxopt_cholmod_module()
    if cvx is not None:
        cvxopt, cvxopt_cholmod = cvx
        return _CvxoptCholmodFactor(K, cvxopt, cvxopt_cholmod, simplicial=many_solves)
    if many_solves and not np.iscomplexobj(K.data):
        cholespy = cholespy_module()
        if cholespy is not None:
            return _CholespyFactor(K, cholespy)
        _log_no_cholespy()
    return _SuperLUFactor(K, hermitian=True, check_pd=True)


@functools.cache
def _log_no_cholespy():
    logger.info(
        "neither scikit-sparse nor cholespy is installed; real positive definite systems "
        "are factored with SciPy SuperLU, whose solves are 3-4x slower (pip install "
        "'torch_edgevf[cholespy]')"
    )
