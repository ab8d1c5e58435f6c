"""The Lanczos engine behind ``eigsh`` and its kernels: deferred full reorthogonalization,
the schedule of convergence tests, inner products, the tridiagonal eigensolver, the scaled
shifted matrix of shift-invert, the fast path's harmonic Ritz vector, the convergence
floor of a singular matrix."""

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse
import torch
from test_problems import grid_laplacian

# ------------------------------------------------- deferred full reorthogonalization


def _hermitian_operator(n, spectrum, seed=0):
    """A dense Hermitian ``n x n`` matrix with the given eigenvalues, and its operator for ``_lanczos``."""
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)) + 1j * rng.standard_normal((n, n)))
    T = (Q * spectrum) @ Q.conj().T
    T = (T + T.conj().T) / 2
    return T, lambda Y: np.asfortranarray(T @ Y)


def _run_lanczos(monkeypatch, T, op, k, **kw):
    """``_lanczos`` on ``op``, counting the deferred passes and the restarts' completions."""
    from torch_edgevf.linalg import lanczos

    calls = {"deferred": 0, "complete": 0}
    for name in calls:
        fn = getattr(lanczos, f"_{name}" if name == "complete" else "_deferred_pass")

        def counted(*a, _fn=fn, _name=name, **k_):
            calls[_name] += 1
            return _fn(*a, **k_)

        monkeypatch.setattr(lanczos, f"_{name}" if name == "complete" else "_deferred_pass", counted)
    n = T.shape[0]
    inner = lanczos._Inner(np.complex128)
    v0 = np.random.default_rng(1).standard_normal(n)
    theta, Y, n_op = lanczos._lanczos(op, inner, n, k, tol=1e-12, maxiter=100, v0=v0, **kw)
    return theta, Y, n_op, calls


@pytest.mark.parametrize("ncv", [14, 15, 60])
def test_lanczos_deferred_reorthogonalization_is_exact(monkeypatch, ncv):
    """Every other block is completed a step late; the result equals full reorthogonalization.

    A spectrum with a fast-converging top (as shift-invert produces) loses orthogonality
    quickly without reorthogonalization.  ncv 14 and 15 restart often, so that restarts
    find the last block pending (14: an even number of blocks) or complete (15), and must
    keep the Lanczos relation exact through the restart; 60 never restarts.
    """
    n, k = 300, 6
    spectrum = 1.0 / (np.arange(1, n + 1) ** 1.5)
    T, op = _hermitian_operator(n, spectrum)
    theta, Y, n_op, calls = _run_lanczos(monkeypatch, T, op, k, block=2, ncv=ncv)
    assert calls["deferred"] >= 3
    np.testing.assert_allclose(theta, spectrum[:k], rtol=1e-11)
    np.testing.assert_allclose(Y.conj().T @ Y, np.eye(k), atol=1e-13)
    resid = np.linalg.norm(T @ Y - Y * theta, axis=0)
    assert np.all(resid <= 1e-11 * theta), resid


def test_lanczos_deferred_pass_survives_invariant_subspaces(monkeypatch):
    """Few distinct eigenvalues, multiplicities above the block size: Krylov breakdowns.

    When a block is (nearly) inside the span of the basis, what the pass against the last
    two blocks leaves is mostly rounding error, which a pending block must not carry to
    the next step: the full procedure takes over, in the plain step and in the deferred
    one (both are reached in this family).  Every eigenvalue comes out with its
    multiplicity -- the breakdowns' random directions find the missing copies -- and the
    Ritz vectors stay orthonormal.
    """
    from torch_edgevf.linalg import lanczos

    fallbacks = []
    orig = lanczos._orthonormalize

    def counted(W, V, *a, lo=0, **kw):
        fallbacks.append(lo > 0)  # lo > 0 only on the near-breakdown fallbacks
        return orig(W, V, *a, lo=lo, **kw)

    monkeypatch.setattr(lanczos, "_orthonormalize", counted)
    n = 150
    for distinct in (4, 5, 6, 7):
        for mult in (2, 3, 4):
            values = np.arange(distinct, 0, -1.0)
            spectrum = np.concatenate([np.repeat(values[:-1], mult), np.full(n - mult * (distinct - 1), 1.0)])
            T, op = _hermitian_operator(n, spectrum, seed=2)
            k = mult * (distinct - 1)
            theta, Y, _ = lanczos._lanczos(
                op,
                lanczos._Inner(np.complex128),
                n,
                k,
                block=2,
                ncv=40,
                tol=1e-12,
                maxiter=100,
                v0=np.random.default_rng(1).standard_normal(n),
            )
            np.testing.assert_allclose(theta, spectrum[:k], rtol=1e-11)
            np.testing.assert_allclose(Y.conj().T @ Y, np.eye(k), atol=1e-13)
    assert sum(fallbacks) >= 2


