"""A repaired file loads into the operators with the default settings.

``edgevf repair IN OUT`` writes the copies of split vertices at the positions of the
originals; the loader must not merge them back (it merges only where two boundary edges
join into one manifold edge), and the positions it writes must have no zero-area face
(caps are flipped). Checked end to end, as a user runs it: the command, ``load_mesh`` with
defaults, ``EdgeOperators`` and a smoothest field, on made-up defects and on the wild
meshes of ``../shared/meshes/wild`` (the large ones in the slow lane).
"""

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.io import load_mesh, save_mesh

from conftest import edgevf, shared_path


def edgevf_repair(src, out):
    result = edgevf("repair", src, out, timeout=600)
    assert result.returncode == 0, result.stderr
    return result.stdout


def operators_accept(path):
    """load_mesh with defaults, EdgeOperators, a smoothest 4-field; the mesh, or the error."""
    mesh = load_mesh(path)
    try:
        ops = ev.EdgeOperators(mesh.verts, mesh.faces)
    except ValueError as err:
        return mesh, str(err)
    z = ev.smoothest_field(mesh.verts, ops.topology, n=4)
    assert torch.isfinite(z).all()
    return mesh, ""


def round_trip(src, tmp_path):
    """(error before, the repaired mesh, error after) for a mesh file."""
    _, before = operators_accept(src)
    out = tmp_path / f"repaired{src.suffix}"
    summary = edgevf_repair(src, out)
    mesh, after = operators_accept(out)
    return before, mesh, after, summary


def test_split_edge_is_not_merged_back(tmp_path):
    # three triangles on one edge: repair cuts the edge, the copies are written at the
    # positions of the originals, and the loader leaves them apart
    verts = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1]], dtype=float)
    faces = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    src = tmp_path / "fan.obj"
    save_mesh(src, torch.from_numpy(verts), torch.from_numpy(faces))
    before, mesh, after, summary = round_trip(src, tmp_path)
    assert "non-manifold edges" in before and after == ""
    assert "non-manifold edges cut" in summary
    r = mesh.report
    assert r.merged_vertices == 0 and len(r.left_apart) > 0 and len(mesh.faces) == 3


@pytest.mark.parametrize("ext", ["obj", "off", "ply"])
def test_zero_area_cap_is_flipped_in_the_written_file(tmp_path, ext):
    v, f = ev.icosphere(2)
    v = v.numpy().copy()
    a, b, c = f[0].tolist()
    v[a] = 0.5 * (v[b] + v[c])  # vertex a on the opposite edge: a cap of zero area
    src = tmp_path / f"cap.{ext}"
    save_mesh(src, torch.from_numpy(v), f)
    before, mesh, after, summary = round_trip(src, tmp_path)
    assert "zero-area" in before and after == ""
    assert "zero-area caps re-triangulated" in summary
    assert torch.equal(mesh.verts, torch.from_numpy(v))  # no vertex moved


WILD = [
    pytest.param("suzanne.obj", "non-manifold edges"),
    pytest.param("teapot.obj", "non-manifold vertices"),
    pytest.param("ogre.obj", "zero-area", marks=pytest.mark.slow),
    pytest.param("beast.obj", "non-manifold edges", marks=pytest.mark.slow),
]


@pytest.mark.parametrize("name, defect", WILD)
def test_wild_mesh_repaired_file_loads_into_operators(tmp_path, name, defect):
    src = shared_path("meshes", "wild", name)
    before, mesh, after, _ = round_trip(src, tmp_path)
    assert defect in before  # the file as published is refused, naming its defect
    assert after == ""  # the repaired file is accepted with the default settings
    assert mesh.report.merged_vertices == 0  # nothing the repair split is merged back
