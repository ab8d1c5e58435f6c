"""Polygons triangulated in their planes: concave ones by ear clipping, with their winding."""

import math

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.mesh.repair import triangulate

# an L-shaped hexagon starting at a corner that does not see the whole polygon
L_HEXAGON = [(2, 0), (2, 1), (1, 1), (1, 2), (0, 2), (0, 0)]
# a U-shaped octagon starting at a reflex corner at the bottom of the notch
U_OCTAGON = [(2, 1), (1, 1), (1, 2), (0, 2), (0, 0), (3, 0), (3, 2), (2, 2)]
# a four-pointed star: tips at radius 1, reflex corners at radius 0.4
STAR_OCTAGON = [
    (
        (1.0 if i % 2 == 0 else 0.4) * math.cos(i * math.pi / 4),
        (1.0 if i % 2 == 0 else 0.4) * math.sin(i * math.pi / 4),
    )
    for i in range(8)
]
CONVEX_PENTAGON = [(0, 0), (2, 0), (2.5, 1.5), (1, 2.5), (-0.5, 1.2)]
# an arrowhead (dart) starting at a convex corner, lifted out of its plane
DART = [(-1, 1, 0.1), (0, -1, -0.2), (1, 1, 0.15), (0, 0.2, -0.1)]
SKEW_QUAD = [(0, 0, 0), (1, 0, 0.3), (1, 1, 0), (0, 1, 0.25)]

CONCAVE = {"L hexagon": L_HEXAGON, "U octagon": U_OCTAGON, "star octagon": STAR_OCTAGON}
POLYGONS = {**CONCAVE, "convex pentagon": CONVEX_PENTAGON, "non-planar dart": DART, "skew quad": SKEW_QUAD}


def _points(corners) -> np.ndarray:
    p = np.array(corners, dtype=np.float64)
    return np.column_stack([p, np.zeros(len(p))]) if p.shape[1] == 2 else p


def _rotation(seed: int) -> np.ndarray:
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def _newell(p: np.ndarray) -> np.ndarray:
    """Twice the vector area of a polygon."""
    return np.cross(p, np.roll(p, -1, axis=0)).sum(0)


def _check_triangulation(p: np.ndarray, tri: np.ndarray, planar: bool):
    """``tri`` triangulates the polygon of corners ``p`` (in order) with its winding."""
    k = len(p)
    assert tri.shape == (k - 2, 3)
    normal = _newell(p)
    unit = normal / np.linalg.norm(normal)
    doubled = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
    in_plane = doubled @ unit
    # every triangle turns as the polygon does, with more than a sliver of its area
    assert in_plane.min() > 1e-3 * np.linalg.norm(normal), in_plane
    # the triangles cover the polygon once: areas in the plane add up to its area
    assert in_plane.sum() == pytest.approx(np.linalg.norm(normal), rel=1e-12)
    if planar:
        assert np.linalg.norm(doubled, axis=1).sum() == pytest.approx(np.linalg.norm(normal), rel=1e-12)
    # each side is a half-edge of one triangle, in the polygon's direction; every other
    # edge is a diagonal, shared by two triangles in opposite directions
    half = {}
    for t in tri.tolist():
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            half[(a, b)] = half.get((a, b), 0) + 1
    assert max(half.values()) == 1
    sides = {(i, (i + 1) % k) for i in range(k)}
    assert sides <= set(half)
    for a, b in set(half) - sides:
        assert (b, a) in half and (b, a) not in sides
    assert len(set(half) - sides) == 2 * (k - 3)


def _flips(p: np.ndarray, tri) -> bool:
    """Whether a triangle of ``tri`` is against the polygon's normal (or has no area)."""
    normal = _newell(p)
    return any(np.cross(p[b] - p[a], p[c] - p[a]) @ normal <= 0 for a, b, c in np.asarray(tri).tolist())


@pytest.mark.parametrize("name", list(POLYGONS))
@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("reverse", [False, True])
def test_polygon_triangulated_in_its_plane(name, seed, reverse):
    p = _points(POLYGONS[name])
    if reverse:
        p = p[::-1].copy()
    p = p @ _rotation(seed).T + np.array([3.0, -1.0, 2.0])
    k = len(p)
    perm = np.random.default_rng(seed).permutation(k + 3)  # the corners anywhere among other vertices
    verts = np.zeros((k + 3, 3))
    verts[perm[:k]] = p
    verts[perm[k:]] = np.nan  # unreferenced vertices are not looked at
    face = perm[:k]
    tri, origin, report = triangulate([face], k + 3, verts=verts)
    assert origin.tolist() == [0] * (k - 2)
    assert report.triangulated_faces == [0] and report.added_triangles == k - 3
    assert report.fan_faces == []
    local = np.argsort(perm)[tri]  # triangles of corner positions 0..k-1
    _check_triangulation(p, local, planar=name not in ("non-planar dart", "skew quad"))


