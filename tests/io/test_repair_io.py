"""Reading what real files hold, ``edgevf info`` on broken files and ``edgevf repair``."""

import numpy as np
import pytest

import torch_edgevf as ev
from torch_edgevf.cli import main
from torch_edgevf.io import read_triangles

WRAPPED_OFF = """OFF
# a quad-dominant file whose records wrap over several lines
6 3 0
0 0 0  1 0 0
1 1 0
0 1 0
2 0 0 2 1 0
4 0 1
  2 3
4 1 4 5 2 255 0 0
3 0 0 1
"""

STRIPS_PLY = """ply
format ascii 1.0
element vertex 6
property float x
property float y
property float z
element tristrips 1
property list int int vertex_indices
end_header
0 0 0
1 0 0
0 1 0
1 1 0
0 2 0
1 2 0
8 0 1 2 3 -1 2 3 4
"""


def test_off_records_over_several_lines_quads_and_colours(tmp_path):
    path = tmp_path / "wrapped.off"
    path.write_text(WRAPPED_OFF)
    mesh = ev.load_mesh(path)
    assert mesh.verts.shape == (6, 3) and mesh.faces.shape == (4, 3)
    rep = mesh.report
    assert rep.triangulated_faces == [0, 1]
    assert rep.repeated_index_faces == [2] and rep.degenerate_faces == 1
    assert any("repeated vertex index" in p for p in rep.problems)
    assert "repeated vertex index" in str(rep)


def test_ply_triangle_strips(tmp_path):
    path = tmp_path / "strips.ply"
    path.write_text(STRIPS_PLY)
    verts, faces, report = read_triangles(path)
    assert faces.tolist() == [[0, 1, 2], [2, 1, 3], [2, 3, 4]]
    mesh = ev.load_mesh(path)
    ev.Topology(mesh.faces)  # consistently oriented


def test_repeated_index_is_reported_not_silent(tmp_path):
    v, f = ev.icosphere(1)
    f = f.numpy().copy()
    f[7] = [f[7, 0], f[7, 0], f[7, 1]]
    path = tmp_path / "hole.obj"
    ev.save_mesh(path, v, np.abs(f))
    mesh = ev.load_mesh(path)
    assert mesh.report.repeated_index_faces == [7]
    assert mesh.report.problems


def test_info_lists_every_problem_of_a_rejected_file(tmp_path, capsys):
    v, f = ev.icosphere(1)
    v, f = v.numpy().copy(), f.numpy().copy()
    f[:4] = f[:4][:, ::-1]  # inconsistent orientation
    f = np.concatenate([f, f[10:11]])  # a duplicate face
    path = tmp_path / "broken.obj"
    ev.save_mesh(path, v, f)
    lines = path.read_text().splitlines()
    lines[3] = "v nan 0 0"  # the fourth vertex record
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=r"not finite \(NaN or Inf coordinates\), at vertices \[3\]"):
        ev.load_mesh(path)
    assert main(["info", str(path)]) == 1
    out = capsys.readouterr().out
    assert "file vertices [3]" in out
    assert "inconsistent orientation" in out
    assert "duplicate faces" in out
    assert "what 'edgevf repair' would do" in out


def test_info_reports_orientation_beside_non_manifold_edges(tmp_path, capsys):
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1], [2, 0.5, 0]], dtype=float)
    f = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [1, 5, 2], [2, 1, 5][::-1]])
    f = f[:4]
    f[3] = f[3][::-1]  # against face 0 across edge (1, 2)
    path = tmp_path / "fin.obj"
    ev.save_mesh(path, v, f)
    assert main(["info", str(path)]) == 1
    out = capsys.readouterr().out
    assert "non-manifold edges" in out and "inconsistent orientation" in out


def test_cli_repair_writes_a_valid_mesh(tmp_path, capsys):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], dtype=float)
    f = np.array([[0, 1, 2], [0, 3, 4]])
    src, out, maps = tmp_path / "bowtie.obj", tmp_path / "fixed.obj", tmp_path / "maps.npz"
    ev.save_mesh(src, v, f)
    assert main(["repair", str(src), str(out), "--maps", str(maps)]) == 0
    assert "non-manifold vertices" in capsys.readouterr().out
    mesh = ev.load_mesh(out, merge=False)
    ev.Topology(mesh.faces, num_vertices=mesh.verts.shape[0])
    with np.load(maps) as data:
        assert sorted(data["vertex_origin"].tolist()) == [0, 0, 1, 2, 3, 4]
