"""eigsh at any scale the dtype can hold: the same relative results.

For a mesh scaled by ``s``, ``L_c`` and the cotan Laplacian do not change, ``M_z`` and the
vertex masses are proportional to ``s^2``, so the eigenvalues scale by ``1 / s^2`` and the
mass-orthonormal eigenvectors by ``1 / s``.  ``eigsh`` divides the pencil by powers of two
before the solve, so at ``s = 1e-100`` (``M_z`` about ``1e-200``) nothing under- or
overflows, and at ``s = 2^j`` the results are bit-identical to those at ``s = 1``.
"""

import math

import numpy as np
import pytest
import scipy.sparse as sp
import torch

import torch_edgevf as ev
from torch_edgevf.linalg import eigsh, to_scipy
from torch_edgevf.linalg.shift_invert import normalize_pair
from torch_edgevf.mesh.topology import Topology
from torch_edgevf.operators import functional as ops

VERTS, FACES = ev.icosphere(3)  # E = 1920, V = 642: both above the dense threshold
# perturbed (fixed seed): no symmetry, so simple eigenvalues and unique eigenvectors
VERTS = VERTS + 0.01 * torch.randn(VERTS.shape, generator=torch.Generator().manual_seed(0), dtype=VERTS.dtype)
SMALL_VERTS, SMALL_FACES = ev.icosphere(2)
TOPO = Topology(FACES, num_vertices=VERTS.shape[0])
RTOL = {torch.float64: 1e-11, torch.float32: 2e-4}


def _edge_pair(verts, faces=FACES):
    o = ev.EdgeOperators(verts, faces, n=1)
    return o.connection_laplacian.coalesce(), o.mass.coalesce()


def _vertex_pair(verts, name):
    L = getattr(ops, name)(verts, TOPO)
    return L, ops.vertex_mass(verts, TOPO, lumped=True).values()


REFERENCE = {k: eigsh(*_edge_pair(VERTS), k, method="lanczos") for k in (1, 6)}


@pytest.mark.parametrize("k", [1, 6])
@pytest.mark.parametrize(
    "dtype, s",
    [(torch.float64, 1e-100), (torch.float64, 1.0), (torch.float64, 1e100)]
    + [(torch.float32, 1e-12), (torch.float32, 1e12)],
)
def test_edge_eigenpairs_scale_covariant(dtype, s, k):
    L, M = _edge_pair((VERTS * s).to(dtype))
    lam, X = eigsh(L, M, k, method="lanczos")
    ref = REFERENCE[k]
    assert lam.dtype == dtype and torch.isfinite(lam).all() and torch.isfinite(X).all()
    err = float(((lam.double() * s * s - ref.values).abs() / ref.values.abs()).max())
    assert err <= RTOL[dtype], (s, err)
    # M-orthonormal at that scale: X^H M X = I (M_z diagonal), so |X| is about 1 / s
    Xc = X.to(torch.complex128)
    gram = (Xc.mH * M.values().double()) @ Xc
    torch.testing.assert_close(gram, torch.eye(k, dtype=gram.dtype), atol=50 * RTOL[dtype], rtol=0)
    # the same eigenvectors as at s = 1, up to a unit factor: |x^H M x_ref| = 1
    overlap = ((Xc * s).conj() * (M.values().double()[:, None] / (s * s)) * ref.vectors).sum(0).abs()
    torch.testing.assert_close(overlap, torch.ones_like(overlap), atol=100 * RTOL[dtype], rtol=0)


@pytest.mark.parametrize("method", ["lanczos", "dense"])
def test_powers_of_two_bit_identical(method):
    # L_c and M_z of a mesh scaled by 2^j are exactly L_c and 2^(2j) M_z
    ref = eigsh(*_edge_pair(SMALL_VERTS, SMALL_FACES), 6, method=method)
    for j in (-332, 332):  # s of about 1e-100 and 1e100
        s = math.ldexp(1.0, j)
        lam, X = eigsh(*_edge_pair(SMALL_VERTS * s, SMALL_FACES), 6, method=method)
        assert torch.equal(lam, ref.values / (s * s)), j
        assert torch.equal(X, ref.vectors / s), j


@pytest.mark.parametrize("name", ["cotan_laplacian", "laplace_beltrami"])
@pytest.mark.parametrize("k", [1, 6])
@pytest.mark.parametrize("s", [1e-100, 1e100])
def test_vertex_eigenpairs_scale_covariant(name, k, s):
    lam0, X0 = eigsh(*_vertex_pair(VERTS, name), k, method="lanczos")
    L, m = _vertex_pair(VERTS * s, name)
    lam, X = eigsh(L, m, k, method="lanczos")
    assert torch.isfinite(lam).all() and torch.isfinite(X).all()
    # relative to the spectrum's scale: the first eigenvalue is 0 (constants)
    torch.testing.assert_close(lam * s * s, lam0, rtol=1e-11, atol=1e-13)
    # the constant eigenvector, M-normalised: 1 / sqrt(area) at that scale
    area = float(m.sum())
    torch.testing.assert_close(X[:, 0] * math.sqrt(area), torch.ones_like(X[:, 0]), atol=1e-9, rtol=0)


@pytest.mark.parametrize("s", [1e-100, 1e100])
def test_gradients_scale_covariant(s):
    """The gradient in ``L_c`` of a scale-free loss of the eigenpairs does not depend on ``s``.

    (The gradient in ``M_z`` scales like ``1 / s^4``: at ``s = 1e-100`` it is not
    representable.)
    """
    v = VERTS
    w = torch.rand(TOPO.num_edges, generator=torch.Generator().manual_seed(1), dtype=torch.float64)

    def grads(scale):
        L, M = _edge_pair(v * scale)
        a = L.values().clone().requires_grad_()
        A = torch.sparse_coo_tensor(L.indices(), a, L.shape).coalesce()
        lam, X = eigsh(A, M, 2, method="lanczos")
        loss = (lam.sum() + (w[:, None] * X.abs() ** 2).sum()) * scale * scale
        (g,) = torch.autograd.grad(loss, a)
        return g

    g0, g = grads(1.0), grads(s)
    assert torch.isfinite(g).all()
    torch.testing.assert_close(g, g0, rtol=1e-7, atol=1e-9 * float(g0.abs().max()))


def test_normalize_pair_exact_and_in_range():
    L, M = _edge_pair(VERTS * 1e-100)
    A = to_scipy(L)
    Mn_in = sp.diags(M.values().numpy()).tocsr()
    An, Mn, sc = normalize_pair(A, Mn_in)
    assert sc.m_exp % 2 == 0
    assert 0.5 <= np.abs(Mn.data).max() < 2
    assert np.array_equal(np.ldexp(Mn.data, sc.m_exp), Mn_in.data)
    assert np.array_equal(An.toarray() * 2.0**sc.a_exp, A.toarray())
    ratio = np.median(np.abs(An.diagonal()) / Mn.diagonal())
    assert 0.5 <= ratio < 1
    lam = np.array([1.0, 3.0])
    np.testing.assert_array_equal(sc.values(sc.normalized_values(lam)), lam)
