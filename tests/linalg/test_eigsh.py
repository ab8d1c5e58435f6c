"""Generalized Hermitian eigenpairs: accuracy, conventions, gradients, errors."""

import contextlib

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse
import torch
from test_problems import grid_laplacian

from torch_edgevf.linalg import components, eigsh

from conftest import record_instances

DTYPES = [torch.float64, torch.complex128]
METHODS = ["dense", "lanczos"]


def reference(p, k):
    return scipy.linalg.eigh(p.A.to_dense().numpy(), np.diag(p.m.numpy()), subset_by_index=[0, k - 1])


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("method", METHODS)
def test_matches_dense_eigh(dtype, method):
    p = grid_laplacian(6, 7, dtype)
    k = 5
    lam, X = eigsh(p.A, p.m, k, method=method)
    ref_lam, ref_X = reference(p, k)
    np.testing.assert_allclose(lam.numpy(), ref_lam, rtol=1e-10, atol=1e-12)
    assert torch.all(lam[1:] >= lam[:-1])  # ascending
    Md = torch.diag(p.m).to(dtype)
    torch.testing.assert_close(X.mH @ Md @ X, torch.eye(k, dtype=dtype), atol=1e-10, rtol=0)
    # same eigenvectors up to phase: |<x, M x_ref>| = 1
    overlap = (X.mH @ Md @ torch.from_numpy(ref_X).to(dtype)).abs().diagonal()
    torch.testing.assert_close(overlap, torch.ones(k, dtype=overlap.dtype), atol=1e-8, rtol=0)
    A = p.A.to_dense()
    torch.testing.assert_close(A @ X, Md @ X * lam.to(dtype), atol=1e-9, rtol=0)


@pytest.mark.parametrize("dtype", DTYPES)
def test_phase_convention(dtype):
    p = grid_laplacian(5, 5, dtype)
    _, X = eigsh(p.A, p.m, 4, method="lanczos")
    pivot = X[X.abs().argmax(0), torch.arange(4)]
    assert torch.all(pivot.real > 0)
    torch.testing.assert_close(
        pivot.imag if dtype.is_complex else torch.zeros(4, dtype=dtype),
        torch.zeros(4, dtype=torch.float64),
        atol=1e-14,
        rtol=0,
    )


def test_singular_laplacian_default_shift():
    """The real grid Laplacian is singular (constants); the default shift handles it."""
    p = grid_laplacian(10, 12, torch.float64)
    lam, X = eigsh(p.A, p.m, 3, method="lanczos")
    assert abs(float(lam[0])) < 1e-10
    const = X[:, 0] / X[:, 0].mean()
    torch.testing.assert_close(const, torch.ones_like(const), atol=1e-8, rtol=0)
    np.testing.assert_allclose(lam.numpy(), reference(p, 3)[0], atol=1e-10)


@pytest.mark.parametrize("method", METHODS)
def test_single_smallest_pair(method):
    p = grid_laplacian(8, 9, torch.complex128)
    lam, X = eigsh(p.A, p.m, 1, method=method)
    assert lam.shape == (1,) and X.shape == (p.n, 1)
    np.testing.assert_allclose(lam.numpy(), reference(p, 1)[0], rtol=1e-10)


def test_identity_mass_and_sparse_mass_agree():
    p = grid_laplacian(5, 6, torch.complex128)
    lam_vec, _ = eigsh(p.A, p.m, 3, method="lanczos")
    lam_sp, _ = eigsh(p.A, torch.diag(p.m).to_sparse(), 3, method="lanczos")
    torch.testing.assert_close(lam_vec, lam_sp, rtol=1e-10, atol=0)
    lam_id, _ = eigsh(p.A, None, 3, method="lanczos")
    np.testing.assert_allclose(lam_id.numpy(), np.linalg.eigvalsh(p.A.to_dense().numpy())[:3], rtol=1e-10)


def test_float32():
    p = grid_laplacian(6, 7, torch.complex64)
    lam, X = eigsh(p.A, p.m, 3, method="lanczos")
    assert lam.dtype == torch.float32 and X.dtype == torch.complex64
    np.testing.assert_allclose(lam.numpy(), reference(p, 3)[0], rtol=1e-4)


