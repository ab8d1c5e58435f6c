"""Sparse solves: accuracy against dense solves, back-ends, gradients, errors."""

import logging

import pytest
import torch
from test_problems import grid_laplacian, random_general

from torch_edgevf.linalg import SparseSolver, solve, solve_constrained, solve_fixed
from torch_edgevf.linalg import factor as factor_module

CASES = {
    "real_spd": lambda: grid_laplacian(4, 5, torch.float64, shift=0.1).A,
    "complex_hermitian": lambda: grid_laplacian(4, 5, torch.complex128).A,
    "real_general": lambda: random_general(9, torch.float64),
    "complex_general": lambda: random_general(9, torch.complex128),
}
EXPECTED_BACKEND = {
    "real_spd": "cholesky",
    "complex_hermitian": "cholesky",
    "real_general": "superlu",
    "complex_general": "superlu",
}


@pytest.fixture(params=["cholmod", "pip-only"])
def backend(request, monkeypatch):
    """Run with CHOLMOD (when installed) and with the pip-only SuperLU path."""
    if request.param == "cholmod":
        pytest.importorskip("sksparse.cholmod")
    else:
        monkeypatch.setattr(factor_module, "cholmod_module", lambda: None)
        monkeypatch.setattr(factor_module, "cvxopt_cholmod_module", lambda: None)
    return request.param


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("cols", [None, 3])
def test_solve_matches_dense(case, cols, backend):
    A = CASES[case]()
    n = A.shape[0]
    shape = (n,) if cols is None else (n, cols)
    b = torch.randn(shape, dtype=A.dtype, generator=torch.Generator().manual_seed(1))
    solver = SparseSolver(A)
    x = solver.solve(b)
    ref = torch.linalg.solve(A.to_dense(), b)
    torch.testing.assert_close(x, ref, rtol=1e-10, atol=1e-12)
    torch.testing.assert_close(
        solver.solve_adjoint(b), torch.linalg.solve(A.to_dense().mH, b), rtol=1e-10, atol=1e-12
    )
    if EXPECTED_BACKEND[case] == "cholesky":
        assert solver.backend == ("cholmod" if backend == "cholmod" else "superlu-hermitian")
    else:
        assert solver.backend == "superlu"


def test_complex_rhs_with_real_matrix():
    A = CASES["real_spd"]()
    b = torch.randn(A.shape[0], 2, dtype=torch.complex128)
    torch.testing.assert_close(solve(A, b), torch.linalg.solve(A.to_dense().to(b.dtype), b))


def test_float32_keeps_dtype(backend):
    A = grid_laplacian(4, 5, torch.complex64, shift=0.1).A
    b = torch.randn(A.shape[0], dtype=torch.complex64)
    x = solve(A, b)
    assert x.dtype == torch.complex64
    torch.testing.assert_close(x, torch.linalg.solve(A.to_dense(), b), rtol=1e-4, atol=1e-5)


def test_repeated_solves_are_bitwise_identical_and_match_function():
    A = CASES["complex_hermitian"]()
    b = torch.randn(A.shape[0], 4, dtype=A.dtype)
    solver = SparseSolver(A)
    x1, x2 = solver.solve(b), solver.solve(b)
    assert torch.equal(x1, x2)
    assert torch.equal(solve(solver, b), x1)
    torch.testing.assert_close(solve(A, b), x1, rtol=1e-12, atol=1e-14)


def test_inputs_not_modified():
    A = CASES["complex_general"]()
    b = torch.randn(A.shape[0], dtype=A.dtype)
    A0, b0 = A.clone(), b.clone()
    solve(A, b)
    assert torch.equal(A.to_dense(), A0.to_dense()) and torch.equal(b, b0)


@pytest.mark.parametrize("dtype", [torch.float64, torch.complex128])
@pytest.mark.parametrize("adjoint", [False, True])
def test_gradcheck_general(dtype, adjoint, gradcheck):
    A = random_general(6, dtype).coalesce()
    idx = A.indices()
    b = torch.randn(6, 2, dtype=dtype, requires_grad=True)

    def f(values, b):
        return solve(torch.sparse_coo_tensor(idx, values, A.shape), b, adjoint=adjoint)

    assert gradcheck(f, (A.values().clone().requires_grad_(), b))


@pytest.mark.parametrize("dtype", [torch.float64, torch.complex128])
def test_gradcheck_hermitian_through_construction(dtype, backend, gradcheck):
    p = grid_laplacian(3, 4, dtype, shift=0.2)
    b = torch.randn(p.n, dtype=dtype, requires_grad=True)

    def f(params, b):
        return solve(p.hermitian(params), b)

    assert gradcheck(f, (p.params.clone().requires_grad_(), b))