# ------------------------------------------------------- convergence test schedule


def _counted_lanczos(monkeypatch, T, op, k, every_step):
    """``_lanczos`` (block 2) with the convergence tests counted; ``every_step`` forces a test per step."""
    from torch_edgevf.linalg import lanczos

    tests = []
    ritz = lanczos._ritz

    def counted(H, cols, b, R):
        tests.append(cols)
        return ritz(H, cols, b, R)

    monkeypatch.setattr(lanczos, "_ritz", counted)
    if every_step:
        monkeypatch.setattr(lanczos._TestSchedule, "due", lambda self, cols, n_op, b: True)
    n = T.shape[0]
    theta, Y, n_op = lanczos._lanczos(
        op,
        lanczos._Inner(np.complex128),
        n,
        k,
        block=2,
        ncv=3 * k,
        tol=1e-12,
        maxiter=100,
        v0=np.random.default_rng(1).standard_normal(n),
    )
    monkeypatch.undo()
    return theta, Y, n_op, tests


def _both_schedules(monkeypatch, n, k):
    """A shift-invert-like spectrum (1 / i): the operator, and ``_counted_lanczos`` with a test
    after every step, then with the schedule."""
    spectrum = 1.0 / np.arange(1, n + 1)
    T, op = _hermitian_operator(n, spectrum)
    every = _counted_lanczos(monkeypatch, T, op, k, every_step=True)
    return spectrum, T, op, every, _counted_lanczos(monkeypatch, T, op, k, every_step=False)


def test_lanczos_spaces_its_tests_when_they_cost_more_than_steps(monkeypatch):
    """Many wanted pairs on a small problem (k = 60 of 600): the dense tests dominated when run
    after every step.  Spaced, they are at most a quarter as many, for at most 15% more solves
    and the same pairs, bit for bit reproducible.  A shift-invert-like spectrum (1 / i)."""
    k = 60
    spectrum, T, op, (theta0, _, n_op0, tests0), (theta, Y, n_op, tests) = _both_schedules(
        monkeypatch, 600, k
    )
    np.testing.assert_allclose(theta, spectrum[:k], rtol=1e-11)
    np.testing.assert_allclose(theta0, spectrum[:k], rtol=1e-11)
    np.testing.assert_allclose(Y.conj().T @ Y, np.eye(k), atol=1e-13)
    residual = np.linalg.norm(T @ Y - Y * theta, axis=0) / theta
    assert residual.max() <= 1e-10
    assert len(tests) <= len(tests0) / 4, (len(tests), len(tests0))
    assert n_op <= 1.15 * n_op0, (n_op, n_op0)
    theta2, Y2, n_op2, tests2 = _counted_lanczos(monkeypatch, T, op, k, every_step=False)
    assert (n_op2, tests2) == (n_op, tests)
    assert np.array_equal(theta2, theta) and np.array_equal(Y2, Y)


def test_lanczos_tests_cheaply_where_tests_are_cheap(monkeypatch):
    """Few wanted pairs on a larger problem (the Spot regime, cols^2 << n): the tests are
    spaced by the predicted convergence only (at most 4 steps apart), which leaves the
    solve count and the pairs as with a test after every step."""
    k = 6
    spectrum, _, _, (theta0, Y0, n_op0, tests0), (theta, Y, n_op, tests) = _both_schedules(
        monkeypatch, 1500, k
    )
    np.testing.assert_allclose(theta, spectrum[:k], rtol=1e-11)
    assert n_op == n_op0
    assert np.array_equal(theta, theta0) and np.array_equal(Y, Y0)
    assert len(tests) < len(tests0) * 0.7, (len(tests), len(tests0))
    assert max(np.diff(tests)) <= 4 * 2  # (columns: steps of block 2)