# ------------------------------------------------------------------------- gradients


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("method", METHODS)
def test_gradcheck_eigenvalues(dtype, method, gradcheck):
    p = grid_laplacian(3, 4, dtype)

    def f(params, m):
        return eigsh(p.hermitian(params), m, 3, method=method).values

    assert gradcheck(f, (p.params.clone().requires_grad_(), p.m.clone().requires_grad_()))


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("method", METHODS)
def test_gradcheck_gauge_invariant_eigenvector_losses(dtype, method, gradcheck):
    p = grid_laplacian(3, 4, dtype)

    def f(params, m):
        X = eigsh(p.hermitian(params), m, 3, method=method).vectors
        return X.abs() ** 2, X[:, :2] @ X[:, :2].mH

    assert gradcheck(f, (p.params.clone().requires_grad_(), p.m.clone().requires_grad_()))


@pytest.mark.parametrize("dtype", DTYPES)
def test_gradcheck_phase_fixed_eigenvectors(dtype, gradcheck):
    """The phase convention is differentiated too: raw eigenvector entries pass gradcheck."""
    p = grid_laplacian(3, 4, dtype)

    def f(params):
        return eigsh(p.hermitian(params), p.m, 2, method="lanczos").vectors

    assert gradcheck(f, (p.params.clone().requires_grad_(),))


def test_gradcheck_sparse_mass(gradcheck):
    p = grid_laplacian(3, 4, torch.complex128)
    n = p.n
    ar = torch.arange(n - 1)
    mi = torch.cat([torch.stack([ar, ar + 1]), torch.stack([ar + 1, ar]), torch.arange(n).expand(2, -1)], 1)

    def mass(off, diag):
        return torch.sparse_coo_tensor(mi, torch.cat([off, off, diag]), (n, n))

    off = torch.full((n - 1,), 0.05, dtype=torch.float64)

    def f(params, off, diag):
        lam, X = eigsh(p.hermitian(params), mass(off, diag), 2, method="lanczos")
        return lam, X.abs() ** 2

    assert gradcheck(
        f, (p.params.clone().requires_grad_(), off.requires_grad_(), p.m.clone().requires_grad_())
    )


def _degenerate_problem():
    """A ring of 18 nodes (one piece: a pencil in pieces is solved piece by piece): a simple
    smallest eigenvalue, then pairs, by the ring's symmetry."""
    n = 18
    i = torch.arange(n)
    rows = torch.cat([i, i, (i + 1) % n])
    cols = torch.cat([i, (i + 1) % n, i])
    vals = torch.cat([torch.full((n,), 2.5, dtype=torch.float64), -torch.ones(2 * n, dtype=torch.float64)])
    A = torch.sparse_coo_tensor(torch.stack([rows, cols]), vals, (n, n)).coalesce()
    return A, torch.ones(n, dtype=torch.float64)


@pytest.mark.filterwarnings("ignore:Anomaly Detection has been enabled")
def test_degenerate_projector_loss_is_supported():
    A, m = _degenerate_problem()
    values = A.coalesce().values().clone().requires_grad_()
    with torch.autograd.detect_anomaly():
        X = eigsh(
            torch.sparse_coo_tensor(A.coalesce().indices(), values, A.shape), m, 3, method="lanczos"
        ).vectors
        (X @ X.mT).diagonal().pow(2).sum().backward()
    assert torch.isfinite(values.grad).all()


def test_degenerate_basis_dependent_loss_raises():
    A, m = _degenerate_problem()
    values = A.coalesce().values().clone().requires_grad_()
    lam, X = eigsh(torch.sparse_coo_tensor(A.coalesce().indices(), values, A.shape), m, 3, method="lanczos")
    gaps = lam.detach().diff()
    assert float(gaps[1]) < 1e-10 < float(gaps[0])
    with pytest.raises(ValueError, match="degenerate eigenspace"):
        (X[:, 1] * torch.arange(18.0)).pow(2).sum().backward()


def test_eigenvalue_gradient_matches_dense_reference():
    """Gradient of sum(lambda) on the pattern equals the dense torch.linalg.eigh gradient."""
    p = grid_laplacian(4, 5, torch.complex128)
    params = p.params.clone().requires_grad_()
    eigsh(p.hermitian(params), p.m, 3).values.sum().backward()
    params2 = p.params.clone().requires_grad_()
    D = p.hermitian(params2).to_dense()
    s = 1 / p.m.sqrt()
    torch.linalg.eigvalsh(s[:, None] * D * s[None, :])[:3].sum().backward()
    torch.testing.assert_close(params.grad, params2.grad)


# ---------------------------------------------------------------------------- errors