def test_gradient_is_on_the_pattern():
    A = CASES["complex_hermitian"]()
    values = A.values().clone().requires_grad_()
    x = solve(torch.sparse_coo_tensor(A.indices(), values, A.shape), torch.ones(A.shape[0], dtype=A.dtype))
    x.abs().pow(2).sum().backward()
    assert values.grad.shape == values.shape
    # reference: dense gradient restricted to the pattern
    D = A.to_dense().clone().requires_grad_()
    torch.linalg.solve(D, torch.ones(A.shape[0], dtype=A.dtype)).abs().pow(2).sum().backward()
    torch.testing.assert_close(values.grad, D.grad[A.indices()[0], A.indices()[1]])


def test_prefactored_solver_differentiates_through_its_values():
    A = CASES["real_spd"]().coalesce()
    values = A.values().clone().requires_grad_()
    solver = SparseSolver(torch.sparse_coo_tensor(A.indices(), values, A.shape))
    b = torch.randn(A.shape[0], dtype=A.dtype)
    (solver.solve(b).sum() + solver.solve_adjoint(b).sum()).backward()
    assert values.grad is not None and torch.isfinite(values.grad).all()


@pytest.mark.parametrize("dtype", [torch.float64, torch.complex128])
def test_solve_fixed(dtype, gradcheck):
    p = grid_laplacian(3, 4, dtype)
    fixed = torch.tensor([0, 5, 11])
    fv = torch.randn(3, dtype=dtype)
    b = torch.randn(p.n, dtype=dtype)
    x = solve_fixed(p.A, b, fixed, fv)
    torch.testing.assert_close(x[fixed], fv)
    free = torch.tensor([k for k in range(p.n) if k not in fixed.tolist()])
    torch.testing.assert_close((p.A.to_dense() @ x)[free], b[free])

    def f(params, b, fv):
        return solve_fixed(p.hermitian(params), b, fixed, fv)

    inputs = (p.params.clone().requires_grad_(), b.requires_grad_(), fv.requires_grad_())
    assert gradcheck(f, inputs)


@pytest.mark.parametrize("dtype", [torch.float64, torch.complex128])
def test_solve_constrained(dtype, gradcheck):
    p = grid_laplacian(3, 4, dtype, shift=0.1)
    C = random_general(p.n, dtype, density=0.7, seed=3).to_dense()[:2].to_sparse().coalesce()
    d = torch.randn(2, dtype=dtype)
    b = torch.randn(p.n, dtype=dtype)
    x, mu = solve_constrained(p.A, b, C, d, return_multipliers=True)
    torch.testing.assert_close(C.to_dense() @ x, d)
    torch.testing.assert_close(p.A.to_dense() @ x + C.to_dense().mH @ mu, b)

    def f(params, b, cv, d):
        return solve_constrained(p.hermitian(params), b, torch.sparse_coo_tensor(C.indices(), cv, C.shape), d)

    inputs = (
        p.params.clone().requires_grad_(),
        b.requires_grad_(),
        C.values().clone().requires_grad_(),
        d.requires_grad_(),
    )
    assert gradcheck(f, inputs)


def test_missing_cholmod_logs_once(monkeypatch, caplog):
    import builtins

    real_import = builtins.__import__

    def fake_import(name, *args, **kwargs):
        if name.startswith("sksparse"):
            raise ImportError("no sksparse")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    monkeypatch.setattr(factor_module, "cvxopt_cholmod_module", lambda: None)
    factor_module.cholmod_module.cache_clear()
    try:
        with caplog.at_level(logging.INFO, logger=factor_module.__name__):
            A = CASES["real_spd"]()
            SparseSolver(A)
            SparseSolver(A)
        messages = [r for r in caplog.records if "CHOLMOD" in r.getMessage()]
        assert len(messages) == 1
        assert SparseSolver(A).backend == "superlu-hermitian"
    finally:
        factor_module.cholmod_module.cache_clear()


# ---------------------------------------------------------------------------- errors


def test_error_non_square():
    with pytest.raises(ValueError, match="A must be square, got shape \\(3, 4\\)"):
        solve(torch.zeros(3, 4).to_sparse(), torch.zeros(3))


def test_error_not_a_matrix():
    with pytest.raises(ValueError, match="A must be a 2-D matrix"):
        SparseSolver(torch.zeros(3))


def test_error_rhs_shape():
    A = CASES["real_spd"]()
    with pytest.raises(ValueError, match=r"b must have shape \(20,\) or \(20, C\), got \(19,\)"):
        solve(A, torch.zeros(19, dtype=A.dtype))


def test_error_precision_mismatch():
    A = CASES["real_spd"]()
    with pytest.raises(ValueError, match="same precision"):
        solve(A, torch.zeros(20, dtype=torch.float32))


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_error_nan_inf(bad):
    A = CASES["real_spd"]().coalesce()
    vals = A.values().clone()
    vals[3] = bad
    with pytest.raises(ValueError, match="A contains NaN or Inf"):
        solve(torch.sparse_coo_tensor(A.indices(), vals, A.shape), torch.zeros(20, dtype=A.dtype))
    b = torch.zeros(20, dtype=A.dtype)
    b[0] = bad
    with pytest.raises(ValueError, match="b contains NaN or Inf"):
        solve(A, b)


