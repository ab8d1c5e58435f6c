"""The loader's merge of vertices at identical positions: only where two boundary edges join.

Made-up cases (a cube whose faces are apart, a crack, surfaces that touch at a vertex or
along an edge, an edge where three sheets meet, a doubled triangle), the shared meshes with
defects, an RNA mesh written as a triangle soup, and the file-to-mesh vertex maps.
"""

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.io import load_mesh, read_triangles, save_mesh
from torch_edgevf.io.merge import join_cracks, position_classes

from conftest import shared_path


def soup(verts, faces):
    """Every triangle with its own three vertices (as STL stores a mesh)."""
    v, f = np.asarray(verts, dtype=np.float64), np.asarray(faces)
    return v[f].reshape(-1, 3), np.arange(3 * len(f)).reshape(-1, 3)


def save(tmp_path, name, verts, faces):
    path = tmp_path / name
    save_mesh(path, torch.as_tensor(np.asarray(verts, dtype=np.float64)), torch.as_tensor(np.asarray(faces)))
    return path


def topology_problems(mesh) -> str:
    try:
        ev.Topology(mesh.faces, num_vertices=len(mesh.verts))
    except ValueError as err:
        return str(err)
    return ""


CUBE_V = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
CUBE_F = np.array(
    [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
     [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
)  # fmt: skip


def test_cube_with_faces_apart_is_joined(tmp_path):
    # each square side of the cube has its own four vertices: 24 vertices, 12 triangles
    faces, verts = [], []
    for side in range(6):
        tri = CUBE_F[2 * side : 2 * side + 2]
        corners = np.unique(tri)
        local = np.searchsorted(corners, tri) + 4 * side
        verts.append(CUBE_V[corners])
        faces.append(local)
    verts, faces = np.concatenate(verts), np.concatenate(faces)
    path = save(tmp_path, "cube.obj", verts, faces)
    mesh = load_mesh(path)
    r = mesh.report
    assert (len(mesh.verts), r.merged_vertices, r.joined_edges, r.left_apart) == (8, 16, 12, [])
    topo = ev.Topology(mesh.faces, num_vertices=8)
    assert (topo.euler_characteristic, topo.num_boundary_edges, topo.num_components) == (2, 0, 1)
    # every file vertex went to the mesh vertex at its position
    assert torch.equal(mesh.verts[mesh.vertex_map], torch.from_numpy(verts))
    assert torch.equal(mesh.vertex_map[mesh.vertex_origin], torch.arange(8))
    # and the mesh is the cube: operators and a field
    ops = ev.EdgeOperators(mesh.verts, mesh.faces)
    z = ev.smoothest_field(mesh.verts, ops.topology, n=4)
    assert torch.isfinite(z).all()


def test_bowtie_made_by_merging_is_left_apart(tmp_path):
    # two triangles touching at one point, each with its own vertex there
    verts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 0], [-1, 0, 0], [0, -1, 0]]
    path = save(tmp_path, "bowtie.obj", verts, [[0, 1, 2], [3, 4, 5]])
    mesh = load_mesh(path)
    r = mesh.report
    assert (len(mesh.verts), r.merged_vertices, r.joined_edges) == (6, 0, 0)
    assert r.left_apart == [0, 3] and "left 2 vertices apart" in str(r)
    assert topology_problems(mesh) == ""
    # merging them anyway (repair's merge of coincident vertices) makes the bowtie
    forced = ev.repair(np.array(verts, float), [[0, 1, 2], [3, 4, 5]], merge_coincident=True, tol=0)
    assert forced.report.non_manifold_vertices == [0]


