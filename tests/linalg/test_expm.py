"""Matrix exponential actions and implicit Euler: accuracy, gradients, errors."""

import numpy as np
import pytest
import torch
from test_problems import grid_laplacian, random_general

from torch_edgevf.linalg import expm_multiply, implicit_euler

DTYPES = [torch.float64, torch.complex128]


def sparse_mass(m: torch.Tensor) -> torch.Tensor:
    """Tridiagonal SPD mass matrix with diagonal ``m``."""
    n = m.numel()
    return (
        (
            torch.diag(m)
            + 0.1 * torch.diag(torch.ones(n - 1, dtype=m.dtype), 1)
            + 0.1 * torch.diag(torch.ones(n - 1, dtype=m.dtype), -1)
        )
        .to_sparse()
        .coalesce()
    )


def dense_flow(A, M, z0, t):
    Md = torch.diag(M) if M.dim() == 1 else M.to_dense()
    K = torch.linalg.solve(Md.to(A.dtype), A.to_dense())
    dtype = torch.promote_types(K.dtype, z0.dtype)
    return torch.linalg.matrix_exp(-t * K.to(dtype)) @ z0.to(dtype)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("mass", ["diagonal", "sparse"])
@pytest.mark.parametrize("cols", [None, 2])
def test_matches_dense_matrix_exp(dtype, mass, cols):
    A = random_general(8, dtype)
    m = 0.5 + torch.rand(8, dtype=torch.float64)
    M = m if mass == "diagonal" else sparse_mass(m)
    z0 = torch.randn((8,) if cols is None else (8, cols), dtype=dtype)
    torch.testing.assert_close(expm_multiply(A, M, z0, 0.7), dense_flow(A, M, z0, 0.7))


def test_heat_flow_conserves_mass_weighted_mean():
    """Real Laplacian: constants are in the kernel, so 1^T M z(t) is conserved."""
    p = grid_laplacian(5, 6)
    z0 = torch.randn(p.n, dtype=torch.float64)
    z = expm_multiply(p.A, p.m, z0, 2.0)
    torch.testing.assert_close((p.m * z).sum(), (p.m * z0).sum())
    assert (p.m * z * z).sum() < (p.m * z0 * z0).sum()


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("mass", ["diagonal", "sparse"])
def test_gradcheck_all_inputs(dtype, mass, gradcheck):
    A = random_general(6, dtype).coalesce()
    g = torch.Generator().manual_seed(1)  # the same inputs in every lane and order, so a failure repeats
    m = 0.5 + torch.rand(6, dtype=torch.float64, generator=g)
    Ms = sparse_mass(m)
    z0 = torch.randn(6, 2, dtype=dtype, generator=g)
    t = torch.tensor(0.7, dtype=torch.float64)

    def f(a_vals, m_vals, z0, t):
        M = m_vals if mass == "diagonal" else torch.sparse_coo_tensor(Ms.indices(), m_vals, Ms.shape)
        return expm_multiply(torch.sparse_coo_tensor(A.indices(), a_vals, A.shape), M, z0, t)

    m_vals = m if mass == "diagonal" else Ms.values()
    inputs = [A.values(), m_vals, z0, t]
    assert gradcheck(f, tuple(x.clone().requires_grad_() for x in inputs))


def test_gradcheck_large_norm_transport():
    """Skew-Hermitian generator (transport-like, no decay), t * ||K|| ~ 40: many panels."""
    B = random_general(6, torch.complex128, seed=4).to_dense()
    A = (4j * (B + B.mH)).to_sparse().coalesce()
    z0 = torch.randn(6, dtype=torch.complex128)
    t = torch.tensor(1.3, dtype=torch.float64)

    def f(a_vals, z0, t):
        return expm_multiply(torch.sparse_coo_tensor(A.indices(), a_vals, A.shape), None, z0, t)

    y = f(A.values(), z0, t)
    torch.testing.assert_close(y.norm(), z0.norm())  # unitary flow
    assert torch.autograd.gradcheck(
        f, (A.values().clone().requires_grad_(), z0.requires_grad_(), t.requires_grad_()), fast_mode=True
    )


def test_real_matrix_complex_initial_value():
    p = grid_laplacian(4, 4)
    z0 = torch.randn(p.n, dtype=torch.complex128)
    torch.testing.assert_close(expm_multiply(p.A, p.m, z0, 0.3), dense_flow(p.A, p.m, z0, 0.3))


@pytest.mark.parametrize("dtype", DTYPES)
def test_implicit_euler_first_order_convergence(dtype):
    p = grid_laplacian(4, 5, dtype)
    z0 = torch.randn(p.n, dtype=dtype)
    exact = expm_multiply(p.A, p.m, z0, 0.5)
    steps = np.array([4, 8, 16, 32])
    err = [float((implicit_euler(p.A, p.m, z0, 0.5, int(s)) - exact).norm()) for s in steps]
    rate = -np.polyfit(np.log(steps), np.log(err), 1)[0]
    assert abs(rate - 1.0) < 0.1, f"observed rate {rate:.3f}, expected 1"


@pytest.mark.parametrize("dtype", DTYPES)
def test_gradcheck_implicit_euler(dtype, gradcheck):
    p = grid_laplacian(3, 4, dtype)
    z0 = torch.randn(p.n, dtype=dtype)
    t = torch.tensor(0.4, dtype=torch.float64)

    def f(params, m, z0, t):
        return implicit_euler(p.hermitian(params), m, z0, t, steps=3)

    inputs = (
        p.params.clone().requires_grad_(),
        p.m.clone().requires_grad_(),
        z0.requires_grad_(),
        t.requires_grad_(),
    )
    assert gradcheck(f, inputs)


def test_float32_keeps_dtype():
    p = grid_laplacian(4, 4, torch.complex64)
    z0 = torch.randn(p.n, dtype=torch.complex64)
    z = expm_multiply(p.A, p.m, z0, 0.3)
    assert z.dtype == torch.complex64
    ref = dense_flow(p.A.to(torch.complex128), p.m.double(), z0.to(torch.complex128), 0.3)
    torch.testing.assert_close(z.to(torch.complex128), ref, rtol=1e-4, atol=1e-5)


def test_errors():
    p = grid_laplacian(3, 3)
    z0 = torch.zeros(p.n, dtype=torch.float64)
    with pytest.raises(ValueError, match=r"z0 must have shape \(9,\) or \(9, C\)"):
        expm_multiply(p.A, p.m, z0[:8], 1.0)
    with pytest.raises(ValueError, match="t must be a real scalar"):
        expm_multiply(p.A, p.m, z0, torch.ones(2))
    with pytest.raises(ValueError, match="t contains NaN or Inf"):
        expm_multiply(p.A, p.m, z0, float("nan"))
    with pytest.raises(ValueError, match="steps must be a positive integer"):
        implicit_euler(p.A, p.m, z0, 1.0, steps=0)
    with pytest.raises(ValueError, match="A must be square"):
        expm_multiply(torch.zeros(3, 4).to_sparse(), None, z0, 1.0)