@pytest.mark.parametrize("name", [*CONCAVE, "non-planar dart"])
def test_the_fan_of_these_polygons_would_flip_a_triangle(name):
    """The cases above are ones the fan from the first corner gets wrong, and ear clipping not."""
    p = _points(POLYGONS[name])
    k = len(p)
    fan = np.stack([np.zeros(k - 2, int), np.arange(1, k - 1), np.arange(2, k)], 1)
    assert _flips(p, fan)
    tri, _, _ = triangulate([np.arange(k)], k, verts=p)
    assert not _flips(p, tri)


def test_reflex_first_corner_fan_is_flipped_ear_clipping_is_not():
    p = _points(U_OCTAGON)
    fan, _, _ = triangulate([np.arange(8)], 8)  # without positions: the fan
    assert _flips(p, fan)
    tri, _, report = triangulate([np.arange(8)], 8, verts=p)
    assert not _flips(p, tri)
    assert report.fan_faces == []


def test_convex_polygons_keep_the_fan():
    p = _points(CONVEX_PENTAGON)
    tri, _, _ = triangulate(np.arange(5)[None], 5, verts=torch.from_numpy(p))
    assert tri.tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 4]]
    tri, _, _ = triangulate(np.arange(4)[None], 4, verts=_points(SKEW_QUAD))
    assert tri.tolist() == [[0, 1, 2], [0, 2, 3]]


def test_collinear_corners_give_no_zero_area_triangle():
    # a square with a corner in the middle of a side: the fan from corner 0 has a zero-area triangle
    p = _points([(0, 0), (1, 0), (2, 0), (2, 2), (0, 2)])
    tri, _, report = triangulate([np.arange(5)], 5, verts=p)
    _check_triangulation(p, tri, planar=True)
    assert report.fan_faces == []


def test_polygons_without_a_plane_or_crossing_sides_keep_the_fan_and_are_named():
    star = _points([(math.cos(a), math.sin(a)) for a in np.arange(5) * 4 * math.pi / 5])  # a pentagram
    bowtie = _points([(0, 0), (3, 0), (0, 1), (1, 2)])  # sides 1-2 and 3-0 cross
    line = _points([(0, 0), (1, 0), (2, 0), (3, 0)])
    # turning once counter-clockwise, but a corner on the opposite side / sides crossing twice
    touching = _points([(0, 0), (4, 0), (4, 2), (2.5, 2), (2, 0), (1.5, 2), (0, 2)])
    crossing = _points([(2, 0), (3, 2), (4, 2), (1, 0), (2, 3), (3, 4)])
    v = np.concatenate([star, bowtie, line, touching, crossing])
    faces = [np.arange(5), 5 + np.arange(4), 9 + np.arange(4), 13 + np.arange(7), 20 + np.arange(6)]
    tri, origin, report = triangulate(faces, len(v), verts=v)
    assert report.fan_faces == [0, 1, 2, 3, 4]
    assert tri[origin == 0].tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 4]]
    assert tri[origin == 4].tolist() == [[20, 21, 22], [20, 22, 23], [20, 23, 24], [20, 24, 25]]
    r = ev.repair(v, faces)
    assert r.report.fan_faces == [0, 1, 2, 3, 4]
    assert r.report.changes()["polygons split into fans"] == 5
    assert "split into fans from their first corner, faces: 5 [0, 1, 2, 3, 4]" in r.report.summary()


def test_repeated_indices_then_ear_clipping():
    p = _points(L_HEXAGON)
    face = [0, 1, 1, 2, 3, 4, 5, 5, 0]
    tri, _, report = triangulate([face], 6, verts=p)
    assert report.repeated_index_faces == [0] and report.triangulated_faces == [0]
    _check_triangulation(p, tri, planar=True)


def test_verts_must_match_the_vertex_count():
    with pytest.raises(ValueError, match=r"verts must be a \(4, 3\) float array"):
        triangulate([[0, 1, 2, 3]], 4, verts=np.zeros((3, 3)))


