"""repair(): triangle soups made into meshes the operators accept, every change reported."""

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.mesh.repair import mollify_lengths


def _sphere(level=1):
    v, f = ev.icosphere(level)
    return v.numpy().copy(), f.numpy().copy()


def _accounted(result, num_faces):
    """Every input face is kept (in face_origin) or reported as dropped."""
    kept = set(result.face_origin.tolist())
    dropped = set(result.report.dropped_faces)
    assert kept.isdisjoint(dropped)
    assert kept | dropped == set(range(num_faces))


def _rotated(f):
    """Each triangle rotated to start at its smallest index (same orientation)."""
    k = f.argmin(1)
    return np.stack([f[np.arange(len(f)), (k + j) % 3] for j in range(3)], 1)


def _check_valid(result):
    """Operators on the repaired mesh: finite, PSD, Hermitian."""
    geom, topo = result.geometry, result.topology
    lc = ev.connection_laplacian(geom, topo, n=1).to_dense()
    m = ev.mass_matrix(geom, topo).to_dense()
    assert torch.isfinite(lc).all() and torch.isfinite(m).all()
    assert torch.allclose(lc, lc.conj().T, atol=1e-12)
    assert float(torch.linalg.eigvalsh(lc).min()) > -1e-8 * float(lc.abs().max())
    assert float(m.diagonal().min()) > 0


def test_clean_mesh_is_unchanged_and_input_is_not_modified():
    v, f = _sphere()
    v0, f0 = v.copy(), f.copy()
    r = ev.repair(v, f)
    assert not r.report.changed and r.epsilon == 0.0
    assert np.array_equal(r.faces.numpy(), f) and np.array_equal(r.verts.numpy(), v)
    assert np.array_equal(r.vertex_origin.numpy(), np.arange(len(v)))
    assert np.array_equal(v, v0) and np.array_equal(f, f0)
    assert "nothing to repair" in r.report.summary()
    lengths = ev.edge_lengths(r.verts, r.topology)
    assert torch.equal(r.edge_lengths, lengths)


def test_tensor_input_is_not_modified_and_dtype_kept():
    v, f = ev.icosphere(1)
    v32 = v.float()
    f2 = torch.cat([f, f[:3]])  # three duplicates
    before = (v32.clone(), f2.clone())
    r = ev.repair(v32, f2)
    assert r.verts.dtype == torch.float32
    assert torch.equal(v32, before[0]) and torch.equal(f2, before[1])
    assert [a for a, _ in r.report.duplicate_faces] == [f.shape[0], f.shape[0] + 1, f.shape[0] + 2]


def test_flipped_patch_is_reoriented_minority_first():
    v, f = _sphere()
    flip = np.arange(0, 12)
    f[flip] = f[flip][:, ::-1]
    r = ev.repair(v, f)
    assert sorted(r.report.flipped_faces) == flip.tolist()
    assert r.flipped.sum() == len(flip)
    ref = ev.icosphere(1)[1].numpy()
    assert np.array_equal(_rotated(r.faces.numpy()), _rotated(ref))
    _accounted(r, len(f))


def test_majority_flipped_flips_the_minority():
    v, f = _sphere()
    f = f[:, ::-1].copy()
    f[:5] = f[:5][:, ::-1]
    r = ev.repair(v, f)
    assert r.report.flipped_faces == [0, 1, 2, 3, 4]


def test_bowtie_vertex_is_split():
    # two triangles touching at one vertex
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], dtype=float)
    f = np.array([[0, 1, 2], [0, 3, 4]])
    with pytest.raises(ValueError):
        ev.Topology(f)
    r = ev.repair(v, f)
    assert r.report.non_manifold_vertices == [0]
    assert r.report.split_vertices == {0: 2}
    assert r.verts.shape[0] == 6 and sorted(r.vertex_origin.tolist()) == [0, 0, 1, 2, 3, 4]
    assert torch.equal(r.verts, torch.from_numpy(v)[r.vertex_origin])
    _check_valid(r)


def test_fan_of_three_faces_on_one_edge_is_cut():
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1]], dtype=float)
    f = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    r = ev.repair(v, f)
    assert r.report.non_manifold_edges == [(0, 1)]
    assert r.topology.num_faces == 3
    _accounted(r, 3)
    _check_valid(r)


