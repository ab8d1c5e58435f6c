"""Geometry: angles, areas, defects, dihedral angles, transport; bad input; gradients."""

import math
import platform
import sys

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.mesh.geometry import FaceGeometry, face_geometry

from conftest import perturbed_icosphere


def test_angles_sum_to_pi_and_match_lengths(closed_mesh):
    v, f = closed_mesh
    g = face_geometry(v, f)
    torch.testing.assert_close(g.angles.sum(1), torch.full((f.shape[0],), math.pi, dtype=v.dtype))
    # law of cosines from lengths only
    intrinsic = FaceGeometry.from_lengths(g.lengths)
    torch.testing.assert_close(intrinsic.double_area, g.double_area)
    torch.testing.assert_close(intrinsic.dots, g.dots)


def test_single_right_triangle_by_hand():
    v = torch.tensor([[0.0, 0, 0], [2.0, 0, 0], [0, 1.0, 0]], dtype=torch.float64)
    f = torch.tensor([[0, 1, 2]])
    g = face_geometry(v, f)
    torch.testing.assert_close(g.lengths[0], torch.tensor([5**0.5, 1.0, 2.0], dtype=v.dtype))
    torch.testing.assert_close(g.area, torch.tensor([1.0], dtype=v.dtype))
    torch.testing.assert_close(g.angles[0, 0], torch.tensor(math.pi / 2, dtype=v.dtype))
    torch.testing.assert_close(g.angles[0, 1], torch.tensor(math.atan(0.5), dtype=v.dtype))
    r = ev.transport_coefficients(v, f)[0]
    # edge opposite corner 0 runs 1 -> 2 (delta=+1), opposite corner 1 runs 2 -> 0 (delta=-1):
    # frames X_0 = (-2, 1)/sqrt5 and X_1 = (0, 1) (from 0 to 2);
    # X_0 = e^{i(pi/2 + alpha_1)}... in X_1's frame:
    x0 = complex(-2, 1) / 5**0.5
    x1 = complex(0, 1)
    assert abs(complex(r[0, 1]) - x0 / x1) < 1e-14  # coefficient c in X_0 is c*x0/x1 in X_1
    assert torch.allclose(r.conj().transpose(0, 1), r)  # r_ba = conj(r_ab)
    assert torch.allclose(torch.diagonal(r), torch.ones(3, dtype=r.dtype))


def test_transport_is_consistent_with_frames(closed_mesh):
    """r_ab u_b-frame relation checked against explicit 3D edge directions on every face."""
    v, f = closed_mesh
    t = ev.Topology(f)
    r = ev.transport_coefficients(v, t).numpy()
    e = t.edges.numpy()
    X = v.numpy()[e[:, 1]] - v.numpy()[e[:, 0]]
    X /= np.linalg.norm(X, axis=1, keepdims=True)
    n = ev.face_normals(v, f).numpy()
    fe = t.face_edges.numpy()
    for a in range(3):
        for b in range(3):
            xa, xb = X[fe[:, a]], X[fe[:, b]]
            # complex coordinate of X_a in the frame (X_b, n x X_b)
            c = (xa * xb).sum(1) + 1j * (xa * np.cross(n, xb)).sum(1)
            np.testing.assert_allclose(r[:, a, b], c, atol=1e-12)


def test_gauss_bonnet_and_boundary_defects():
    v, f = perturbed_icosphere(2, 0.05)
    assert abs(float(ev.angle_defects(v, f).sum()) - 4 * math.pi) < 1e-10
    v, f = ev.meshes.grid(4, 4)
    d = ev.angle_defects(v, f)
    t = ev.Topology(f)
    assert d[~t.boundary_vertices].abs().max() < 1e-12
    # corners of the square turn by pi/2, other boundary vertices are straight
    assert abs(float(d.sum()) - 2 * math.pi) < 1e-12


def test_dihedral_angles_sign_and_value():
    v, f = ev.icosphere(0)
    beta = ev.dihedral_angles(v, f)
    expected = math.pi - math.acos(-(5**0.5) / 3)  # exterior dihedral of the icosahedron
    torch.testing.assert_close(beta, torch.full_like(beta, expected))
    # flip the sphere inside out: every edge becomes concave
    beta_in = ev.dihedral_angles(v, f[:, [0, 2, 1]])
    torch.testing.assert_close(beta_in, -beta)
    vg, fg = ev.meshes.grid(2, 2)
    assert ev.dihedral_angles(vg, fg).abs().max() == 0


