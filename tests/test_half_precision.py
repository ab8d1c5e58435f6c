"""Half-precision positions (float16, bfloat16) are refused at every public entry point.

Half precision cannot hold the operators (squared lengths and areas under- and overflow,
torch has no sparse complex32 kernels): each entry point that takes vertex positions
raises ``ValueError`` naming the dtype and saying to use float64 or float32, before any
work and without modifying the input.
"""

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.learning.precompute import compute_operators

V, F = ev.icosphere(1)
E = 120
Z = torch.ones(E, dtype=torch.complex64)

ENTRY_POINTS = {
    "connection_laplacian": lambda v: ev.connection_laplacian(v, F, 1),
    "mass_matrix": lambda v: ev.mass_matrix(v, F),
    "cotan_laplacian": lambda v: ev.cotan_laplacian(v, F),
    "face_geometry": lambda v: ev.face_geometry(v, F),
    "EdgeOperators": lambda v: ev.EdgeOperators(v, F),
    "repair": lambda v: ev.repair(v, F),
    "smoothest_field": lambda v: ev.smoothest_field(v, F, n=4),
    "FieldDesigner": lambda v: ev.FieldDesigner(v, F, 4),
    "curvature_aligned_field": lambda v: ev.curvature_aligned_field(v, F, n=4),
    "singularities": lambda v: ev.singularities(v, F, Z, n=1),
    "compute_operators": lambda v: compute_operators(v, F),
}


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
@pytest.mark.parametrize("name", sorted(ENTRY_POINTS))
def test_half_precision_vertices_get_a_value_error(name, dtype):
    verts = V.to(dtype)
    before = verts.clone()
    with pytest.raises(ValueError, match=rf"verts has dtype {dtype}.*float64 \(recommended\) or float32"):
        ENTRY_POINTS[name](verts)
    assert torch.equal(verts, before)


@pytest.mark.parametrize("name", ["connection_laplacian", "EdgeOperators", "repair", "smoothest_field"])
def test_numpy_float16_vertices_get_a_value_error(name):
    with pytest.raises(ValueError, match=r"verts has dtype float16.*astype\(numpy.float64\)"):
        ENTRY_POINTS[name](V.numpy().astype(np.float16))


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
def test_half_precision_files(tmp_path, dtype):
    with pytest.raises(ValueError, match=rf"cannot save mesh .*m.obj: verts has dtype {dtype}"):
        ev.save_mesh(tmp_path / "m.obj", V.to(dtype), F)
    with pytest.raises(ValueError, match=rf"cannot save field .*f.npz: verts has dtype {dtype}"):
        ev.save_field(tmp_path / "f.npz", V.to(dtype), F, Z)
    ev.save_mesh(tmp_path / "ok.obj", V, F)
    with pytest.raises(ValueError, match=rf"load_mesh: dtype is {dtype}, which is not supported"):
        ev.load_mesh(tmp_path / "ok.obj", dtype=dtype)


def test_half_precision_field_file_is_refused(tmp_path):
    """A field file written elsewhere with float16 positions."""
    ev.save_field(tmp_path / "f.npz", V, F, Z.to(torch.complex128), n=1)
    with np.load(tmp_path / "f.npz") as data:
        arrays = {k: data[k] for k in data.files}
    arrays["verts"] = arrays["verts"].astype(np.float16)
    np.savez(tmp_path / "half.npz", **arrays)
    with pytest.raises(ValueError, match=r"cannot load field .*half.npz: verts has dtype float16"):
        ev.load_field(tmp_path / "half.npz")


def test_half_precision_lengths_get_a_value_error():
    lengths = ev.face_geometry(V, F).lengths
    with pytest.raises(ValueError, match="lengths has dtype torch.float16"):
        ev.FaceGeometry.from_lengths(lengths.half())


def test_float32_and_float64_still_work():
    for dtype, cdtype in ((torch.float32, torch.complex64), (torch.float64, torch.complex128)):
        ops = ev.EdgeOperators(V.to(dtype), F)
        assert ops.connection_laplacian.dtype == cdtype
        assert ev.repair(V.to(dtype), F).verts.dtype == dtype