def test_test_schedule_never_skips_past_half_the_predicted_steps():
    """The schedule itself: the first test is due at once; the gap is the cost bound
    (round(1.5 cols^2 / n) steps) unless the rate of convergence predicts convergence
    sooner, then half the predicted steps, and at least one step."""
    from torch_edgevf.linalg.lanczos import _TestSchedule

    s = _TestSchedule(n=100)
    assert s.due(cols=40, n_op=0, b=2)
    s.record(np.array([1e10, 1e4]), n_op=40, b=2)  # worst log10 ratio 10, no rate yet
    by_cost = round(1.5 * 40 * 40 / 100)  # 24 steps of 2 solves
    assert not s.due(cols=40, n_op=40 + 2 * by_cost - 1, b=2)
    assert s.due(cols=40, n_op=40 + 2 * by_cost, b=2)
    s.record(np.array([1e6]), n_op=60, b=2)  # 4 decades in 10 steps: 15 steps left, test in 7
    assert not s.due(cols=40, n_op=60 + 2 * 7 - 1, b=2)
    assert s.due(cols=40, n_op=60 + 2 * 7, b=2)
    s.record(np.array([1e5]), n_op=74, b=2)  # slower now: 0.14 decades per step
    assert s.predicted == int(0.5 * 5 / (1 / 7))
    s.record(np.array([2e5]), n_op=76, b=2)  # no progress: the cost bound alone
    assert s.predicted == np.inf
    s.record(np.array([1.0001]), n_op=80, b=2)
    assert s.predicted == 1  # (at least one step)
    # cheap tests (cols^2 << n): the prediction, at most 4 steps
    s = _TestSchedule(n=10_000)
    s.record(np.array([1e12]), n_op=10, b=2)
    assert not s.due(cols=40, n_op=17, b=2) and s.due(cols=40, n_op=18, b=2)
    s.record(np.array([1e10]), n_op=18, b=2)  # 0.5 decades per step: 20 steps left, but 4
    assert not s.due(cols=40, n_op=25, b=2) and s.due(cols=40, n_op=26, b=2)
    s.record(np.array([1e4]), n_op=26, b=2)  # 1.5 decades per step: 2.7 steps left, test in 1
    assert s.due(cols=40, n_op=28, b=2)


# ------------------------------------------------------- kernels of the engine


@pytest.mark.parametrize("dtype", [np.float64, np.complex128])
def test_inner_products_narrow_and_wide_blocks_match_numpy(dtype):
    """The gemv branches (one or two columns) and the gemm branch agree with plain NumPy."""
    from torch_edgevf.linalg import lanczos

    rng = np.random.default_rng(3)
    n = 57

    def rand(*shape):
        x = rng.standard_normal(shape)
        return np.asfortranarray(x + 1j * rng.standard_normal(shape) if dtype == np.complex128 else x)

    m = rng.uniform(0.5, 2.0, n)
    for mmul in (None, lambda W: np.asfortranarray(m[:, None] * W)):
        inner = lanczos._Inner(dtype, mmul=mmul)
        weight = np.ones(n) if mmul is None else m
        for cols in (1, 2, 3, 7):
            for b in (1, 2, 4):
                V, W, C = rand(n, cols), rand(n, b), rand(cols, b)
                np.testing.assert_allclose(
                    inner.dot(V, W), V.conj().T @ (weight[:, None] * W), rtol=1e-13, atol=1e-12
                )
                expected = W - V @ C
                out = inner.subtract(W, V, C)
                np.testing.assert_allclose(out, expected, rtol=1e-13, atol=1e-12)
                if b <= 2:  # in place on a Fortran-ordered block
                    assert np.shares_memory(out, W)
                np.testing.assert_allclose(inner.combine(V, C), V @ C, rtol=1e-13, atol=1e-12)
        # an empty basis
        assert inner.dot(rand(n, 0), rand(n, 1)).shape == (0, 1)
        W = rand(n, 1)
        np.testing.assert_array_equal(inner.subtract(W.copy(), rand(n, 0), np.zeros((0, 1), dtype)), W)


@pytest.mark.parametrize("size", [1, 2, 9])
def test_tridiagonal_eigh_matches_dense(size):
    from torch_edgevf.linalg import lanczos

    rng = np.random.default_rng(size)
    d, e = rng.standard_normal(size), rng.standard_normal(max(size - 1, 1))
    theta, S = lanczos._tridiagonal_eigh(d, e)
    T = np.diag(d) + np.diag(e[: size - 1], 1) + np.diag(e[: size - 1], -1)
    ref = np.linalg.eigvalsh(T)[::-1]
    np.testing.assert_allclose(theta, ref, rtol=1e-13, atol=1e-13)
    assert np.all(np.diff(theta) <= 0)  # descending
    np.testing.assert_allclose(T @ S, S * theta, atol=1e-12)


@pytest.mark.parametrize("dtype", [np.float64, np.complex128])
@pytest.mark.parametrize("full_diagonal", [True, False])
def test_scaled_shifted_matrix(dtype, full_diagonal):
    """D (A - sigma M) D from the CSR arrays equals the dense formula, with or without
    a stored entry on every diagonal position."""
    from torch_edgevf.linalg import shift_invert

    rng = np.random.default_rng(4)
    n = 30
    B = scipy.sparse.random(n, n, density=0.15, random_state=5, dtype=np.float64)
    if dtype == np.complex128:
        B = B + 1j * scipy.sparse.random(n, n, density=0.15, random_state=6)
    A = (B + B.conj().T).tocsr()
    if full_diagonal:
        A = (A + scipy.sparse.identity(n)).tocsr()
    else:  # drop the stored diagonal of a few rows
        A = A.tolil()
        A.setdiag(0.0)
        A = (A + scipy.sparse.diags(np.r_[np.ones(n - 5), np.zeros(5)])).tocsr()
        A.eliminate_zeros()
    A.sort_indices()
    m = rng.uniform(0.5, 2.0, n)
    sigma = -0.3
    K = shift_invert._scaled_shifted(A, m, 1 / np.sqrt(m), sigma)
    assert K.format == "csc"
    D = np.diag(1 / np.sqrt(m))
    np.testing.assert_allclose(
        K.toarray(), D @ (A.toarray() - sigma * np.diag(m)) @ D, rtol=1e-14, atol=1e-14
    )