def test_moebius_strip_is_a_clear_error():
    n = 8
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    verts = []
    for a in t:
        for s in (-0.3, 0.3):
            r = 1 + s * np.cos(a / 2)
            verts.append([r * np.cos(a), r * np.sin(a), s * np.sin(a / 2)])
    faces = []
    for i in range(n):
        a0, a1 = 2 * i, 2 * i + 1
        if i < n - 1:
            b0, b1 = 2 * i + 2, 2 * i + 3
        else:
            b0, b1 = 1, 0  # the half twist
        faces += [[a0, b0, a1], [a1, b0, b1]]
    with pytest.raises(ValueError, match="cannot be oriented"):
        ev.repair(np.array(verts), np.array(faces))


def test_repeated_indices_quads_and_polygons():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0]], dtype=float)
    faces = [[0, 1, 2, 3], [1, 4, 5, 5, 2], [0, 0, 1]]
    r = ev.repair(v, faces)
    rep = r.report
    assert rep.triangulated_faces == [0, 1] and rep.added_triangles == 2
    assert rep.repeated_index_faces == [1, 2]
    assert rep.dropped_faces == {2: "repeated vertex indices"}
    assert r.face_origin.tolist() == [0, 0, 1, 1]
    _accounted(r, 3)


def test_nonfinite_vertex_faces_dropped_and_named():
    v, f = _sphere()
    v[5] = np.nan
    r = ev.repair(v, f)
    assert r.report.nonfinite_vertices == [5]
    bad = np.flatnonzero((f == 5).any(1)).tolist()
    assert sorted(r.report.dropped_faces) == bad
    assert 5 in r.report.unreferenced_vertices
    assert torch.isfinite(r.verts).all()


def test_out_of_range_index_is_an_error():
    v, f = _sphere()
    f[3, 1] = 999
    with pytest.raises(ValueError, match=r"faces \[3\]"):
        ev.repair(v, f)


def test_zero_area_cap_flipped_without_moving_vertices():
    v, f = _sphere(2)
    # move a vertex onto the segment of two of its neighbours: collinear triple, a cap
    i = int(f[0, 0])
    a, b = f[0, 1], f[0, 2]
    v[i] = 0.5 * (v[a] + v[b])
    with pytest.raises(ValueError, match="zero-area"):
        ev.face_geometry(torch.from_numpy(v), torch.from_numpy(f))
    r = ev.repair(v, f)
    assert r.report.flipped_caps == [0] and r.epsilon == 0 and r.report.mollified_faces == []
    assert torch.equal(r.verts, torch.from_numpy(v)) and len(r.faces) == len(f)
    # the positions themselves now pass: the cap and the face across ab became two triangles
    # covering that face, with the winding of the sheet
    areas = ev.face_areas(r.verts, r.faces)
    soup = torch.from_numpy(v[f[1:]].reshape(-1, 3))  # the other faces, apart (the cap has no area)
    before = ev.face_areas(soup, torch.arange(len(soup)).reshape(-1, 3))
    assert float(areas.sum()) == pytest.approx(float(before.sum()), rel=1e-12)
    _check_valid(r)
    ops = ev.EdgeOperators(r.verts, r.faces)
    assert torch.isfinite(ops.connection_laplacian.values()).all()
    # the edge ab is gone, replaced by the edge from i to the far corner of the face across it
    edges = {tuple(sorted(e)) for e in r.topology.edges.tolist()}
    assert tuple(sorted((int(a), int(b)))) not in edges


