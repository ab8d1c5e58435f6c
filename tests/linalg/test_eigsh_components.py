"""eigsh on meshes in pieces: the spectrum of the whole is the union of the pieces' spectra.

A mesh of several disjoint parts gives block-diagonal operators (up to the numbering).
Identical parts repeat every eigenvalue once per part, and a vertex Laplacian has one null
vector per part; the solver takes the blocks one at a time, so neither the multiplicities
nor the null space stall it.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf import EdgeOperators
from torch_edgevf.linalg import eigsh, to_scipy
from torch_edgevf.linalg.components import blocks

from conftest import shared_path

trimesh = pytest.importorskip("trimesh")


def _pieces(meshes, seed=0):
    """One mesh of the parts ``meshes`` (trimesh), faces shuffled so the numbering interleaves."""
    verts, faces, offset = [], [], 0
    for m in meshes:
        verts.append(np.asarray(m.vertices, dtype=np.float64))
        faces.append(np.asarray(m.faces, dtype=np.int64) + offset)
        offset += len(m.vertices)
    v, f = np.concatenate(verts), np.concatenate(faces)
    rng = np.random.default_rng(seed)
    perm = rng.permutation(len(v))  # vertices of the parts interleaved in the numbering
    inverse = np.empty_like(perm)
    inverse[perm] = np.arange(len(v))
    return torch.from_numpy(v[perm]), torch.from_numpy(inverse[f][rng.permutation(len(f))])


def _spectrum(verts, faces, n, k, **kw):
    ops = EdgeOperators(verts, faces, n=n)
    return eigsh(ops.connection_laplacian, ops.mass, k, **kw)


def _dense_spectrum(verts, faces, n):
    import scipy.linalg

    ops = EdgeOperators(verts, faces, n=n)
    A = to_scipy(ops.connection_laplacian).toarray()
    M = to_scipy(ops.mass).toarray()
    return scipy.linalg.eigh(A, M, eigvals_only=True)


@pytest.mark.parametrize("n", [1, 2])
def test_disjoint_spheres_give_the_union_of_their_spectra(n):
    """Three spheres (two alike, one smaller and elsewhere): every eigenvalue of the whole is
    one of a part's, with the multiplicity of the parts summed."""
    a = trimesh.creation.icosphere(subdivisions=3)
    b = trimesh.creation.icosphere(subdivisions=3).apply_translation([3.0, 0, 0])
    c = trimesh.creation.icosphere(subdivisions=2, radius=0.7).apply_translation([0, 3.0, 0])
    k = 24
    parts = []
    for m in (a, c):
        v, f = torch.from_numpy(np.asarray(m.vertices)), torch.from_numpy(np.asarray(m.faces))
        parts.append(_spectrum(v, f, n, k, method="lanczos")[0].numpy())
    union = np.sort(np.concatenate([parts[0], parts[0], parts[1]]))[:k]
    verts, faces = _pieces([a, b, c])
    lam, X = _spectrum(verts, faces, n, k, method="lanczos")
    lam = lam.numpy()
    np.testing.assert_allclose(lam, union, rtol=1e-9, atol=1e-12)
    # M-orthonormal, and each vector an eigenvector of the whole pencil
    ops = EdgeOperators(verts, faces, n=n)
    A, M, Xn = to_scipy(ops.connection_laplacian), to_scipy(ops.mass), X.numpy()
    np.testing.assert_allclose(Xn.conj().T @ (M @ Xn), np.eye(k), atol=1e-10)
    residual = np.linalg.norm(A @ Xn - (M @ Xn) * lam, axis=0) / np.linalg.norm(M @ Xn, axis=0)
    assert residual.max() < 1e-8 * lam.max()


def test_vertex_laplacian_null_space_has_one_vector_per_piece():
    """The scalar (n = 0) Laplacian of 5 parts has a 5-dimensional null space, then the
    parts' first nonzero eigenvalues; the null vectors are constant on each part."""
    meshes = [trimesh.creation.icosphere(subdivisions=2).apply_translation([3.0 * i, 0, 0]) for i in range(4)]
    meshes.append(trimesh.creation.box().subdivide().apply_translation([0, 5.0, 0]))
    verts, faces = _pieces(meshes, seed=1)
    k = 8
    lam, X = _spectrum(verts, faces, 0, k, method="lanczos")
    parts = [
        _spectrum(torch.from_numpy(np.asarray(m.vertices)), torch.from_numpy(np.asarray(m.faces)), 0, k)[
            0
        ].numpy()
        for m in meshes
    ]
    union = np.sort(np.concatenate(parts))[:k]
    np.testing.assert_allclose(lam.numpy(), union, rtol=1e-9, atol=1e-10 * union[-1])
    assert np.all(np.abs(lam.numpy()[:5]) < 1e-10) and lam[5] > 1e-3
    # the null vectors span the functions constant on each part
    ops = EdgeOperators(verts, faces, n=0)
    labels = _part_of_edge(ops.topology.edges.numpy(), verts.numpy(), len(meshes))
    indicator = np.stack([labels == p for p in range(len(meshes))], axis=1).astype(float)
    null = X.numpy()[:, :5]
    projected = null @ np.linalg.lstsq(null, indicator, rcond=None)[0]
    np.testing.assert_allclose(projected, indicator, atol=1e-8)