def test_surfaces_touching_along_an_edge_are_left_apart(tmp_path):
    # two closed tetrahedra sharing the positions of one edge: both edges already have two faces
    a = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    b = np.array([[0, 0, 0], [1, 0, 0], [0, -1, 0], [0, 0, -1]], dtype=float)
    tet = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    tet_b = tet[:, ::-1] + 4  # b is a reflection: reverse its winding to keep it outward
    path = save(tmp_path, "touch.obj", np.vstack([a, b]), np.vstack([tet, tet_b]))
    mesh = load_mesh(path)
    assert (mesh.report.merged_vertices, mesh.report.left_apart) == (0, [0, 1, 4, 5])
    assert topology_problems(mesh) == ""
    old = load_mesh(path, merge=False)
    assert torch.equal(old.faces, mesh.faces)


def test_three_sheets_at_one_edge_are_left_apart(tmp_path):
    # three triangles, each with its own copy of the edge (0,0,0)-(1,0,0): ambiguous
    edge = [[0, 0, 0], [1, 0, 0]]
    verts, faces = [], []
    for k, tip in enumerate([[0, 1, 0], [0, -1, 0], [0, 0, 1]]):
        verts += edge + [tip]
        faces.append([3 * k, 3 * k + 1, 3 * k + 2])
    mesh = load_mesh(save(tmp_path, "fan.obj", verts, faces))
    r = mesh.report
    assert (r.merged_vertices, r.joined_edges) == (0, 0) and r.left_apart == [0, 1, 3, 4, 6, 7]
    assert "3 boundary edges lie three or more at one pair of positions" in str(r)


def test_two_sheets_at_one_edge_are_joined(tmp_path):
    # the same with two triangles: a crack of zero width, closed into one manifold edge
    verts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 0], [1, 0, 0], [0, -1, 0]]
    mesh = load_mesh(save(tmp_path, "crack.obj", verts, [[0, 1, 2], [4, 3, 5]]))
    assert (len(mesh.verts), mesh.report.merged_vertices, mesh.report.joined_edges) == (4, 2, 1)
    assert mesh.vertex_map.tolist() == [0, 1, 2, 0, 1, 3]


def test_doubled_triangle_is_not_folded(tmp_path):
    # the same triangle twice, with vertices of its own: joining its three edges would make
    # two faces on the same three vertices (a closed pillow of no volume)
    verts = [[0, 0, 0], [1, 0, 0], [0, 1, 0]] * 2
    mesh = load_mesh(save(tmp_path, "double.obj", verts, [[0, 1, 2], [3, 5, 4]]))
    r = mesh.report
    assert (r.merged_vertices, r.left_apart) == (0, [0, 1, 2, 3, 4, 5])
    assert "joins would make a non-manifold edge or a collapsed or duplicate face" in str(r)


def test_joins_that_make_a_non_manifold_edge_are_undone():
    # two triangles on the interior edge x-y, and a copy of the first with its own vertices:
    # its sides y-p and p-x meet the boundary sides of the first, but joining them would give
    # x-y a third face (and the copy the first one's vertices): both joins are undone
    x, y, p, q = [0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0]
    verts = np.array([x, y, p, q, x, y, p], dtype=float)
    faces = np.array([[0, 1, 2], [1, 0, 3], [4, 6, 5]])
    result = join_cracks(verts, faces)
    assert (result.merged_vertices, result.joined_edges, result.undone_joins) == (0, 0, 2)
    assert result.left_apart == [0, 1, 2, 4, 5, 6]
    # without the copy, no two used vertices share a position
    assert join_cracks(verts, faces[[0, 1]]).left_apart == []


def test_position_classes_exact():
    v = np.array([[0.0, 1, 2], [-0.0, 1, 2], [0, 1, 2 + 1e-15], [np.nan, 0, 0], [np.nan, 0, 0], [0, 1, 2]])
    pos = position_classes(v)
    assert pos.tolist() == [0, 0, 2, 3, 4, 0]  # -0.0 is 0.0, NaN rows apart, one ulp apart
    assert position_classes(np.eye(3)) is None