@pytest.mark.parametrize("method", ["auto", "lu"])
def test_error_singular(method):
    A = torch.tensor([[1.0, 2.0], [2.0, 4.0]], dtype=torch.float64).to_sparse()
    with pytest.raises(ValueError, match="singular"):
        solve(A, torch.ones(2, dtype=torch.float64), method=method)


def test_error_indefinite_cholesky(backend):
    A = torch.tensor([[1.0, 2.0], [2.0, 1.0]], dtype=torch.float64).to_sparse()
    with pytest.raises(ValueError, match="not positive definite"):
        SparseSolver(A, method="cholesky")
    assert SparseSolver(A).backend == "superlu"  # auto falls back to LU


def test_error_cholesky_non_hermitian():
    with pytest.raises(ValueError, match="needs a Hermitian"):
        SparseSolver(CASES["real_general"](), method="cholesky")


def test_error_unknown_method():
    with pytest.raises(ValueError, match="method must be one of"):
        SparseSolver(CASES["real_spd"](), method="qr")


def test_error_fixed_index():
    A = CASES["real_spd"]()
    with pytest.raises(ValueError, match="fixed_idx has repeated entries"):
        solve_fixed(A, torch.zeros(20, dtype=A.dtype), torch.tensor([1, 1]), torch.zeros(2, dtype=A.dtype))
    with pytest.raises(ValueError, match=r"fixed_idx has entries outside \[0, 20\)"):
        solve_fixed(A, torch.zeros(20, dtype=A.dtype), torch.tensor([20]), torch.zeros(1, dtype=A.dtype))


def test_error_constraint_shape():
    A = CASES["real_spd"]()
    with pytest.raises(ValueError, match=r"C must be a \(m, 20\) matrix"):
        solve_constrained(A, torch.zeros(20, dtype=A.dtype), torch.zeros(2, 19).to_sparse(), torch.zeros(2))


# ------------------------------------------------------------------ sparse_matrix


def test_sparse_matrix_matches_torch_constructor_and_gradients():
    from torch_edgevf.linalg import sparse_matrix

    A = CASES["complex_hermitian"]().coalesce()
    idx = A.indices()
    b = torch.randn(A.shape[0], 2, dtype=A.dtype, generator=torch.Generator().manual_seed(2))
    v1 = A.values().clone().requires_grad_()
    v2 = A.values().clone().requires_grad_()
    S = sparse_matrix(idx, v1, A.shape)
    assert S.is_coalesced() and torch.equal(S.to_dense(), A.to_dense())
    x1 = solve(S, b)
    x2 = solve(torch.sparse_coo_tensor(idx, v2, A.shape), b)
    torch.testing.assert_close(x1, x2, rtol=0, atol=0)
    g = torch.randn(x1.shape, dtype=x1.dtype, generator=torch.Generator().manual_seed(3))
    (g1,) = torch.autograd.grad(x1, v1, g)
    (g2,) = torch.autograd.grad(x2, v2, g)
    torch.testing.assert_close(g1, g2, rtol=1e-14, atol=0)


@pytest.mark.parametrize("dtype", [torch.float64, torch.complex128])
def test_gradcheck_sparse_matrix(dtype, gradcheck):
    from torch_edgevf.linalg import sparse_matrix

    A = grid_laplacian(3, 4, dtype, shift=0.3).A.coalesce()
    idx = A.indices()
    b = torch.randn(A.shape[0], dtype=dtype, requires_grad=True)

    def f(values, b):
        S = sparse_matrix(idx, values, A.shape)
        return solve(S, b), S.to_dense().diagonal()  # a sparse and a dense gradient path

    assert gradcheck(f, (A.values().clone().requires_grad_(), b))


def test_sparse_matrix_unsorted_indices_fall_back_to_coalesce():
    from torch_edgevf.linalg import sparse_matrix

    idx = torch.tensor([[1, 0, 1, 0], [1, 0, 0, 0]])
    v = torch.tensor([2.0, 1.0, 3.0, 4.0], dtype=torch.float64, requires_grad=True)
    S = sparse_matrix(idx, v, (2, 2))
    torch.testing.assert_close(S.to_dense(), torch.tensor([[5.0, 0.0], [3.0, 2.0]], dtype=torch.float64))
    S.to_dense().sum().backward()
    torch.testing.assert_close(v.grad, torch.ones(4, dtype=torch.float64))
    with pytest.raises(ValueError, match="indices must be"):
        sparse_matrix(idx[:1], v, (2, 2))