def test_error_k_out_of_range():
    p = grid_laplacian(3, 3)
    with pytest.raises(ValueError, match="k must be an integer with 1 <= k < N = 9, got 9"):
        eigsh(p.A, p.m, 9)
    with pytest.raises(ValueError, match="got 0"):
        eigsh(p.A, p.m, 0)


def test_error_mass_size_and_dtype():
    p = grid_laplacian(3, 3)
    with pytest.raises(ValueError, match="M has size 8 but A has size 9"):
        eigsh(p.A, p.m[:8], 2)
    with pytest.raises(ValueError, match="M must be real"):
        eigsh(p.A, p.m.to(torch.complex128), 2)
    with pytest.raises(ValueError, match="M has dtype torch.float32"):
        eigsh(p.A, p.m.float(), 2)


def test_error_nan_and_method():
    p = grid_laplacian(3, 3)
    m = p.m.clone()
    m[0] = float("nan")
    with pytest.raises(ValueError, match="M contains NaN or Inf"):
        eigsh(p.A, m, 2)
    with pytest.raises(ValueError, match="method must be one of"):
        eigsh(p.A, p.m, 2, method="arpack")


# ------------------------------------------------------------------ k = 1 fast path


@pytest.mark.parametrize("dtype", DTYPES)
def test_smallest_pair_fast_path_matches_general_path_and_dense(dtype, caplog):
    """k = 1 runs the dedicated inverse-iteration path; it agrees with the block path and eigh."""
    import logging

    p = grid_laplacian(12, 13, dtype, shift=0.05)
    with caplog.at_level(logging.DEBUG, logger="torch_edgevf.linalg"):
        lam, X = eigsh(p.A, p.m, 1, method="lanczos")
    lam_gen, X_gen = eigsh(p.A, p.m, 1, method="lanczos", block_size=2)  # general block path
    ref_lam, ref_X = reference(p, 1)
    np.testing.assert_allclose(lam.numpy(), ref_lam, rtol=1e-12)
    torch.testing.assert_close(lam, lam_gen, rtol=1e-12, atol=0)
    Md = torch.diag(p.m).to(dtype)
    assert abs(float((X.mH @ Md @ X).real) - 1) < 1e-12
    # same vector as the general path and the dense reference (phase convention fixes it)
    torch.testing.assert_close(X, X_gen, atol=1e-9, rtol=0)
    overlap = (X.mH @ Md @ torch.from_numpy(ref_X).to(dtype)).abs()
    assert abs(float(overlap) - 1) < 1e-12
    A = p.A.to_dense()
    residual = (A @ X - Md @ X * lam.to(dtype)).norm() / (A @ X).norm()
    assert float(residual) < 1e-10
    assert any("solves for k=1" in r.getMessage() for r in caplog.records)


def test_smallest_pair_falls_back_when_the_basis_is_exhausted():
    """With a tiny basis the fast path hands over to the restarted general path."""
    p = grid_laplacian(12, 13, torch.complex128, shift=0.05)
    lam, _ = eigsh(p.A, p.m, 1, method="lanczos", ncv=3)
    np.testing.assert_allclose(lam.numpy(), reference(p, 1)[0], rtol=1e-12)


def test_smallest_pair_singular_laplacian():
    """A zero eigenvalue (constant kernel): inverse iteration converges in a few steps."""
    p = grid_laplacian(10, 12, torch.float64)
    lam, X = eigsh(p.A, p.m, 1, method="lanczos")
    assert abs(float(lam[0])) < 1e-10
    const = X[:, 0] / X[:, 0].mean()
    torch.testing.assert_close(const, torch.ones_like(const), atol=1e-8, rtol=0)


@pytest.mark.parametrize("dtype", DTYPES)
def test_gradcheck_smallest_pair(dtype, gradcheck):
    """Gradients of the k = 1 path: eigenvalue, gauge-invariant and phase-fixed vector losses."""
    p = grid_laplacian(3, 4, dtype)

    def f(params, m):
        lam, X = eigsh(p.hermitian(params), m, 1, method="lanczos")
        return lam, X.abs() ** 2, X

    assert gradcheck(f, (p.params.clone().requires_grad_(), p.m.clone().requires_grad_()))


# --------------------------------------------------------------- adaptive block size


