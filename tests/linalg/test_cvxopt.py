"""The cvxopt back-end: CHOLMOD from cvxopt's PyPI wheels, real and complex Hermitian.

Like the cholespy tests, these run only in a process where scikit-sparse cannot be loaded
(CI: ``EDGEVF_HIDE_CHOLMOD=1``, a separate step), so that two CHOLMOD builds never share a
process; they skip elsewhere.
"""

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.linalg as sla
import torch
from test_problems import grid_laplacian

from torch_edgevf.linalg import SparseSolver, eigsh, solve
from torch_edgevf.linalg._utils import as_sparse

from conftest import record_instances


@pytest.fixture
def fm(monkeypatch):
    """The factor module with scikit-sparse hidden and cvxopt installed (else skip)."""
    from torch_edgevf.linalg import factor as factor_module

    if factor_module.cholmod_module() is not None:
        pytest.skip(
            "scikit-sparse is loadable: the cvxopt tests run in a process without it (EDGEVF_HIDE_CHOLMOD=1)"
        )
    if factor_module.cvxopt_cholmod_module() is None:
        pytest.skip("cvxopt is not installed")
    return factor_module


def _scipy(A):
    return as_sparse(A).to_scipy().tocsc()


@pytest.mark.parametrize("dtype", [torch.float64, torch.complex128])
@pytest.mark.parametrize("many_solves", [False, True])
def test_factor_solves_like_spsolve(fm, dtype, many_solves):
    """Simplicial LDL^H for many solves, supernodal LL^H otherwise; vectors, blocks, complex b."""
    K = _scipy(grid_laplacian(7, 8, dtype, magnetic=dtype.is_complex, shift=0.1).A)
    f = fm.factorize(K, "auto", hermitian=True, many_solves=many_solves)
    assert f.backend == "cholmod-cvxopt"
    rng = np.random.default_rng(0)
    for b in (
        rng.standard_normal(56),
        rng.standard_normal((56, 3)),
        rng.standard_normal((56, 2)) + 1j * rng.standard_normal((56, 2)),
    ):
        ref = sla.spsolve(K.astype(np.result_type(K.dtype, b.dtype)), b)
        np.testing.assert_allclose(f.solve(b), ref.reshape(b.shape), rtol=1e-11, atol=1e-12)
        np.testing.assert_allclose(f.solve(b, adjoint=True), f.solve(b), rtol=0, atol=0)


@pytest.mark.parametrize("many_solves", [False, True])
@pytest.mark.parametrize("dtype", [torch.float64, torch.complex128])
def test_indefinite_is_refused_and_auto_falls_back_to_lu(fm, many_solves, dtype):
    """Supernodal LL^H fails on the matrix; simplicial LDL^H is caught on its pivots D."""
    K = _scipy(grid_laplacian(6, 7, dtype, magnetic=dtype.is_complex, shift=0.1).A)
    Ki = (K - 2.0 * scipy.sparse.identity(K.shape[0])).tocsc()
    with pytest.raises(fm.NotPositiveDefiniteError):
        fm.factorize(Ki, "cholesky", hermitian=True, many_solves=many_solves)
    assert fm.factorize(Ki, "auto", hermitian=True, many_solves=many_solves).backend == "superlu"


def test_float32_is_factored_in_double_and_cast_back(fm):
    p = grid_laplacian(6, 7, torch.float32, shift=0.1)
    b = torch.randn(42, dtype=torch.float32, generator=torch.Generator().manual_seed(0))
    solver = SparseSolver(p.A)
    assert solver.backend == "cholmod-cvxopt"
    x = solver.solve(b)
    assert x.dtype == torch.float32
    torch.testing.assert_close(x, torch.linalg.solve(p.A.to_dense(), b), rtol=1e-5, atol=1e-6)


def test_gradcheck_solve(fm):
    """Gradients with respect to b and to the matrix values through the cvxopt factor."""
    p = grid_laplacian(3, 4, torch.complex128, magnetic=True, shift=0.2)
    b = torch.randn(12, dtype=torch.complex128, generator=torch.Generator().manual_seed(2))

    def f(params, rhs):
        return solve(SparseSolver(p.hermitian(params)), rhs)

    assert SparseSolver(p.hermitian(p.params)).backend == "cholmod-cvxopt"
    assert torch.autograd.gradcheck(f, (p.params.clone().requires_grad_(), b.clone().requires_grad_()))


@pytest.mark.parametrize("k", [1, 6])
def test_eigsh_matches_dense(fm, k, monkeypatch):
    """k > 1 (many solves) factors simplicial LDL^H, the smallest pair supernodal LL^H."""
    made = record_instances(monkeypatch, fm, "_CvxoptCholmodFactor")
    p = grid_laplacian(9, 11, torch.complex128, magnetic=True, shift=0.05)
    lam, X = eigsh(p.A, p.m, k, method="lanczos")
    assert [f.simplicial for f in made] == [k > 1]
    ref = scipy.linalg.eigh(p.A.to_dense().numpy(), np.diag(p.m.numpy()), subset_by_index=[0, k - 1])[0]
    np.testing.assert_allclose(lam.numpy(), ref, rtol=1e-11)
    Md = torch.diag(p.m).to(X.dtype)
    torch.testing.assert_close(X.mH @ Md @ X, torch.eye(k, dtype=X.dtype), atol=1e-12, rtol=0)


def test_gradcheck_eigenvalues(fm):
    p = grid_laplacian(4, 5, torch.complex128, magnetic=True, shift=0.05)

    def f(params, m):
        return eigsh(p.hermitian(params), m, 2, method="lanczos").values

    assert torch.autograd.gradcheck(f, (p.params.clone().requires_grad_(), p.m.clone().requires_grad_()))
