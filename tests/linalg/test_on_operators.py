"""End to end: linear algebra on the mesh operators, gradients to vertex positions."""

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.linalg import eigsh


def perturbed_icosphere(level=1, scale=0.05, seed=0):
    v, f = ev.icosphere(level)
    g = torch.Generator().manual_seed(seed)
    return v + scale * torch.randn(v.shape, generator=g, dtype=v.dtype), f


def smallest_eigenvalue(verts, faces, which):
    ops = ev.EdgeOperators(verts, faces, n=1)
    if which == "connection":
        A, M = ops.connection_laplacian, ops.mass
        return eigsh(A, M, 1, method="lanczos").values[0]
    # (L, M_v): skip the constant kernel, take the first non-zero eigenvalue
    return eigsh(ops.laplace_beltrami, ops.vertex_mass, 2, method="lanczos").values[1]


@pytest.mark.parametrize("which", ["connection", "laplace_beltrami"])
def test_eigenvalue_gradient_wrt_vertices_matches_finite_differences(which):
    verts, faces = perturbed_icosphere(1, 0.08, seed=3)
    v = verts.clone().requires_grad_()
    (grad,) = torch.autograd.grad(smallest_eigenvalue(v, faces, which), v)
    g = torch.Generator().manual_seed(7)
    for _ in range(3):
        direction = torch.randn(verts.shape, generator=g, dtype=verts.dtype)
        h = 1e-5
        fd = (
            smallest_eigenvalue(verts + h * direction, faces, which)
            - smallest_eigenvalue(verts - h * direction, faces, which)
        ) / (2 * h)
        np.testing.assert_allclose(float((grad * direction).sum()), float(fd), rtol=1e-5, atol=1e-8)


def test_lanczos_finds_every_copy_of_multiple_eigenvalues():
    """The exact icosphere has clusters of equal eigenvalues (multiplicity up to 5)."""
    ops = ev.EdgeOperators(*ev.icosphere(2), n=1)
    A, M = ops.connection_laplacian, ops.mass
    lam = eigsh(A, M, 24, method="lanczos").values
    ref = eigsh(A, M, 24, method="dense").values
    torch.testing.assert_close(lam, ref, rtol=1e-9, atol=1e-9)


def test_connection_laplacian_spectrum_of_the_sphere():
    """Smallest eigenvalues of L_c on the unit sphere: l(l+1) - 1 for l >= 1, multiplicity 2l+1."""
    ops = ev.EdgeOperators(*ev.icosphere(3), n=1)
    lam = eigsh(ops.connection_laplacian, ops.mass, 8, method="lanczos").values
    np.testing.assert_allclose(lam.numpy(), [1.0] * 3 + [5.0] * 5, rtol=2e-2)