@contextlib.contextmanager
def _one_pencil():
    """The Lanczos engine on the whole pencil: a pencil in pieces is otherwise split into
    its blocks (``linalg.components``), and the engine would never see the multiplicities."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(components, "blocks", lambda A, M: None)
        yield


def test_block_grows_on_multiple_eigenvalues_without_symmetry(caplog):
    """Three identical disconnected grids: every eigenvalue is triple, beyond the initial block of 2."""
    import logging

    p = grid_laplacian(6, 7, torch.complex128, shift=0.1)
    A = p.A.to_dense()
    Z = torch.zeros_like(A)
    big = torch.cat([torch.cat([A, Z, Z], 1), torch.cat([Z, A, Z], 1), torch.cat([Z, Z, A], 1)])
    m = p.m.repeat(3)
    with caplog.at_level(logging.DEBUG, logger="torch_edgevf.linalg"), _one_pencil():
        lam = eigsh(big.to_sparse(), m, 9, method="lanczos").values
    ref = eigsh(big.to_sparse(), m, 9, method="dense").values
    torch.testing.assert_close(lam, ref, rtol=1e-10, atol=1e-12)
    assert any("block size 2 -> 4" in r.getMessage() for r in caplog.records)


def test_block_doubles_twice_on_fivefold_eigenvalues(caplog):
    """Five identical disconnected grids: every eigenvalue has multiplicity 5; the block
    fills at 2 and again at 4, and ends at 6."""
    import logging

    p = grid_laplacian(6, 7, torch.complex128, shift=0.1)
    A = p.A.to_dense()
    big = torch.block_diag(*[A] * 5)
    m = p.m.repeat(5)
    with caplog.at_level(logging.DEBUG, logger="torch_edgevf.linalg"), _one_pencil():
        lam = eigsh(big.to_sparse(), m, 10, method="lanczos").values
    ref = eigsh(big.to_sparse(), m, 10, method="dense").values
    torch.testing.assert_close(lam, ref, rtol=1e-10, atol=1e-12)
    messages = [r.getMessage() for r in caplog.records]
    assert any("block size 2 -> 4" in s for s in messages)
    assert any("block size 4 -> 6" in s for s in messages)


def test_no_block_growth_on_a_simple_spectrum(caplog):
    import logging

    p = grid_laplacian(9, 11, torch.complex128, shift=0.1)
    with caplog.at_level(logging.DEBUG, logger="torch_edgevf.linalg"):
        lam = eigsh(p.A, p.m, 8, method="lanczos").values
    np.testing.assert_allclose(lam.numpy(), reference(p, 8)[0], rtol=1e-10)
    assert not any("block size" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("block_size", [1, 3, 6])
def test_explicit_block_size(block_size):
    p = grid_laplacian(9, 11, torch.complex128, shift=0.1)
    lam = eigsh(p.A, p.m, 7, method="lanczos", block_size=block_size).values
    np.testing.assert_allclose(lam.numpy(), reference(p, 7)[0], rtol=1e-10)


def test_general_sparse_mass_path():
    """A non-diagonal mass runs Lanczos in the M inner product (no M^{1/2} change of variables)."""
    p = grid_laplacian(8, 9, torch.complex128, shift=0.1)
    n = p.n
    ar = torch.arange(n - 1)
    mi = torch.cat([torch.stack([ar, ar + 1]), torch.stack([ar + 1, ar]), torch.arange(n).expand(2, -1)], 1)
    mv = torch.cat([torch.full((2 * (n - 1),), 0.05, dtype=torch.float64), p.m])
    Msp = torch.sparse_coo_tensor(mi, mv, (n, n)).coalesce()
    for k in (1, 5):
        lam, X = eigsh(p.A, Msp, k, method="lanczos")
        ref = scipy.linalg.eigh(p.A.to_dense().numpy(), Msp.to_dense().numpy(), eigvals_only=True)[:k]
        np.testing.assert_allclose(lam.numpy(), ref, rtol=1e-10)
        Md = Msp.to_dense().to(torch.complex128)
        torch.testing.assert_close(X.mH @ Md @ X, torch.eye(k, dtype=X.dtype), atol=1e-10, rtol=0)


def test_eigenvalue_gradient_through_sparse_matrix_constructor():
    """linalg.sparse_matrix (gather-only backward) gives the same gradients as torch's constructor."""
    from torch_edgevf.linalg import sparse_matrix

    p = grid_laplacian(5, 6, torch.complex128, shift=0.1)
    A = p.A.coalesce()
    v1 = A.values().clone().requires_grad_()
    v2 = A.values().clone().requires_grad_()
    lam1 = eigsh(sparse_matrix(A.indices(), v1, A.shape), p.m, 3, method="lanczos").values
    lam2 = eigsh(torch.sparse_coo_tensor(A.indices(), v2, A.shape), p.m, 3, method="lanczos").values
    torch.testing.assert_close(lam1, lam2, rtol=0, atol=0)
    (g1,) = torch.autograd.grad(lam1.sum(), v1)
    (g2,) = torch.autograd.grad(lam2.sum(), v2)
    torch.testing.assert_close(g1, g2, rtol=1e-13, atol=1e-15)


