"""Test matrices for the linear-algebra tests, and checks of their defining properties.

``grid_laplacian`` is a weighted graph Laplacian on an ``nx x ny`` grid; with
``magnetic=True`` its off-diagonal entries carry random phases,
``-w_ij exp(i theta_ij)`` (a magnetic Laplacian: complex Hermitian, positive definite
for generic phases).  The values are returned as a flat parameter vector so that tests
can differentiate through the construction of a Hermitian sparse matrix.
"""

from dataclasses import dataclass

import numpy as np
import torch


@dataclass
class Problem:
    """Hermitian sparse matrix ``A = hermitian(params)`` and a diagonal mass ``m``."""

    i: torch.Tensor
    j: torch.Tensor
    params: torch.Tensor  # off-diagonal values (len(i)) then the diagonal (n)
    m: torch.Tensor
    n: int

    def hermitian(self, params=None) -> torch.Tensor:
        """The Hermitian sparse matrix with these off-diagonal/diagonal parameters."""
        params = self.params if params is None else params
        off, d = params[: self.i.numel()], params[self.i.numel() :]
        if off.is_complex():
            d = d.real.to(off.dtype)
        ar = torch.arange(self.n)
        idx = torch.stack([torch.cat([self.i, self.j, ar]), torch.cat([self.j, self.i, ar])])
        return torch.sparse_coo_tensor(idx, torch.cat([off, off.conj(), d]), (self.n, self.n))

    @property
    def A(self) -> torch.Tensor:
        return self.hermitian().coalesce()


def grid_laplacian(nx=4, ny=5, dtype=torch.float64, magnetic=False, shift=0.0, seed=0) -> Problem:
    """Weighted (magnetic if complex) grid Laplacian plus ``shift * I``, random diagonal mass."""
    g = torch.Generator().manual_seed(seed)
    idx = torch.arange(nx * ny).reshape(nx, ny)
    i = torch.cat([idx[:-1].reshape(-1), idx[:, :-1].reshape(-1)])
    j = torch.cat([idx[1:].reshape(-1), idx[:, 1:].reshape(-1)])
    w = 1 + 0.5 * torch.rand(i.numel(), generator=g, dtype=torch.float64)
    n = nx * ny
    d = torch.zeros(n, dtype=torch.float64).index_add(0, i, w).index_add(0, j, w) + shift
    if magnetic or dtype.is_complex:
        theta = 0.7 * torch.randn(i.numel(), generator=g, dtype=torch.float64)
        off = -w * torch.exp(1j * theta)
    else:
        off = -w
    m = 0.5 + torch.rand(n, generator=g, dtype=torch.float64)
    real = torch.float32 if dtype in (torch.float32, torch.complex64) else torch.float64
    params = torch.cat([off, d.to(off.dtype)]).to(dtype)
    return Problem(i, j, params, m.to(real), n)


def random_general(n=7, dtype=torch.float64, density=0.4, seed=0) -> torch.Tensor:
    """A random sparse non-symmetric, well-conditioned matrix (diagonal always stored)."""
    g = torch.Generator().manual_seed(seed)
    D = torch.randn(n, n, generator=g, dtype=dtype)
    D[torch.rand(n, n, generator=g) < density] = 0
    D = D + 3 * torch.eye(n, dtype=dtype)
    return D.to_sparse()


def test_magnetic_laplacian_is_hermitian_positive_definite():
    p = grid_laplacian(4, 5, torch.complex128)
    D = p.A.to_dense()
    assert torch.allclose(D, D.mH)
    assert torch.linalg.eigvalsh(D).min() > 1e-3


def test_real_grid_laplacian_has_constant_kernel():
    p = grid_laplacian(4, 5, torch.float64)
    D = p.A.to_dense()
    assert torch.allclose(D.sum(1), torch.zeros(p.n, dtype=D.dtype), atol=1e-12)
    assert np.linalg.matrix_rank(D.numpy()) == p.n - 1