def _prism(corners, height=1.0):
    """A closed prism over a polygon (counter-clockwise seen from +z): polygons, outward."""
    p = _points(corners)
    k = len(p)
    verts = np.concatenate([p, p + [0, 0, height]])
    faces = [list(range(k))[::-1], list(range(k, 2 * k))]
    faces += [[i, (i + 1) % k, k + (i + 1) % k, k + i] for i in range(k)]
    return verts, faces


@pytest.mark.parametrize("name", list(CONCAVE))
def test_repaired_prism_has_the_true_surface_and_angle_defects(name):
    corners = np.array(POLYGONS[name], dtype=np.float64)
    verts, faces = _prism(corners)
    k = len(corners)
    r = ev.repair(verts, faces)
    rep = r.report
    assert rep.flipped_faces == [] and rep.fan_faces == [] and not r.mollified
    assert rep.triangulated_faces == list(range(k + 2))
    assert [c["euler"] for c in rep.components] == [2]
    v = r.verts
    topo = r.topology
    # outward triangles: the vector area of each cap is that of its polygon
    area = ev.face_areas(v, r.faces)
    side = np.linalg.norm(np.roll(corners, -1, 0) - corners, axis=1).sum()
    polygon_area = abs(_newell(_points(corners))[2]) / 2
    assert float(area.sum()) == pytest.approx(2 * polygon_area + side, rel=1e-12)
    normals = torch.cross(v[r.faces[:, 1]] - v[r.faces[:, 0]], v[r.faces[:, 2]] - v[r.faces[:, 0]], dim=1)
    origin = r.face_origin
    assert (normals[origin == 0, 2] < 0).all() and (normals[origin == 1, 2] > 0).all()
    # the angle defect of a prism corner is pi minus the polygon's interior angle there
    e_in = corners - np.roll(corners, 1, 0)
    e_out = np.roll(corners, -1, 0) - corners
    turn = np.arctan2(e_in[:, 0] * e_out[:, 1] - e_in[:, 1] * e_out[:, 0], (e_in * e_out).sum(1))
    interior = math.pi - turn
    defects = ev.angle_defects(v, topo).numpy()
    expected = np.tile(math.pi - interior, 2)[r.vertex_origin.numpy()]
    np.testing.assert_allclose(defects, expected, atol=1e-12)
    # the operators accept it: finite, Hermitian, positive semi-definite
    lc = ev.connection_laplacian(v, topo, n=1).to_dense()
    m = ev.mass_matrix(v, topo).to_dense()
    assert torch.isfinite(lc).all() and torch.allclose(lc, lc.conj().T, atol=1e-12)
    assert float(torch.linalg.eigvalsh(lc).min()) > -1e-8 * float(lc.abs().max())
    assert float(m.diagonal().min()) > 0


def test_off_reader_triangulates_a_concave_polygon(tmp_path):
    corners = U_OCTAGON
    lines = ["OFF", "9 2 0"] + [f"{x} {y} 0" for x, y in corners] + ["1 -1 0"]
    lines += ["8 " + " ".join(map(str, range(8))), "3 4 8 5"]  # the U and a triangle below it
    path = tmp_path / "u.off"
    path.write_text("\n".join(lines) + "\n")
    mesh = ev.load_mesh(path)
    rep = mesh.report
    assert rep.triangulated_faces == [0] and mesh.faces.shape == (7, 3)
    assert "polygons split into triangles in their planes" in str(rep)
    p = mesh.verts.numpy()
    f = mesh.faces.numpy()
    normal_z = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])[:, 2]
    assert (normal_z > 0).all()  # the file's polygons run counter-clockwise, and so do their triangles
    area = 0.5 * normal_z.sum()
    assert area == pytest.approx(3 * 2 - 1 + 1.5)
    ev.Topology(mesh.faces)  # manifold, oriented


def test_off_reader_names_polygons_that_keep_the_fan(tmp_path):
    star = [(math.cos(a), math.sin(a)) for a in np.arange(5) * 4 * math.pi / 5]
    lines = ["OFF", "5 1 0"] + [f"{x!r} {y!r} 0" for x, y in star] + ["5 0 1 2 3 4"]
    path = tmp_path / "pentagram.off"
    path.write_text("\n".join(lines) + "\n")
    _, faces, rep = ev.io.read_triangles(path)
    assert faces.shape == (3, 3)
    assert any("split into fans from their first corner: file faces [0]" in n for n in rep.notes)