# ------------------------------------------------------------------- cholespy back-end


@pytest.fixture
def no_cholmod(monkeypatch):
    """The factor module with scikit-sparse hidden and cholespy installed (else skip).

    Skipped where scikit-sparse's CHOLMOD can be loaded: with both CHOLMOD builds in one process
    (Debian's, through scikit-sparse, and the one cholespy bundles and exports) about half of
    the full runs aborted with heap corruption at interpreter exit, and none without cholespy.
    The library never loads both (CHOLMOD first, cholespy only without it); CI runs these tests
    in a second process with ``EDGEVF_HIDE_CHOLMOD=1`` (see ``conftest.py``).
    """
    from torch_edgevf.linalg import factor as factor_module

    if factor_module.cholmod_module() is not None:
        pytest.skip(
            "scikit-sparse is loadable: cholespy tests run in a process without it (EDGEVF_HIDE_CHOLMOD=1)"
        )
    pytest.importorskip("cholespy")

    monkeypatch.setattr(factor_module, "cholmod_module", lambda: None)
    monkeypatch.setattr(factor_module, "cvxopt_cholmod_module", lambda: None)
    return factor_module


def _scipy(A):
    from torch_edgevf.linalg._utils import as_sparse

    return as_sparse(A).to_scipy()


def test_cholespy_factor_for_many_solves_of_real_spd_only(no_cholmod):
    import scipy.sparse.linalg as sla

    fm = no_cholmod
    K = _scipy(grid_laplacian(6, 7, torch.float64, shift=0.1).A)
    f = fm.factorize(K, "auto", hermitian=True, many_solves=True)
    assert f.backend == "cholespy"
    rng = np.random.default_rng(0)
    for b in (
        rng.standard_normal(42),
        rng.standard_normal((42, 3)),
        rng.standard_normal((42, 2)) + 1j * rng.standard_normal((42, 2)),
    ):
        np.testing.assert_allclose(
            f.solve(b), sla.spsolve(K.tocsc().astype(b.dtype), b), rtol=1e-12, atol=1e-13
        )
        np.testing.assert_allclose(f.solve(b, adjoint=True), f.solve(b), rtol=0, atol=0)
    # one-off solves keep SuperLU (cheaper factorization); complex matrices never use cholespy
    assert fm.factorize(K, "auto", hermitian=True).backend == "superlu-hermitian"
    Kc = _scipy(grid_laplacian(6, 7, torch.complex128, shift=0.1).A)
    assert fm.factorize(Kc, "auto", hermitian=True, many_solves=True).backend == "superlu-hermitian"
    # an indefinite matrix: Cholesky refuses it, "auto" falls back to LU
    Ki = (K - 2.0 * scipy.sparse.identity(42)).tocsc()
    with pytest.raises(fm.NotPositiveDefiniteError):
        fm.factorize(Ki, "cholesky", hermitian=True, many_solves=True)
    assert fm.factorize(Ki, "auto", hermitian=True, many_solves=True).backend == "superlu"


def test_cholespy_missing_is_logged_once(no_cholmod, monkeypatch, caplog):
    import logging

    fm = no_cholmod
    monkeypatch.setattr(fm, "cholespy_module", lambda: None)
    fm._log_no_cholespy.cache_clear()
    K = _scipy(grid_laplacian(6, 7, torch.float64, shift=0.1).A)
    try:
        with caplog.at_level(logging.INFO, logger=fm.__name__):
            backends = {fm.factorize(K, "auto", hermitian=True, many_solves=True).backend for _ in range(2)}
        assert backends == {"superlu-hermitian"}
        assert len([r for r in caplog.records if "cholespy" in r.getMessage()]) == 1
    finally:
        fm._log_no_cholespy.cache_clear()


@pytest.fixture
def cholespy_factors(no_cholmod, monkeypatch):
    """Records every cholespy factorization made while the test runs."""
    return record_instances(monkeypatch, no_cholmod, "_CholespyFactor")


