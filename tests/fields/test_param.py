"""Seamless parametrization from a cross field (thesis chapter 4)."""

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.fields.param import _tree_cumsum, comb, cut_graph, flipped_faces, parametrize
from torch_edgevf.fields.singularities import face_frame_angles, singularities
from torch_edgevf.mesh.topology import Topology


def cross_field(verts, faces):
    from torch_edgevf.fields.design import smoothest_field

    return smoothest_field(verts, faces, n=4)


@pytest.fixture(scope="module")
def ellipsoid_param():
    v, f = ev.meshes.ellipsoid((1.0, 0.8, 0.6), level=3)
    z = cross_field(v, f)
    return parametrize(v, f, z), parametrize(v, f, z, round_integers=False)


def _gradients(P):
    """Per-face gradients of u and v as 3D vectors, and the combed directions U, V."""
    v, f = P.verts.numpy(), P.faces.numpy()
    p = v[f]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area2 = np.linalg.norm(n, axis=1)
    n /= area2[:, None]
    e = p[:, [2, 0, 1]] - p[:, [1, 2, 0]]
    grad_hat = np.cross(n[:, None], e) / area2[:, None, None]  # grad lambda_k
    uv = P.uv.numpy()
    gu = (uv[:, :, 0:1] * grad_hat).sum(1)
    gv = (uv[:, :, 1:2] * grad_hat).sum(1)
    topo = Topology(P.faces)
    d0 = (p[:, 2] - p[:, 1]) * topo.face_edge_signs.numpy()[:, :1]
    d0 /= np.linalg.norm(d0, axis=1, keepdims=True)
    y0 = np.cross(n, d0)
    a = P.face_angle.numpy()[:, None]
    U = P.scale * (np.cos(a) * d0 + np.sin(a) * y0)
    V = np.cross(n, U)
    return gu, gv, U, V


def test_tree_cumsum():
    parent = np.array([-1, 0, 1, 1, 3, -1, 5])
    delta = np.array([9, 1, 2, 3, 4, 7, 1])
    assert _tree_cumsum(delta, parent).tolist() == [0, 1, 3, 4, 8, 0, 1]


def test_cut_graph_is_a_disk_and_reaches_the_singularities():
    v, f = ev.meshes.ellipsoid((1.0, 0.8, 0.6), level=2)
    z = cross_field(v, f)
    topo = Topology(f)
    s = singularities(v, topo, z, 4)
    cg = cut_graph(v, topo, s.singular_vertices.numpy())
    assert int(cg.tree_edges.sum()) == topo.num_faces - 1
    cut_vertices = np.unique(topo.edges.numpy()[cg.cut_edges])
    assert set(s.singular_vertices.tolist()) <= set(cut_vertices.tolist())
    # genus 0: the cut is a tree (V_cut - E_cut = 1)
    assert cut_vertices.size - int(cg.cut_edges.sum()) == 1


def test_comb_matchings_vanish_on_the_tree_and_holonomy_marks_cones():
    v, f = ev.meshes.ellipsoid((1.0, 0.8, 0.6), level=3)
    z = cross_field(v, f)
    topo = Topology(f)
    cg = cut_graph(v, topo)
    c = comb(v, topo, z, cg)
    assert not c.matching[cg.tree_edges].any()
    s = singularities(v, topo, z, 4)
    cones = set(np.flatnonzero(c.holonomy).tolist())
    assert cones == set(s.singular_vertices.tolist())
    # the combed direction is one of the four roots of the field at the face centroid
    theta = face_frame_angles(v, topo)
    zf = z[topo.face_edges]
    w = (zf * torch.polar(torch.ones_like(theta), 4 * theta)).sum(1)
    assert np.allclose(np.cos(4 * c.angle), np.cos(torch.angle(w).numpy()), atol=1e-9)


def test_gradients_align_with_the_cross_field(ellipsoid_param):
    P, P0 = ellipsoid_param
    for res in (P, P0):
        gu, gv, U, V = _gradients(res)
        cos_u = (gu * U).sum(1) / np.linalg.norm(gu, axis=1) / np.linalg.norm(U, axis=1)
        cos_v = (gv * V).sum(1) / np.linalg.norm(gv, axis=1) / np.linalg.norm(V, axis=1)
        assert np.median(cos_u) > 0.99 and np.median(cos_v) > 0.99
        assert np.mean(cos_u > 0.9) > 0.95
        assert res.flipped == 0


def test_transitions_are_rotations_plus_integer_translations(ellipsoid_param):
    P, P0 = ellipsoid_param
    topo = Topology(P.faces)
    ef, ec = topo.edge_faces.numpy(), topo.edge_corners.numpy()
    for res, integer in ((P, True), (P0, False)):
        uv = res.uv.numpy()
        ce = np.flatnonzero(res.cut_edges.numpy())
        assert ce.size > 0
        k = res.matching.numpy()[ce]
        f, g = ef[ce, 0], ef[ce, 1]
        kf, kg = ec[ce, 0], ec[ce, 1]
        scale = np.abs(uv).max()
        for corner_f, corner_g in (((kf + 1) % 3, (kg + 2) % 3), ((kf + 2) % 3, (kg + 1) % 3)):
            wf = uv[f, corner_f, 0] + 1j * uv[f, corner_f, 1]
            wg = uv[g, corner_g, 0] + 1j * uv[g, corner_g, 1]
            t = wg - (1j ** (-k)) * wf
            assert np.allclose(t.real, res.translations.numpy()[:, 0], atol=1e-6 * scale)
            assert np.allclose(t.imag, res.translations.numpy()[:, 1], atol=1e-6 * scale)
        tr = res.translations.numpy()
        if integer:
            assert np.abs(tr - np.rint(tr)).max() < 1e-6
        else:
            assert np.abs(tr - np.rint(tr)).max() > 1e-3


def test_parametrization_on_spot_has_few_flips():
    from torch_edgevf.io import default_mesh

    v, f = default_mesh()
    z = cross_field(v, f)
    P = parametrize(v, f, z)
    assert P.flipped <= 0.01 * P.faces.shape[0], P.flipped
    tr = P.translations.numpy()
    assert np.abs(tr - np.rint(tr)).max() < 1e-6


def test_split_and_face_singularities_become_cut_vertices():
    v, f = ev.meshes.ellipsoid((1.0, 0.8, 0.6), level=2)
    g = torch.Generator().manual_seed(0)
    v = v + 0.01 * torch.randn(v.shape, generator=g, dtype=v.dtype)
    z = cross_field(v, f)
    topo = Topology(f)
    zr = z * torch.polar(
        torch.ones(topo.num_edges, dtype=torch.float64),
        0.3 * torch.randn(topo.num_edges, generator=g, dtype=torch.float64),
    )
    s = singularities(v, topo, zr, 4)
    P = parametrize(v, f, zr, round_integers=False)
    assert P.verts.shape[0] == v.shape[0] + s.singular_faces.numel()
    s2 = singularities(P.verts, P.faces, P.z, 4)
    assert s2.singular_faces.numel() == 0
    assert s2.total == 2


def test_flipped_faces_helper():
    uv = torch.tensor([[[0.0, 0], [1, 0], [0, 1]], [[0.0, 0], [0, 1], [1, 0]]])
    assert flipped_faces(uv).tolist() == [False, True]


def test_validation():
    v, f = ev.icosphere(1)
    with pytest.raises(ValueError, match="shape"):
        parametrize(v, f, torch.zeros(3, dtype=torch.complex128))