def test_vertex_normals_point_outward_on_sphere():
    v, f = ev.icosphere(2)
    n = ev.vertex_normals(v, f)
    assert float((n * v).sum(1).min()) > 0.99


def test_nan_and_inf_vertices_named():
    v, f = ev.icosphere(1)
    v = v.clone()
    v[3, 1] = float("nan")
    v[7, 0] = float("inf")
    with pytest.raises(ValueError, match=r"NaN or Inf coordinates at vertices \[3, 7\]"):
        ev.face_areas(v, f)


def test_zero_area_faces_named():
    v = torch.tensor([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], dtype=torch.float64)
    f = torch.tensor([[0, 1, 3], [0, 2, 1]])
    with pytest.raises(ValueError, match=r"zero-area \(degenerate\) faces at faces \[1\]"):
        ev.EdgeOperators(v, f)
    with pytest.raises(ValueError, match="triangle inequality"):
        FaceGeometry.from_lengths(torch.tensor([[1.0, 1.0, 2.0]], dtype=torch.float64))


def test_bad_vertex_inputs():
    f = torch.tensor([[0, 1, 2]])
    with pytest.raises(ValueError, match="floating dtype"):
        ev.face_areas(torch.zeros(3, 3, dtype=torch.int64), f)
    with pytest.raises(ValueError, match=r"shape \(V, 3\)"):
        ev.face_areas(torch.zeros(3, 4), f)
    with pytest.raises(ValueError, match="verts has 3 rows but the topology was built for 4"):
        ev.edge_lengths(torch.eye(3, dtype=torch.float64), ev.Topology(f, num_vertices=4))


def test_planar_input_and_float32_follow():
    v, f = ev.meshes.grid(2, 2, dtype=torch.float32)
    a2 = ev.face_areas(v[:, :2], f)
    assert a2.dtype == torch.float32
    torch.testing.assert_close(a2.sum(), torch.tensor(1.0))


def test_geometry_gradcheck(gradcheck):
    v, f = perturbed_icosphere(0, 0.1, seed=3)
    v = v.requires_grad_()
    t = ev.Topology(f)
    for fn in (
        lambda x: ev.face_areas(x, f),
        lambda x: ev.corner_angles(x, f),
        lambda x: ev.dihedral_angles(x, t),
        lambda x: ev.angle_defects(x, t),
        lambda x: torch.view_as_real(ev.transport_coefficients(x, t, n=3)),
    ):
        assert gradcheck(fn, (v,))


def test_geometry_reuse_sees_every_change_of_positions():
    """Without autograd the last face geometry of a topology is reused only for equal positions.

    In-place edits through a NumPy view do not bump torch's version counter, so the cache
    must compare values: every such edit has to give new operators.
    """
    v, f = ev.icosphere(2)
    topo = ev.Topology(f)
    first = ev.mass_matrix(v, topo).values().clone()
    assert torch.equal(ev.mass_matrix(v, topo).values(), first)  # reuse gives the same values
    v.numpy()[:] *= 2.0  # in place, behind torch's back
    assert torch.allclose(ev.mass_matrix(v, topo).values(), 4 * first)
    v.mul_(0.5)  # in place, through torch
    assert torch.allclose(ev.mass_matrix(v, topo).values(), first)
    assert torch.allclose(ev.mass_matrix(v.float(), topo).values().double(), first, rtol=1e-6)


def test_geometry_reuse_never_shares_an_autograd_graph():
    """Two differentiable assemblies from the same positions can be back-propagated separately."""
    v, f = ev.icosphere(1)
    v = v.clone().requires_grad_()
    topo = ev.Topology(f)
    ev.connection_laplacian(v, topo, 1).values().abs().sum().backward()
    g1 = v.grad.clone()
    v.grad = None
    ev.connection_laplacian(v, topo, 1).values().abs().sum().backward()  # would fail on a freed graph
    assert torch.equal(v.grad, g1)
    with torch.no_grad():
        m = ev.mass_matrix(v, topo)
    assert m.values().grad_fn is None
    assert ev.mass_matrix(v, topo).values().grad_fn is not None


def test_tune_allocator_validates_and_reports():
    with pytest.raises(ValueError, match="keep_bytes"):
        ev.tune_allocator(keep_bytes=-1)
    with pytest.raises(ValueError, match="top_pad"):
        ev.tune_allocator(top_pad=2**40)
    applied = ev.tune_allocator()
    assert isinstance(applied, bool)
    if sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc":
        assert applied