@pytest.mark.parametrize("k", [1, 5])
def test_eigsh_with_cholespy_matches_dense_eigh(k, cholespy_factors):
    p = grid_laplacian(8, 9, torch.float64, shift=0.05)
    lam, X = eigsh(p.A, p.m, k, method="lanczos")
    # the smallest pair (10-20 solves) keeps SuperLU's cheaper factorization
    assert len(cholespy_factors) == (1 if k > 1 else 0)
    ref_lam, ref_X = reference(p, k)
    np.testing.assert_allclose(lam.numpy(), ref_lam, rtol=1e-12)
    Md = torch.diag(p.m)
    overlap = (X.mT @ Md @ torch.from_numpy(ref_X)).abs().diagonal()
    torch.testing.assert_close(overlap, torch.ones(k, dtype=overlap.dtype), atol=1e-10, rtol=0)
    residual = (p.A.to_dense() @ X - Md @ X * lam).norm(dim=0) / (p.A.to_dense() @ X).norm(dim=0)
    assert float(residual.max()) < 1e-10


def test_gradcheck_eigsh_with_cholespy(cholespy_factors):
    """Eigenvalues and eigenvector losses (the backward's complement CG uses the cholespy factor)."""
    p = grid_laplacian(4, 5, torch.float64, shift=0.05)

    def f(params, m):
        lam, X = eigsh(p.hermitian(params), m, 2, method="lanczos")
        return lam, X**2, X

    assert torch.autograd.gradcheck(f, (p.params.clone().requires_grad_(), p.m.clone().requires_grad_()))
    assert cholespy_factors


@pytest.mark.parametrize("k", [64, 128])
def test_many_pairs_on_an_icosphere_are_accurate(caplog, k):
    """Icosphere 3's connection Laplacian (1,920 edges; clusters of equal eigenvalues, block
    growth, many well converged Ritz vectors): every pair's true residual is at the level of
    the tolerance.  The deferred reorthogonalization, correcting a pending block that had
    drifted 1e-11 off the basis to first order, returned residuals of 1e-10 (k = 64) and
    3e-7 after 18,644 solves (k = 128)."""
    import logging

    from torch_edgevf import EdgeOperators, icosphere
    from torch_edgevf.linalg._utils import as_sparse

    ops = EdgeOperators(*icosphere(3), n=1)
    L, Mz = ops.connection_laplacian.detach().coalesce(), ops.mass.detach().coalesce()
    A, M = as_sparse(L).to_scipy(), as_sparse(Mz).to_scipy()
    with caplog.at_level(logging.DEBUG, logger="torch_edgevf"):
        lam, X = eigsh(L, Mz, k, method="lanczos")
    lam, X = lam.numpy(), X.numpy()
    residual = np.linalg.norm(A @ X - (M @ X) * lam, axis=0) / np.linalg.norm(A @ X, axis=0)
    assert residual.max() <= 1e-11, residual.max()
    solves = [int(r.getMessage().split()[1]) for r in caplog.records if "solves for k=" in r.getMessage()]
    assert solves and solves[-1] <= 6 * k, solves
    dense = scipy.linalg.eigh(A.toarray(), M.toarray(), eigvals_only=True, subset_by_index=[0, k - 1])
    np.testing.assert_allclose(lam, dense, rtol=1e-10)


def test_auto_method_goes_dense_when_k_is_a_large_part_of_n(monkeypatch):
    """``method="auto"``: dense for N <= 300 and for N <= 6 k (up to 4000), Lanczos otherwise;
    both give the same pairs."""
    from torch_edgevf.linalg import shift_invert

    assert shift_invert.dense_is_faster(300, 1) and not shift_invert.dense_is_faster(301, 1)
    assert shift_invert.dense_is_faster(642, 128) and not shift_invert.dense_is_faster(1920, 128)
    assert not shift_invert.dense_is_faster(6000, 1000)
    calls = []
    dense = shift_invert.eig_dense
    monkeypatch.setattr(shift_invert, "eig_dense", lambda *a: calls.append(a[0].shape[0]) or dense(*a))
    p = grid_laplacian(20, 20)  # N = 400
    A, m = p.hermitian().detach(), p.m
    lam_auto, _ = eigsh(A, m, 70)
    assert calls == [400]
    lam_lanczos, _ = eigsh(A, m, 70, method="lanczos")
    assert calls == [400]
    torch.testing.assert_close(lam_auto, lam_lanczos, rtol=1e-10, atol=1e-12)
