"""Topology: edges, incidences, orientation, boundary, components, and every bad input."""

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.mesh.topology import Topology, remove_unreferenced_vertices

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


def _fans_reference(f: np.ndarray) -> np.ndarray:
    """Number of fans per vertex: connected components of its faces through shared edges."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    nv = int(f.max()) + 1
    corner_vertex = f.ravel()
    # corners at the same vertex in faces sharing an edge through that vertex are linked
    pairs = {}
    for face, (a, b, c) in enumerate(f):
        for u, w in ((a, b), (b, c), (c, a)):
            pairs.setdefault((min(u, w), max(u, w)), []).append((face, u, w))
    rows, cols = [], []
    for (u, w), members in pairs.items():
        for i in range(len(members)):
            for j in range(i + 1, len(members)):
                for x in (u, w):
                    fi, fj = members[i][0], members[j][0]
                    rows.append(3 * fi + list(f[fi]).index(x))
                    cols.append(3 * fj + list(f[fj]).index(x))
    nc = 3 * len(f)
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(nc, nc))
    _, labels = connected_components(graph, directed=False)
    fans = np.zeros(nv, dtype=int)
    for v in range(nv):
        fans[v] = np.unique(labels[corner_vertex == v]).size
    return fans


@pytest.mark.parametrize("case", ["closed_and_open", "two_closed", "two_open", "valid_cone", "valid_grid"])
def test_fan_check_agrees_with_connected_components(case):
    """The walking fan count matches a connected-components reference on glued meshes."""
    sphere = ev.icosphere(1)[1].numpy()
    nsph = int(sphere.max()) + 1
    grid = ev.meshes.grid(4, 4)[1].numpy()
    cone = np.array([[0, 1 + k, 2 + k] for k in range(39)])  # an open fan of 39 faces around vertex 0
    if case == "closed_and_open":
        f = np.concatenate([sphere, grid + nsph])
        f[f == nsph] = 0  # a grid corner (open fan) glued to a sphere vertex (closed fan)
    elif case == "two_closed":
        f = np.concatenate([sphere, sphere + nsph])
        f[f == nsph + 3] = 3
    elif case == "two_open":
        f = np.concatenate([cone, cone + 41])
        f[f == 41] = 0
    elif case == "valid_cone":
        f = cone
    else:
        f = grid
    fans = _fans_reference(f)
    bad = np.flatnonzero(fans > 1)
    assert bool(bad.size) == (not case.startswith("valid"))
    if bad.size:
        with pytest.raises(ValueError, match=r"non-manifold vertices.*\[" + ", ".join(map(str, bad))):
            Topology(torch.from_numpy(f))
    else:
        Topology(torch.from_numpy(f))


@pytest.mark.parametrize("mesh", ["closed", "open"])
def test_int64_work_arrays_give_the_same_topology_and_operators(mesh, monkeypatch):
    """Meshes too large for int32 work arrays take the int64 path; it must agree exactly."""
    import torch_edgevf.mesh.topology as topology_module

    v, f = perturbed_icosphere(1, seed=3) if mesh == "closed" else perturbed_grid(5, seed=3)
    small = Topology(f, num_vertices=v.shape[0])
    monkeypatch.setattr(topology_module, "_work_dtype", lambda nv, nf: np.int64)
    large = Topology(f, num_vertices=v.shape[0])
    assert large.side_corners().dtype == np.int64 and small.side_corners().dtype == np.int32
    for name in (
        "faces",
        "edges",
        "face_edges",
        "face_edge_signs",
        "edge_faces",
        "edge_corners",
        "boundary_edges",
        "boundary_vertices",
    ):
        a, b = getattr(small, name), getattr(large, name)
        assert a.dtype == b.dtype and torch.equal(a, b), name
    for n in (0, 1, 3):
        la, lb = ev.connection_laplacian(v, small, n), ev.connection_laplacian(v, large, n)
        assert torch.equal(la.indices(), lb.indices()) and torch.equal(la.values(), lb.values())
    assert torch.equal(ev.mass_matrix(v, small).values(), ev.mass_matrix(v, large).values())


def test_topology_pickles_with_its_lazy_attributes():
    import pickle

    v, f = perturbed_icosphere(1, seed=4)
    t = Topology(f)
    _ = t.edges  # one made before pickling, the others after
    u = pickle.loads(pickle.dumps(t))
    for name in ("faces", "edges", "face_edges", "face_edge_signs", "edge_faces", "edge_corners"):
        assert torch.equal(getattr(t, name), getattr(u, name)), name
    assert torch.equal(ev.connection_laplacian(v, u).to_dense(), ev.connection_laplacian(v, t).to_dense())
