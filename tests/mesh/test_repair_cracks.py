"""Zero-width cracks: coincident vertices and T-junctions, found, reported and closed on request."""

from pathlib import Path

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.mesh.diagnose import COINCIDENT_TOL, diagnose, find_coincident_vertices, find_t_junctions
from torch_edgevf.mesh.repair import repair
from torch_edgevf.operators.functional import connection_laplacian, mass_matrix

from conftest import SHARED, shared_path

# --------------------------------------------------------------------------- generated cracks


def cracked_grid(n: int = 4, slit: bool = False):
    """An n x n grid cut along x = 1/2: faces right of the line use copies of its vertices.

    With ``slit``, only the inner vertices of the line are copied (a slit inside the
    square, whose two ends stay joined). Returns verts, faces, the uncut faces and the
    expected coincident pairs ``(original, copy)``.
    """
    assert n % 2 == 0
    v, f = ev.meshes.grid(n, n)
    v, f = v.numpy(), f.numpy()
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    line = idx[n // 2]
    if slit:
        line = line[1:-1]
    copies = len(v) + np.arange(len(line))
    right = v[f].mean(1)[:, 0] > 0.5
    to_copy = np.arange(len(v))
    to_copy[line] = copies
    cut = f.copy()
    cut[right] = to_copy[cut[right]]
    return np.concatenate([v, v[line]]), cut, f, np.stack([line, copies], 1)


def refined_seam(pieces: int = 2):
    """[0, 1]^2 as a 2 x 2 grid beside [1, 2] x [0, 1] as a 2 x (2 pieces) grid, sharing vertices.

    The vertices the two sides have in common (x = 1, y = 0, 1/2, 1) are shared; the
    extra ones of the finer side lie inside the coarse side's boundary edges: T-junctions.
    Returns verts, faces and the expected rows ``(vertex, a, b, face)``.
    """
    v1, f1 = ev.meshes.grid(2, 2)
    v2, f2 = ev.meshes.grid(2, 2 * pieces)
    v1, f1, v2, f2 = v1.numpy(), f1.numpy(), v2.numpy() + [1.0, 0.0, 0.0], f2.numpy()
    # the finer side's left column is x = 1; its vertices with y in {0, 1/2, 1} are the coarse side's
    coarse_seam = {round(y * 2): i for i, (x, y, _) in enumerate(v1) if x == 1.0}
    index = np.arange(len(v2)) + len(v1)
    extra = []
    for j, (x, y, _) in enumerate(v2):
        if x == 1.0 and (y * 2) == round(y * 2):
            index[j] = coarse_seam[round(y * 2)]
        elif x == 1.0:
            extra.append(j)
    keep = np.flatnonzero(index >= len(v1))
    renumber = np.full(len(v2), -1)
    renumber[keep] = len(v1) + np.arange(len(keep))
    index = np.where(index >= len(v1), renumber, index)
    verts = np.concatenate([v1, v2[keep]])
    faces = np.concatenate([f1, index[f2]])
    expected = []
    for j in extra:
        y = v2[j, 1]
        lo, hi = coarse_seam[int(np.floor(y * 2))], coarse_seam[int(np.ceil(y * 2))]
        face = [i for i, t in enumerate(f1) if lo in t and hi in t]
        assert len(face) == 1
        expected.append((int(index[j]), min(lo, hi), max(lo, hi), face[0]))
    expected.sort(key=lambda row: (row[3], (verts[row[0], 1])))
    return verts, faces, np.array(expected, dtype=np.int64)


def two_sided_t():
    """A big triangle with a T-junction vertex on two of its edges (two rounds of splitting)."""
    verts = np.array(
        [[0, 0, 0], [2, 0, 0], [0, 2, 0], [1, 0, 0], [1, -1, 0], [0, 1, 0], [-1, 1, 0]], dtype=np.float64
    )
    a, b, c, m, d, n, e = range(7)
    faces = np.array([[a, b, c], [a, d, m], [m, d, b], [a, n, e], [n, c, e]])
    return verts, faces, np.array([[m, a, b, 0], [n, a, c, 0]])


def face_set(faces) -> set:
    return {tuple(sorted(t)) for t in np.asarray(faces).tolist()}


def total_area(verts, faces) -> float:
    p = np.asarray(verts, dtype=np.float64)[np.asarray(faces)]
    return float(np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum() / 2)


def assert_operators_finite(result):
    geometry = result.geometry if result.mollified else result.verts
    for op in (connection_laplacian(geometry, result.topology, 1), mass_matrix(geometry, result.topology)):
        values = op.coalesce().values()
        assert values.dtype in (torch.float64, torch.complex128)
        assert bool(torch.isfinite(values).all())


def rotated_and_renumbered(verts, faces, seed: int = 0):
    """A random rotation, offset and vertex permutation; returns the new mesh and ``new_of_old``."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    perm = rng.permutation(len(verts))  # new vertex i is old vertex perm[i]
    new_of_old = np.empty_like(perm)
    new_of_old[perm] = np.arange(len(perm))
    v = (verts @ q.T + rng.normal(size=3))[perm]
    return v, new_of_old[faces], new_of_old


# --------------------------------------------------------------------------- coincident vertices


@pytest.mark.parametrize("slit", [False, True])
def test_coincident_vertices_found_exactly(slit):
    v, f, _, pairs = cracked_grid(6, slit)
    assert np.array_equal(find_coincident_vertices(v, f), pairs)
    assert np.array_equal(find_coincident_vertices(v, f, tol=0), pairs)
    assert find_t_junctions(v, f).shape == (0, 4)
    d = diagnose(v, f)
    assert np.array_equal(d.coincident_vertices, pairs)
    assert [p for p in d.problems if "coincident" in p] == [
        p for p in d.problems if f"{len(pairs)} pairs of coincident vertices" in p and "merge_coincident" in p
    ]
    assert any(f"({pairs[0, 0]}, {pairs[0, 1]})" in p for p in d.problems)
    # after a rotation, an offset and a renumbering: the same pairs, renamed
    v2, f2, new = rotated_and_renumbered(v, f)
    renamed = np.sort(new[pairs], axis=1)
    renamed = renamed[np.lexsort((renamed[:, 1], renamed[:, 0]))]
    assert np.array_equal(find_coincident_vertices(v2, f2), renamed)


def test_coincident_tolerance_relative_to_the_diagonal():
    v, f, _, pairs = cracked_grid(4)
    nv = len(v) - len(pairs)
    near = v.copy()
    near[nv:, 0] += 1e-3 * COINCIDENT_TOL  # well inside the tolerance, not bitwise equal
    assert np.array_equal(find_coincident_vertices(near, f), pairs)
    assert find_coincident_vertices(near, f, tol=0).shape == (0, 2)
    far = v.copy()
    far[nv:, 0] += 1e3 * COINCIDENT_TOL
    assert find_coincident_vertices(far, f).shape == (0, 2)
    assert np.array_equal(find_coincident_vertices(far, f, tol=1e-2), pairs)
    # scale-free, also near the float64 limits (the positions are scaled by a power of two)
    for scale in (1e-150, 1e150, 1e300):
        assert np.array_equal(find_coincident_vertices(near * scale, f), pairs)


def test_unreferenced_copies_are_not_coincident():
    v, f = ev.meshes.grid(3, 3)
    v = torch.cat([v, v[:2]])  # two unreferenced vertices on top of referenced ones
    assert find_coincident_vertices(v, f).shape == (0, 2)
    assert diagnose(v, f).coincident_vertices.shape == (0, 2)


def test_repair_reports_coincident_vertices_and_leaves_them_by_default():
    v, f, _, pairs = cracked_grid(4)
    vin, fin = v.copy(), f.copy()
    result = repair(v, f)
    rep = result.report
    assert rep.coincident_vertices == [tuple(p) for p in pairs.tolist()]
    assert rep.merged_vertices == {} and not rep.changed and rep.cracks
    topo = result.topology
    assert (topo.num_components, topo.euler_characteristic, topo.num_boundary_edges) == (2, 2, 4 * 4 + 2 * 4)
    assert "not merged" in rep.summary() and "merge_coincident=True" in rep.summary()
    assert np.array_equal(v, vin) and np.array_equal(f, fin)


@pytest.mark.parametrize("slit", [False, True])
def test_merge_closes_the_crack(slit):
    n = 6
    v, f, uncut, pairs = cracked_grid(n, slit)
    vt, ft = torch.from_numpy(v), torch.from_numpy(f)
    vin, fin = vt.clone(), ft.clone()
    result = repair(vt, ft, merge_coincident=True)
    rep = result.report
    assert torch.equal(vt, vin) and torch.equal(ft, fin)  # nothing the caller passed is modified
    assert rep.merged_vertices == {int(c): int(o) for o, c in pairs}
    assert rep.collapsed_faces == [] and rep.dropped_faces == {} and rep.unreferenced_vertices == []
    assert rep.changes()["coincident vertices merged"] == len(pairs)
    topo = result.topology
    assert (topo.num_vertices, topo.num_faces) == ((n + 1) ** 2, 2 * n * n)
    assert (topo.num_components, topo.euler_characteristic, topo.num_boundary_edges) == (1, 1, 4 * n)
    # the repaired faces, in input vertices, are the uncut grid
    vo = result.vertex_origin.numpy()
    assert face_set(vo[result.faces.numpy()]) == face_set(uncut)
    assert torch.equal(result.verts, vt[result.vertex_origin])
    merged_to = result.merged_to.numpy()
    assert np.array_equal(merged_to[pairs[:, 1]], pairs[:, 0])
    assert np.array_equal(merged_to[vo], vo)  # vertex_origin names the kept vertices
    assert_operators_finite(result)
    # values come back on both vertices of a merged pair, and on both sides' edges
    x = torch.arange(topo.num_vertices, dtype=torch.float64)
    back = result.map_vertex_values(x)
    assert torch.equal(back[pairs[:, 1]], back[pairs[:, 0]]) and bool(torch.isfinite(back).all())
    z = torch.randn(topo.num_edges, dtype=torch.complex128, generator=torch.Generator().manual_seed(0))
    mapped = result.map_edge_field(z, n=1)
    edges = mapped.edges.numpy()
    copy_of = dict(zip(pairs[:, 0].tolist(), pairs[:, 1].tolist()))
    a, b = int(pairs[0, 0]), int(pairs[1, 0])  # a crack edge on the line, and its copy
    ia = np.flatnonzero((edges == [min(a, b), max(a, b)]).all(1))
    ca, cb = copy_of[a], copy_of[b]
    ib = np.flatnonzero((edges == [min(ca, cb), max(ca, cb)]).all(1))
    assert len(ia) == len(ib) == 1
    assert bool(torch.isfinite(mapped.values[ia]).all()) and not bool(mapped.cut.any())
    assert torch.allclose(mapped.values[ia], mapped.values[ib])
    assert bool(torch.isfinite(mapped.values).all())  # every input edge has one image


def test_merge_of_a_zero_length_edge_drops_and_reports_its_faces():
    v, f = ev.meshes.grid(2, 2)
    v = v.clone()
    v[4] = v[1]  # the centre onto the middle of the bottom side: faces 0 and 4 lose their area
    result = repair(v, f, merge_coincident=True)
    rep = result.report
    assert rep.coincident_vertices == [(1, 4)] and rep.merged_vertices == {4: 1}
    assert rep.collapsed_faces == sorted(i for i, t in enumerate(f.tolist()) if 1 in t and 4 in t)
    assert set(rep.dropped_faces) == set(rep.collapsed_faces)
    assert "collapsed" in rep.summary()


# --------------------------------------------------------------------------- T-junctions


@pytest.mark.parametrize("pieces", [2, 3])
def test_t_junctions_found_exactly(pieces):
    v, f, expected = refined_seam(pieces)
    assert len(expected) == 2 * (pieces - 1)
    assert find_coincident_vertices(v, f).shape == (0, 2)
    assert np.array_equal(find_t_junctions(v, f), expected)
    d = diagnose(v, f)
    assert np.array_equal(d.t_junctions, expected)
    assert any(f"{len(expected)} T-junctions" in p and "split_t_junctions=True" in p for p in d.problems)
    # renumbered and moved: the same rows, renamed (the edge's ends sorted again)
    v2, f2, new = rotated_and_renumbered(v, f, seed=1)
    got = find_t_junctions(v2, f2)
    want = {(int(new[w]), *sorted((int(new[a]), int(new[b]))), int(t)) for w, a, b, t in expected}
    assert {tuple(r) for r in got.tolist()} == want


def test_t_junction_needs_the_vertex_strictly_inside_and_close():
    v, f, expected = refined_seam(2)
    w = expected[0, 0]
    off = v.copy()
    off[w, 0] += 1e3 * COINCIDENT_TOL * np.sqrt(5)  # off the line, beyond the tolerance
    assert find_t_junctions(off, f)[:, 0].tolist() == [expected[1, 0]]
    near = v.copy()
    near[w, 0] += 1e-2 * COINCIDENT_TOL
    assert np.array_equal(find_t_junctions(near, f), expected)
    # a grid's boundary vertices are collinear with its boundary edges, but never inside one
    g, gf = ev.meshes.grid(8, 3)
    assert find_t_junctions(g, gf).shape == (0, 4)


@pytest.mark.parametrize("pieces", [2, 3])
def test_split_closes_the_t_junctions(pieces):
    v, f, expected = refined_seam(pieces)
    vin, fin = v.copy(), f.copy()
    default = repair(v, f)
    assert default.report.t_junctions == [tuple(r) for r in expected.tolist()]
    assert default.report.split_faces == []
    # the sides touch only at the shared vertices: bowties, split apart into two squares
    assert default.topology.num_components == 2 and default.topology.num_boundary_edges == 8 + 4 + 4 * pieces
    result = repair(v, f, split_t_junctions=True)
    rep = result.report
    assert np.array_equal(v, vin) and np.array_equal(f, fin)
    faces_split = sorted(set(expected[:, 3].tolist()))
    assert rep.split_faces == faces_split
    assert rep.t_junction_triangles == len(expected)
    assert rep.changes()["faces split at T-junctions"] == len(faces_split)
    topo = result.topology
    assert topo.num_faces == len(f) + len(expected)
    assert (topo.num_components, topo.euler_characteristic) == (1, 1)
    assert topo.num_boundary_edges == 2 + 2 + 2 + 2 * pieces + 2 + 2  # the outline of [0, 2] x [0, 1]
    assert torch.equal(result.vertex_origin, torch.arange(len(v)))
    counts = np.bincount(result.face_origin.numpy(), minlength=len(f))
    assert counts[faces_split].tolist() == [pieces] * len(faces_split) and counts.sum() == topo.num_faces
    assert total_area(result.verts, result.faces) == pytest.approx(total_area(v, f), rel=1e-14)
    assert result.report.flipped_faces == []
    assert find_t_junctions(result.verts, result.faces).shape == (0, 4)
    assert diagnose(result.verts, result.faces).ok
    assert_operators_finite(result)


def test_t_junctions_on_two_edges_of_one_face():
    v, f, expected = two_sided_t()
    assert np.array_equal(find_t_junctions(v, f), expected)
    result = repair(v, f, split_t_junctions=True)
    assert result.report.split_faces == [0] and result.report.t_junction_triangles == 2
    topo = result.topology
    assert (topo.num_faces, topo.euler_characteristic, topo.num_boundary_edges) == (7, 1, 5)
    assert total_area(result.verts, result.faces) == pytest.approx(total_area(v, f), rel=1e-14)
    assert find_t_junctions(result.verts, result.faces).shape == (0, 4)
    assert_operators_finite(result)


def test_merge_then_split_a_seam_of_both_kinds():
    """The finer side with its own copies of the shared vertices: merged first, then split."""
    v1, f1 = ev.meshes.grid(2, 2)
    v2, f2 = ev.meshes.grid(2, 4)
    v = np.concatenate([v1.numpy(), v2.numpy() + [1.0, 0.0, 0.0]])
    f = np.concatenate([f1.numpy(), f2.numpy() + len(v1)])
    assert len(find_coincident_vertices(v, f)) == 3 and len(find_t_junctions(v, f)) == 2
    result = repair(v, f, merge_coincident=True, split_t_junctions=True)
    rep = result.report
    assert len(rep.merged_vertices) == 3 and len(rep.split_faces) == 2
    topo = result.topology
    assert (topo.num_vertices, topo.num_components, topo.euler_characteristic) == (len(v) - 3, 1, 1)
    assert topo.num_boundary_edges == 14
    assert diagnose(result.verts, result.faces).ok
    assert_operators_finite(result)
    # only one of the two: still two squares (merged alone, the sides touch at three bowties)
    merged = repair(v, f, merge_coincident=True)
    assert merged.topology.num_components == 2
    assert merged.report.split_vertices == dict.fromkeys(sorted(rep.merged_vertices.values()), 2)
    split = repair(v, f, split_t_junctions=True)
    assert split.topology.num_components == 2 and len(split.report.split_faces) == 2


# --------------------------------------------------------------------------- clean meshes


def _trimesh_meshes():
    trimesh = pytest.importorskip("trimesh")
    return {
        "trimesh icosphere": trimesh.creation.icosphere(subdivisions=3),
        "trimesh torus": trimesh.creation.torus(major_radius=1.0, minor_radius=0.3),
        "trimesh cylinder": trimesh.creation.cylinder(radius=1.0, height=2.0, sections=24),
        "trimesh annulus": trimesh.creation.annulus(r_min=0.5, r_max=1.0, height=0.3),
    }


def clean_meshes():
    meshes = {
        "icosphere": ev.icosphere(3),
        "grid": ev.meshes.grid(9, 5),
        "cylinder (open)": ev.meshes.cylinder(),
        "ellipsoid": ev.meshes.ellipsoid(),
        "sphere_delaunay": ev.meshes.sphere_delaunay(400),
    }
    return meshes


@pytest.mark.parametrize("name", list(clean_meshes()))
def test_nothing_reported_on_clean_library_meshes(name):
    v, f = clean_meshes()[name]
    assert find_coincident_vertices(v, f).shape == (0, 2)
    assert find_t_junctions(v, f).shape == (0, 4)
    assert diagnose(v, f).ok
    rep = repair(v, f, merge_coincident=True, split_t_junctions=True).report
    assert not rep.cracks and not rep.changed, rep.summary()


def test_nothing_reported_on_trimesh_meshes():
    for name, mesh in _trimesh_meshes().items():
        v, f = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
        assert find_coincident_vertices(v, f).shape == (0, 2), name
        assert find_t_junctions(v, f).shape == (0, 4), name
        rep = repair(v, f, merge_coincident=True, split_t_junctions=True).report
        assert not rep.cracks, (name, rep.summary())


def _shared_mesh_files():
    if not (SHARED / "meshes").is_dir():
        return ["missing"]
    files = [
        p for p in sorted((SHARED / "meshes").rglob("*")) if p.suffix.lower() in (".obj", ".off", ".ply")
    ]
    return [str(p.relative_to(SHARED / "meshes")) for p in files]


@pytest.mark.parametrize("name", _shared_mesh_files())
def test_no_cracks_in_the_shared_real_meshes(name):
    """None of the real meshes has a crack (after the reader's merge of identical positions).

    Checked with the default tolerance and ten times it; the defects of the wild meshes
    are of other kinds (non-manifold edges and vertices, zero-area faces). The coincident
    vertices found are those the reader left apart, where merging would not join a surface
    (suzanne: two vertices of a closed surface touching another sheet).
    """
    from torch_edgevf.io import read_triangles

    path = shared_path("meshes", *Path(name).parts)
    v, f, report = read_triangles(path, merge=True)
    apart = set(report.vertex_map[report.left_apart].tolist())
    for tol in (COINCIDENT_TOL, 10 * COINCIDENT_TOL):
        assert set(find_coincident_vertices(v, f, tol).ravel().tolist()) == apart
        assert find_t_junctions(v, f, tol).shape == (0, 4)
    assert repair(v, f).report.cracks == bool(apart)
    assert bool(apart) == (name == "wild/suzanne.obj")


def test_unmerged_file_has_its_seams_as_coincident_vertices(tmp_path):
    """Written by trimesh (a vertex per corner, split at the normals' seams), a mesh file's copies
    are coincident vertices: the reader's merge and repair's agree on them."""
    import trimesh

    from torch_edgevf.io import read_triangles

    src = shared_path("meshes", "spot_low_resolution.obj")
    path = tmp_path / "spot_split.obj"
    trimesh.load(src, process=False).export(path)
    v, f, _ = read_triangles(path, merge=False)
    _, _, report = read_triangles(path, merge=True)
    pairs = find_coincident_vertices(v, f, tol=0)
    assert report.merged_vertices == len(v) - 829 > 0 and len(pairs) >= report.merged_vertices
    assert report.left_apart == []
    result = repair(v, f, merge_coincident=True, tol=0)
    assert len(result.report.merged_vertices) == report.merged_vertices
    topo = result.topology
    assert (topo.num_components, topo.euler_characteristic, topo.num_boundary_edges) == (1, 2, 0)


# --------------------------------------------------------------------------- errors, scale, command line


def test_errors_name_the_problem():
    v, f = ev.meshes.grid(2, 2)
    with pytest.raises(ValueError, match=r"tol must be a number in \[0, 1\)"):
        find_coincident_vertices(v, f, tol=-1)
    with pytest.raises(ValueError, match="tol must be"):
        repair(v, f, tol=float("nan"))
    with pytest.raises(ValueError, match="merge_coincident must be True or False"):
        repair(v, f, merge_coincident="yes")
    bad = f.clone()
    bad[3, 1] = 99
    with pytest.raises(ValueError, match=r"outside \[0, 9\) at faces \[3\]"):
        find_t_junctions(v, bad)
    nan = v.clone()
    nan[2, 0] = float("nan")
    with pytest.raises(ValueError, match=r"NaN or Inf coordinates at vertices \[2\]"):
        find_coincident_vertices(nan, f)
    assert not diagnose(nan, f).ok  # never raises


@pytest.mark.slow
def test_cracks_on_a_large_mesh():
    """About 150k vertices, a crack of 317 vertex pairs and 316 T-junctions along one line."""
    n = 316
    v1, f1 = ev.meshes.grid(n // 2, n, size=(0.5, 1.0))
    v2, f2 = ev.meshes.grid(n // 2, 2 * n, size=(0.5, 1.0))
    v = np.concatenate([v1.numpy(), v2.numpy() + [0.5, 0.0, 0.0]])
    f = np.concatenate([f1.numpy(), f2.numpy() + len(v1)])
    pairs, junctions = find_coincident_vertices(v, f), find_t_junctions(v, f)
    assert (len(pairs), len(junctions)) == (n + 1, n)
    result = repair(v, f, merge_coincident=True, split_t_junctions=True)
    assert result.topology.num_boundary_edges == 2 * (n // 2 + n // 2) + n + 2 * n


def test_cli_info_and_repair_close_a_crack(tmp_path):
    from torch_edgevf.io import save_mesh

    from conftest import edgevf

    v1, f1 = ev.meshes.grid(2, 2)
    v2, f2 = ev.meshes.grid(2, 4)
    # the copies of the shared vertices 1e-9 apart: the reader's exact merge keeps them
    v = np.concatenate([v1.numpy(), v2.numpy() + [1.0 + 1e-9, 0.0, 0.0]])
    f = np.concatenate([f1.numpy(), f2.numpy() + len(v1)])
    save_mesh(tmp_path / "crack.obj", v, f)
    info = edgevf("info", tmp_path / "crack.obj")
    assert info.returncode == 1, info.stderr
    assert "3 pairs of coincident vertices" in info.stdout and "2 T-junctions" in info.stdout
    assert "what 'edgevf repair --merge-coincident --split-t-junctions' would do:" in info.stdout
    assert "1 components, Euler characteristics 1 (x1); 14 boundary edges" in info.stdout
    assert edgevf("info", tmp_path / "crack.obj", "--tol", "0").returncode == 0
    out, maps = tmp_path / "closed.obj", tmp_path / "maps.npz"
    done = edgevf(
        "repair", tmp_path / "crack.obj", out, "--merge-coincident", "--split-t-junctions", "--maps", maps
    )
    assert done.returncode == 0, done.stderr
    assert "coincident vertices merged" in done.stdout and "faces split at 2 T-junction" in done.stdout
    closed = edgevf("info", out)
    assert closed.returncode == 0 and "14 boundary edges" in closed.stdout, closed.stdout
    m = np.load(maps)
    assert len(m["merged_to"]) == len(v) and int((m["merged_to"] != np.arange(len(v))).sum()) == 3
    bad = edgevf("repair", tmp_path / "crack.obj", out, "--tol", "2")
    assert bad.returncode == 2 and "--tol" in bad.stderr