def test_unreferenced_file_vertices_map_to_minus_one(tmp_path):
    path = tmp_path / "m.off"
    path.write_text("OFF\n5 1 0\n0 0 0\n7 7 7\n1 0 0\n0 1 0\n8 8 8\n3 0 2 3\n")
    mesh = load_mesh(path)
    assert mesh.vertex_map.tolist() == [0, -1, 1, 2, -1] and mesh.vertex_origin.tolist() == [0, 2, 3]
    labels = np.array([10, 11, 12, 13, 14])
    assert labels[mesh.vertex_origin.numpy()].tolist() == [10, 12, 13]


# ----------------------------------------------------------------------------- real meshes


def test_rna_mesh_as_a_soup_comes_back_as_the_file_has_it(tmp_path):
    """A molecular surface written as a triangle soup is joined back to the OFF file's mesh,
    the vertices that the file keeps apart at one position kept apart again."""
    off = shared_path("datasets", "rna_sample", "off", "3CXC_9.off")
    mesh = load_mesh(off)
    assert len(mesh.report.left_apart) == 8  # the file's own vertices at shared positions
    v, f = soup(mesh.verts.numpy(), mesh.faces.numpy())
    back = load_mesh(save(tmp_path, "soup.obj", v, f))
    assert (len(back.verts), len(back.faces)) == (len(mesh.verts), len(mesh.faces))
    assert torch.equal(back.verts[back.faces], mesh.verts[mesh.faces])  # corner by corner
    # the same vertices: corner by corner, the vertices of one mesh match those of the other
    pairs = np.unique(np.stack([back.faces.numpy().ravel(), mesh.faces.numpy().ravel()], 1), axis=0)
    assert len(pairs) == len(mesh.verts)


@pytest.mark.parametrize("name", ["teapot.obj", "suzanne.obj"])
def test_wild_meshes_merge_creates_no_defect(name):
    """The merge never adds a non-manifold edge or vertex to what the file has."""
    path = shared_path("meshes", "wild", name)
    merged, apart = load_mesh(path), load_mesh(path, merge=False)
    problems = topology_problems(merged)
    if name == "suzanne.obj":  # its own non-manifold edge, and 4 vertices left apart
        assert merged.report.merged_vertices == 0 and len(merged.report.left_apart) == 4
        assert problems == topology_problems(apart) and "non-manifold edges" in problems
    else:  # the teapot's seams joined: 38 non-manifold vertices in the file, 1 left
        assert merged.report.merged_vertices == 403 and merged.report.left_apart == []
        in_file = topology_problems(apart)
        assert "non-manifold vertices" in in_file and "(38 in all)" in in_file
        assert problems == "non-manifold vertices (their faces form several fans): vertices [353]"


def test_read_triangles_merge_reports_the_map(tmp_path):
    verts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 0], [1, 0, 0], [0, -1, 0]]
    path = save(tmp_path, "crack.obj", verts, [[0, 1, 2], [4, 3, 5]])
    v, f, r = read_triangles(path, merge=True)
    assert len(v) == 4 and r.vertex_map.tolist() == [0, 1, 2, 0, 1, 3]
    assert f.tolist() == [[0, 1, 2], [1, 0, 3]]


def test_docs_snippet_carries_labels_through_load_and_repair(tmp_path, monkeypatch):
    """The example of docs/operators.md ("Per-vertex data of the file") prints the maps."""
    import contextlib
    import io
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "operators.md").read_text()
    section = text.split("### Per-vertex data of the file", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "operators.md", "exec"), {})
    lines = out.getvalue().splitlines()
    assert lines[0] == "[0, 1, 2, -1, 3, 4]"
    # the cut edge 0-1: each of its three faces keeps its own copy of both ends
    assert lines[1] == "9 [10, 10, 10, 11, 11, 11, 12, 14, 15]"
    # every file vertex in the mesh gets the mean of its copies' values; the dropped one NaN
    assert lines[2] == "[1.0, 4.0, 6.0, nan, 7.0, 8.0]"