def _part_of_edge(edges, verts, count):
    """The part of each edge: parts lie 3 apart along x (spheres) or at y = 5 (the box)."""
    mid = verts[edges].mean(axis=1)
    return np.where(mid[:, 1] > 2.5, count - 1, np.round(mid[:, 0] / 3.0).astype(int))


def test_truck_like_model_of_many_pieces_gets_its_smoothest_field():
    """A model made of many parts, several alike (body, cab, wheels, bolts: 16 boxes and
    cylinders), flat faces everywhere: the smoothest 1- and 4-fields come out with the
    eigenvalue of the dense decomposition."""
    body = trimesh.creation.box(extents=[4, 1.6, 1]).subdivide()
    cab = trimesh.creation.box(extents=[1.2, 1.6, 1]).apply_translation([1.4, 0, 1])
    wheels = [
        trimesh.creation.cylinder(radius=0.4, height=0.3, sections=16).apply_translation([x, y, -0.5])
        for x in (-1.4, 1.4)
        for y in (-0.95, 0.95)
    ]
    bolts = [
        trimesh.creation.cylinder(radius=0.05, height=0.05, sections=6).apply_translation([x, y, -0.5])
        for x in (-1.4, 1.4)
        for y in (-1.15, 1.15, -1.2, 1.2, -1.25)
    ]
    meshes = [body, cab, *wheels, *bolts]
    verts, faces = _pieces(meshes, seed=2)
    pieces = blocks(*(to_scipy(t) for t in _operators(verts, faces)))
    assert pieces is not None and len(pieces) == len(meshes)
    for n in (1, 4):
        full = _dense_spectrum(verts, faces, n)
        z, value = ev.FieldDesigner(verts, faces, n).smoothest(return_eigenvalue=True)
        assert float(value) == pytest.approx(full[0], rel=1e-8, abs=1e-10 * full[-1])
        ops = EdgeOperators(verts, faces, n=n)
        A, M, zn = to_scipy(ops.connection_laplacian), to_scipy(ops.mass), z.numpy()
        assert np.linalg.norm(A @ zn - float(value) * (M @ zn)) < 1e-8 * max(full[-1], 1.0)


def _operators(verts, faces):
    ops = EdgeOperators(verts, faces, n=1)
    return ops.connection_laplacian, ops.mass


def test_connected_mesh_is_one_block():
    v, f = ev.icosphere(2)
    assert blocks(*(to_scipy(t) for t in _operators(v, f))) is None


def test_unused_vertices_carry_no_eigenpair():
    """Vertices that no face uses give empty rows of the scalar Laplacian; the pairs are
    those of the mesh without them (no spurious zero or infinite eigenvalue)."""
    m = trimesh.creation.icosphere(subdivisions=2)
    v = np.concatenate([np.asarray(m.vertices), np.random.default_rng(0).standard_normal((7, 3))])
    f = np.asarray(m.faces, dtype=np.int64)
    k = 6
    lam_extra = _spectrum(torch.from_numpy(v), torch.from_numpy(f), 0, k, method="lanczos")[0]
    lam = _spectrum(torch.from_numpy(np.asarray(m.vertices)), torch.from_numpy(f), 0, k, method="lanczos")[0]
    np.testing.assert_allclose(lam_extra.numpy(), lam.numpy(), atol=1e-10)


@pytest.mark.slow
def test_shared_truck_gets_its_smoothest_field():
    """libigl's tutorial truck (``wild/truck.obj`` of the test data, if there): many
    components after repair, each with its share of the spectrum."""
    from torch_edgevf.io import load_mesh
    from torch_edgevf.mesh.repair import repair

    path = shared_path("meshes", "wild", "truck.obj")
    m = load_mesh(path)
    r = repair(m.verts, m.faces)
    z = ev.smoothest_field(torch.as_tensor(r.verts), torch.as_tensor(r.faces), 1)
    assert torch.isfinite(z).all()
