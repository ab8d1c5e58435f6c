"""The default cross field of quad_mesh: curvature where it has a direction, smoothest elsewhere."""

import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.fields.design import FieldDesigner
from torch_edgevf.quad.field import anisotropy_weight, curvature_anisotropy, curvature_guide
from torch_edgevf.quad.mesh import quad_mesh, quad_mesh_report


def test_the_curvature_of_a_sphere_has_no_direction():
    v, f = ev.meshes.icosphere(level=3)
    designer = FieldDesigner(v, f, n=4)
    r = curvature_anisotropy(designer)
    assert r.shape == (designer.num_edges,)
    assert float(r.max()) < 0.02  # the discretization's noise only
    assert not bool(anisotropy_weight(r).any())
    assert curvature_guide(designer) is None


def test_the_curvature_of_a_torus_has_a_direction():
    import trimesh

    m = trimesh.creation.torus(1.0, 0.4, major_sections=40, minor_sections=16)
    designer = FieldDesigner(torch.tensor(m.vertices), torch.tensor(m.faces, dtype=torch.int64), n=4)
    r = curvature_anisotropy(designer)
    # k1 = 1/0.4, k2 = cos(t)/(1 + 0.4 cos(t)) in [-0.71, 1/1.4]: r = |k1 - k2| / (|k1| + |k2|) > 0.55
    assert float(r.min()) > 0.5 and float(r.max()) <= 1.0
    assert bool((anisotropy_weight(r) == 1).all())
    guide = curvature_guide(designer)
    assert torch.allclose(guide, designer.curvature())  # the curvature only: anisotropic everywhere


def test_umbilic_regions_follow_the_smoothest_field():
    import trimesh

    m = trimesh.creation.capsule(height=1.2, radius=0.5, count=[14, 14])
    v, f = torch.tensor(m.vertices), torch.tensor(m.faces, dtype=torch.int64)
    designer = FieldDesigner(v, f, n=4)
    a = anisotropy_weight(curvature_anisotropy(designer))
    poles = a == 0
    assert bool(poles.any()) and bool((a == 1).any())  # umbilic caps, anisotropic cylinder
    guide = curvature_guide(designer)
    smooth = designer.smoothest()
    turn = guide[poles] / smooth[poles]  # one phase there: the smoothest field's directions
    assert float((turn / turn.abs()).std()) < 1e-9


def test_anisotropy_weight_is_a_smooth_step():
    r = torch.tensor([0.0, 0.1, 0.2, 0.3, 0.5, 1.0], dtype=torch.float64)
    assert anisotropy_weight(r).tolist() == pytest.approx([0, 0, 0.5, 1, 1, 1])
    with pytest.raises(ValueError, match="low < high"):
        anisotropy_weight(r, 0.2, 0.1)


def test_the_default_quad_mesh_of_a_sphere_has_the_eight_cones_of_the_smoothest_field():
    v, f = ev.meshes.icosphere(level=3)
    q = quad_mesh(v, f)
    r = quad_mesh_report(q.verts, q.quads)
    assert len(r.irregular) == 8 and q.cone_index.tolist() == [0.25] * 8
    smooth = quad_mesh(v, f, field="smoothest")
    assert torch.equal(q.quads, smooth.quads)


def test_a_flat_mesh_keeps_no_curvature_guide():
    v, f = ev.meshes.grid(4, 4)
    designer = FieldDesigner(v, f, n=4)
    r = curvature_anisotropy(designer)
    assert bool(torch.isfinite(r).all()) and float(r.abs().max()) == 0.0
    assert curvature_guide(designer) is None