@pytest.mark.parametrize("scale", [1e-170, 1e-100, 1.0, 1e100, 1e160])
def test_zero_area_caps_found_at_every_scale(scale):
    """The zero-area test is scale-free: at coordinates whose squares underflow or overflow
    it finds the one cap, no other face, and warns of nothing."""
    import warnings

    from torch_edgevf.mesh.repair import find_degenerate_faces

    v, f = _sphere(2)
    assert find_degenerate_faces(v * scale, f).size == 0
    v[int(f[0, 0])] = 0.5 * (v[f[0, 1]] + v[f[0, 2]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert find_degenerate_faces(v * scale, f).tolist() == [0]
        assert ev.repair(v * scale, f).report.flipped_caps == [0]


def test_zero_area_needle_mollified_without_moving_vertices():
    v, f = _sphere(2)
    # move a vertex onto its neighbour: a zero-length edge, no flip can help
    i = int(f[0, 0])
    a = f[0, 1]
    v[i] = v[a]
    with pytest.raises(ValueError, match="zero-area"):
        ev.face_geometry(torch.from_numpy(v), torch.from_numpy(f))
    r = ev.repair(v, f)
    assert r.epsilon > 0 and 0 in r.report.mollified_faces and r.report.flipped_caps == []
    assert torch.equal(r.verts, torch.from_numpy(v))
    slack = r.geometry.lengths.sum(1, keepdim=True) - 2 * r.geometry.lengths
    assert float(slack.min()) >= r.report.delta * (1 - 1e-9)
    _check_valid(r)
    z = ev.smoothest_field(r.geometry, r.topology, n=4)
    s = ev.singularities(r.geometry, r.topology, z, n=4)
    assert s.total == r.topology.euler_characteristic == 2


def test_mollify_lengths_is_smallest_and_differentiable():
    lengths = torch.tensor([1.0, 1.0, 2.0, 1.5, 1.2], dtype=torch.float64, requires_grad=True)
    fe = torch.tensor([[0, 1, 2], [2, 3, 4]])
    out, eps, faces = mollify_lengths(lengths, fe, factor=1e-3)
    delta = 1e-3 * float(lengths.detach().mean())
    assert faces.tolist() == [0]
    assert float(eps.detach()) == pytest.approx(delta)
    geom = ev.FaceGeometry.from_lengths(out[fe])
    geom.area.sum().backward()
    assert torch.isfinite(lengths.grad).all()
    # a valid mesh is left alone
    out2, eps2, faces2 = mollify_lengths(torch.tensor([1.0, 1.0, 1.0]), torch.tensor([[0, 1, 2]]))
    assert float(eps2) == 0 and faces2.numel() == 0


def test_operators_accept_geometry_from_edge_lengths_gradcheck():
    v, f = ev.icosphere(0)
    topo = ev.Topology(f)
    lengths = ev.edge_lengths(v, topo).detach().requires_grad_(True)
    geom = ev.FaceGeometry.from_edge_lengths(lengths, topo)
    for op in (ev.mass_matrix, ev.connection_laplacian, ev.gradient, ev.laplace_beltrami, ev.cotan_laplacian):
        a = op(geom, topo).to_dense()
        b = op(v, topo).to_dense()
        assert torch.allclose(a, b, atol=1e-12), op.__name__

    def energy(l):
        g = ev.FaceGeometry.from_edge_lengths(l, topo)
        return ev.connection_laplacian(g, topo, n=2).to_dense().abs().sum()

    assert torch.autograd.gradcheck(energy, (lengths,))
    with pytest.raises(ValueError, match="lengths must be an"):
        ev.FaceGeometry.from_edge_lengths(lengths[:-1], topo)


def test_designer_and_singularities_accept_geometry():
    v, f = ev.icosphere(2)
    topo = ev.Topology(f)
    geom = ev.FaceGeometry.from_edge_lengths(ev.edge_lengths(v, topo), topo)
    z_pos = ev.smoothest_field(v, topo, n=4)
    z_len = ev.smoothest_field(geom, topo, n=4)
    assert torch.allclose(z_pos.abs(), z_len.abs(), atol=1e-8)
    s = ev.singularities(geom, topo, z_len, n=4)
    assert s.total == 2


def test_map_edge_field_back_to_input():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], dtype=float)
    f = np.array([[0, 1, 2], [0, 3, 4]])
    r = ev.repair(v, f)
    z = torch.arange(r.topology.num_edges, dtype=torch.float64) + 1j
    mapped = r.map_edge_field(z, n=1)
    assert mapped.edges.tolist() == [[0, 1], [0, 2], [0, 3], [0, 4], [1, 2], [3, 4]]
    assert not mapped.cut.any()
    vo = r.vertex_origin
    for e, (a, b) in enumerate(r.topology.edges.tolist()):
        key = sorted((int(vo[a]), int(vo[b])))
        row = mapped.edges.tolist().index(key)
        sign = 1 if vo[a] < vo[b] else -1
        assert mapped.values[row] == sign * z[e]
    assert mapped.face_values.shape == (2, 3)
    faces = r.map_face_values(torch.tensor([1.0, 2.0]))
    assert faces[r.face_origin].tolist() == [1.0, 2.0]
    verts = r.map_vertex_values(torch.ones(r.topology.num_vertices))
    assert torch.equal(verts, torch.ones(5, dtype=verts.dtype))


def test_cut_edge_is_marked_cut_in_the_mapping():
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1]], dtype=float)
    f = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    r = ev.repair(v, f)
    mapped = r.map_edge_field(torch.ones(r.topology.num_edges, dtype=torch.complex128), n=2)
    row = mapped.edges.tolist().index([0, 1])
    assert bool(mapped.cut[row]) and torch.isnan(mapped.values[row])