def test_to_scipy_is_the_coalesced_matrix():
    from torch_edgevf.linalg._utils import as_sparse

    p = grid_laplacian(4, 5, torch.complex128)
    A = as_sparse(p.A).to_scipy()
    assert A.format == "csr" and A.has_canonical_format
    np.testing.assert_array_equal(A.toarray(), p.A.to_dense().numpy())
    # an empty row (and column) at either end
    idx = torch.tensor([[1, 1, 2], [1, 2, 2]])
    B = torch.sparse_coo_tensor(idx, torch.tensor([1.0, 2.0, 3.0]), (4, 4))
    np.testing.assert_array_equal(as_sparse(B).to_scipy().toarray(), B.to_dense().numpy())


def test_smallest_pair_harmonic_ritz_vector():
    """The fast path returns the Ritz and the harmonic Ritz vector; on a shift-invert
    spectrum the harmonic one has the (much) smaller residual in the original problem,
    and the returned pair is the better of the two."""
    from torch_edgevf.linalg import lanczos

    rng = np.random.default_rng(7)
    n = 400
    lam = np.sort(np.r_[1.0, 1.6, 2.1, rng.uniform(2.5, 1e4, n - 3)])
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)) + 1j * rng.standard_normal((n, n)))
    K = (Q * lam) @ Q.conj().T  # K = T^-1, Hermitian positive definite
    K = (K + K.conj().T) / 2
    T = np.linalg.inv(K)

    def op(Y):
        return np.asfortranarray(T @ Y)

    inner = lanczos._Inner(np.complex128)
    _, Y, n_op = lanczos._smallest_pair(op, inner, n, tol=1e-8, maxiter=10, v0=rng.standard_normal(n))
    assert Y.shape[1] == 2

    def residual(y):
        rho = np.vdot(y, K @ y).real / np.vdot(y, y).real
        return np.linalg.norm(K @ y - rho * y) / (rho * np.linalg.norm(y))

    plain, harmonic = residual(Y[:, 0]), residual(Y[:, 1])
    assert harmonic < 0.2 * plain, (plain, harmonic)
    y, ky = lanczos._better_of(Y, lambda Z: K @ Z)
    np.testing.assert_array_equal(y, Y[:, 1:2])
    np.testing.assert_allclose(ky, K @ y)
    # the returned vector is the smallest eigenvector
    x1 = Q[:, 0]
    assert abs(np.vdot(x1, y[:, 0])) / np.linalg.norm(y) > 1 - 1e-8


def test_lanczos_convergence_floor_for_a_singular_matrix(monkeypatch, caplog):
    """A singular ``A`` (the Laplace-Beltrami operator's constants) under the tiny default
    shift gives ``T`` one eigenvalue ~1e5 times the others: the wanted pairs' residuals
    stall at the rounding floor ``eps ||T||``, above ``tol |theta|`` for the larger ones
    (icosphere 5, k = 128: 2,600 solves, or never).  The test accepts ``10 eps ||T||``;
    without it the same run does not converge."""
    import logging

    from torch_edgevf.linalg import lanczos

    n, k = 800, 60
    spectrum = np.concatenate([[1e5], 1.0 / np.arange(1, n)])
    T, op = _hermitian_operator(n, spectrum)
    inner = lanczos._Inner(np.complex128)
    v0 = np.random.default_rng(1).standard_normal(n)
    theta, Y, n_op = lanczos._lanczos(op, inner, n, k, block=2, ncv=3 * k, tol=1e-13, maxiter=20, v0=v0)
    np.testing.assert_allclose(theta, spectrum[:k], rtol=1e-9)
    residual = np.linalg.norm(T @ Y - Y * theta, axis=0)
    assert residual.max() <= 100 * np.finfo(float).eps * 1e5
    assert n_op <= 400, n_op
    monkeypatch.setattr(lanczos, "_FLOOR", 0.0)
    with caplog.at_level(logging.WARNING, logger="torch_edgevf"):
        _, _, n_op0 = lanczos._lanczos(op, inner, n, k, block=2, ncv=3 * k, tol=1e-13, maxiter=20, v0=v0)
    assert "did not converge" in caplog.text and n_op0 > 2 * n_op
