"""Topology: edges, incidences, orientation, boundary, components, and every bad input."""

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.topology import Topology, remove_unreferenced_vertices

from conftest import perturbed_grid, perturbed_icosphere


def test_edges_sorted_unique_low_to_high():
    _, f = perturbed_icosphere(2)
    t = Topology(f)
    e = t.edges.numpy()
    assert (e[:, 0] < e[:, 1]).all()
    keys = e[:, 0] * t.num_vertices + e[:, 1]
    assert (np.diff(keys) > 0).all()
    assert t.num_edges == 3 * t.num_faces // 2


def test_face_edges_and_signs_match_corners():
    _, f = perturbed_icosphere(1)
    t = Topology(f)
    fa, e, fe, s = f.numpy(), t.edges.numpy(), t.face_edges.numpy(), t.face_edge_signs.numpy()
    for k in range(3):
        src, dst = fa[:, (k + 1) % 3], fa[:, (k + 2) % 3]
        np.testing.assert_array_equal(e[fe[:, k]], np.sort(np.stack([src, dst], 1), axis=1))
        np.testing.assert_array_equal(s[:, k], np.where(src < dst, 1, -1))


def test_edge_faces_slots_and_corners():
    _, f = perturbed_grid(3)
    t = Topology(f)
    for e in range(t.num_edges):
        for slot, sign in ((0, 1), (1, -1)):
            face, corner = int(t.edge_faces[e, slot]), int(t.edge_corners[e, slot])
            if face < 0:
                continue
            assert int(t.face_edges[face, corner]) == e
            assert int(t.face_edge_signs[face, corner]) == sign
    assert ((t.edge_faces >= 0).sum(1) == 2 - t.boundary_edges.long()).all()


def test_invariants_closed_open_and_components():
    v, f = ev.icosphere(2)
    t = Topology(f)
    assert t.is_closed and t.euler_characteristic == 2 and t.num_components == 1
    _, g = ev.meshes.grid(3, 5)
    tg = Topology(g)
    assert not tg.is_closed and tg.euler_characteristic == 1
    assert tg.num_boundary_edges == 2 * (3 + 5)
    assert int(tg.boundary_vertices.sum()) == 2 * (3 + 5)
    two = torch.cat([f, g + f.max() + 1])
    t2 = Topology(two)
    assert t2.num_components == 2 and t2.euler_characteristic == 3


def test_unreferenced_vertices_are_kept_and_reported():
    v, f = ev.icosphere(1)
    v2 = torch.cat([v, torch.zeros(2, 3, dtype=v.dtype)])
    t = Topology(f, num_vertices=v2.shape[0])
    assert t.unreferenced_vertices.tolist() == [v.shape[0], v.shape[0] + 1]
    assert t.components[-1] == -1 and t.euler_characteristic == 2
    ops = ev.EdgeOperators(v2, f)
    L = ops.laplace_beltrami.to_dense()
    assert L[-2:].abs().sum() == 0 and torch.isfinite(L).all()
    v3, f3, kept = remove_unreferenced_vertices(v2, f)
    assert torch.equal(v3, v) and torch.equal(f3, f) and kept.numel() == v.shape[0]


def _tet():
    return torch.tensor([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])


@pytest.mark.parametrize(
    "faces, match",
    [
        (torch.zeros(0, 3, dtype=torch.int64), "empty"),
        (torch.tensor([[0, 1, 2, 3]]), r"shape \(F, 3\)"),
        (torch.tensor([[0.0, 1.0, 2.0]]), "integer dtype"),
        (np.array([[0.0, 1.0, 2.0]]), "integer dtype"),
        ([[0, 1, 2]], "integer tensor"),
        (torch.tensor([[0, 1, -2]]), r"negative vertex indices in faces \[0\]"),
        (torch.tensor([[0, 1, 2], [0, 2, 1]]), "duplicated faces"),
        (torch.tensor([[0, 1, 2], [1, 1, 3]]), r"repeat a vertex index within a face at faces \[1\]"),
        (torch.tensor([[0, 1, 2], [0, 1, 3], [0, 1, 4]]), r"non-manifold edges.*\(0, 1\)"),
        (torch.tensor([[0, 1, 2], [0, 1, 3]]), r"inconsistent face orientation.*\(0, 1\)"),
        (torch.tensor([[0, 1, 2], [0, 3, 4]]), r"non-manifold vertices.*\[0\]"),
    ],
)
def test_bad_faces_raise_named_errors(faces, match):
    with pytest.raises(ValueError, match=match):
        Topology(faces)


def test_out_of_range_index_names_face():
    with pytest.raises(ValueError, match=r"out-of-range vertex indices \(>= 3 vertices\) in faces \[1\]"):
        Topology(torch.tensor([[0, 1, 2], [2, 1, 3]]), num_vertices=3)


def test_inputs_not_modified():
    f = _tet()
    before = f.clone()
    Topology(f)
    assert torch.equal(f, before)


def test_require_closed_names_boundary():
    _, g = ev.meshes.grid(2, 2)
    with pytest.raises(ValueError, match="requires a closed mesh.*8 boundary edges"):
        Topology(g).require_closed("the test")
