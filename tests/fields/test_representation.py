"""Evaluation and conversion of edge fields (torch_edgevf.fields)."""

import math

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf import fields as F
from torch_edgevf.mesh.topology import Topology

from conftest import perturbed_grid, perturbed_icosphere

C128 = torch.complex128


def planar_field(v, topo, fn):
    """Edge values of the planar vector field ``fn(p) -> (P, 3)`` at edge midpoints."""
    e = topo.edges
    mid = (v[e[:, 0]] + v[e[:, 1]]) / 2
    return ev.edges_from_vectors(v, topo, fn(mid))


def random_points(topo, num, seed=0, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    face = torch.randint(0, topo.num_faces, (num,), generator=g)
    b = -torch.log(torch.rand(num, 3, generator=g, dtype=dtype))
    return face, b / b.sum(1, keepdim=True)


def gradient_field(v, topo, fn):
    """``z = M_z^{-1} G f``: the edge field of the gradient of the vertex function ``f``."""
    g = ev.gradient(v, topo)
    m = ev.mass_matrix(v, topo).values()
    return (g @ fn.to(C128)) / m


def tangent_part(p, vec):
    n = p / p.norm(dim=1, keepdim=True)
    return vec - (vec * n).sum(1, keepdim=True) * n


# --------------------------------------------------------------------------- powers


def test_nth_power_preserves_norm_and_multiplies_angle():
    u = torch.polar(
        torch.tensor([0.5, 2.0, 3.0], dtype=torch.float64),
        torch.tensor([0.3, -1.0, 2.5], dtype=torch.float64),
    )
    for n in (1, 2, 3, 4):
        z = F.nth_power(u, n)
        assert torch.allclose(z.abs(), u.abs())
        assert torch.allclose(z, u.abs() * torch.exp(1j * n * torch.angle(u)))
        r = F.nth_root(z, n)
        assert torch.allclose(F.nth_power(r, n), z)
        roots = F.nth_roots(z, n)
        assert roots.shape == (3, n)
        assert torch.allclose(F.nth_power(roots, n), z[:, None].expand(-1, n))
        # the n roots are one root turned by 2 pi k / n
        turn = torch.exp(2j * math.pi * torch.arange(n, dtype=torch.float64) / n)
        assert torch.allclose(roots, roots[:, :1] * turn)
    assert F.nth_power(torch.zeros(2, dtype=C128), 3).abs().max() == 0


def test_nth_power_bad_n():
    with pytest.raises(ValueError, match="n must be an integer >= 1"):
        F.nth_power(torch.ones(2, dtype=C128), 0)
    with pytest.raises(ValueError, match="n must be an integer >= 1"):
        F.nth_root(torch.ones(2, dtype=C128), 1.5)


# --------------------------------------------------------------------------- planar exactness


@pytest.mark.parametrize("flat_noise", [False, True])
def test_linear_field_interpolates_exactly_on_a_plane(flat_noise):
    """The Crouzeix-Raviart interpolation reproduces constant and linear fields exactly."""
    if flat_noise:
        v, f = perturbed_grid(5, 0.1, seed=3, flat=True)
    else:
        v, f = ev.meshes.grid(5, 4)
    topo = Topology(f, v.shape[0])
    const = torch.tensor([0.3, -0.7, 0.0], dtype=torch.float64)
    amat = torch.tensor([[0.5, -1.0, 0.0], [2.0, 0.25, 0.0], [0.0, 0.0, 0.0]], dtype=torch.float64)

    def linear(p):
        return p @ amat.T + const

    for fn in (lambda p: const.expand(p.shape[0], 3), linear):
        z = planar_field(v, topo, fn)
        face, bary = random_points(topo, 200)
        p = (bary[:, :, None] * v[f[face]]).sum(1)
        assert torch.allclose(F.point_vectors(v, topo, z, face, bary), fn(p), atol=1e-12)
        centroid = v[f].mean(1)
        assert torch.allclose(F.face_vectors(v, topo, z), fn(centroid), atol=1e-12)
        assert torch.allclose(
            F.edge_vectors(v, topo, z), fn((v[topo.edges[:, 0]] + v[topo.edges[:, 1]]) / 2), atol=1e-12
        )
    # a constant field is exact at vertices too (flat: no angle defect, no rescaling)
    z = planar_field(v, topo, lambda p: const.expand(p.shape[0], 3))
    assert torch.allclose(F.vertex_vectors(v, topo, z), const.expand(v.shape[0], 3), atol=1e-12)
    assert torch.allclose(F.vertices_to_edges(v, topo, F.edges_to_vertices(v, topo, z)), z, atol=1e-12)


def test_integral_property_gauss_quadrature():
    """(3.2): int_{e_i} psi_i = |e_i| X_i and int_{e_j} psi_i = 0 for the two other edges."""
    v, f = perturbed_grid(2, 0.3, seed=4)
    topo = Topology(f, v.shape[0])
    x_edge, _, _ = F.edge_frames(v, topo)
    # 2-point Gauss-Legendre on [0, 1]: exact for the linear psi_i
    nodes = torch.tensor([0.5 - 0.5 / math.sqrt(3), 0.5 + 0.5 / math.sqrt(3)], dtype=torch.float64)
    for face in range(topo.num_faces):
        for k in range(3):
            e_k = int(topo.face_edges[face, k])
            z = torch.zeros(topo.num_edges, dtype=C128)
            z[e_k] = 1.0
            for j in range(3):  # integrate along the edge opposite corner j
                a, b = (j + 1) % 3, (j + 2) % 3
                bary = torch.zeros(2, 3, dtype=torch.float64)
                bary[:, a], bary[:, b] = 1 - nodes, nodes
                vals = F.point_vectors(v, topo, z, torch.full((2,), face), bary)
                length = float((v[f[face, b]] - v[f[face, a]]).norm())
                integral = vals.mean(0) * length
                expected = length * x_edge[e_k] if j == k else torch.zeros(3, dtype=torch.float64)
                assert torch.allclose(integral, expected, atol=1e-12), (face, k, j)


def test_face_values_is_interpolation_at_barycenter_and_face_mean(closed_mesh):
    v, f = closed_mesh
    topo = Topology(f, v.shape[0])
    g = torch.Generator().manual_seed(0)
    z = torch.randn(topo.num_edges, dtype=C128, generator=g)
    for n in (1, 3):
        bary = torch.full((topo.num_faces, 3), 1 / 3, dtype=torch.float64)
        w = F.interpolate(v, topo, z, torch.arange(topo.num_faces), bary, n)
        assert torch.allclose(F.face_values(v, topo, z, n), w)
    # mean over a face with the 3-point edge-midpoint rule (exact for linear functions)
    mids = torch.tensor([[0.0, 0.5, 0.5], [0.5, 0.0, 0.5], [0.5, 0.5, 0.0]], dtype=torch.float64)
    vals = torch.stack(
        [
            F.interpolate(v, topo, z, torch.arange(topo.num_faces), mids[k].expand(topo.num_faces, 3))
            for k in range(3)
        ]
    )
    assert torch.allclose(vals.mean(0), F.face_values(v, topo, z))


def test_edges_from_vectors_inverts_edge_vectors(closed_mesh):
    """Round trip z -> edge_vectors -> edges_from_vectors is the identity; the normal part of
    an ambient vector is dropped (its tangent projection is kept)."""
    v, f = closed_mesh
    topo = Topology(f)
    g = torch.Generator().manual_seed(3)
    z = torch.complex(
        torch.randn(topo.num_edges, generator=g, dtype=torch.float64),
        torch.randn(topo.num_edges, generator=g, dtype=torch.float64),
    )
    vec = F.edge_vectors(v, topo, z)
    torch.testing.assert_close(F.edges_from_vectors(v, topo, vec), z)
    _, _, normal = F.edge_frames(v, topo)
    torch.testing.assert_close(ev.edges_from_vectors(v, topo, vec + 2.5 * normal), z)
    torch.testing.assert_close(F.edge_vectors(v, topo, ev.edges_from_vectors(v, f, vec)), vec)
    assert ev.edges_from_vectors(v.float(), topo, vec.float()).dtype == torch.complex64
    with pytest.raises(ValueError, match="shape"):
        ev.edges_from_vectors(v, topo, vec[:-1])
    with pytest.raises(ValueError, match="floating"):
        ev.edges_from_vectors(v, topo, torch.ones(topo.num_edges, 3, dtype=torch.int64))


def test_face_edge_coefficients_match_3d_frames(closed_mesh):
    v, f = closed_mesh
    topo = Topology(f, v.shape[0])
    u = F.face_edge_coefficients(v, topo)
    x, y, _ = F.face_frames(v, topo)
    xe, _, _ = F.edge_frames(v, topo)
    xk = xe[topo.face_edges]  # (F, 3, 3)
    expected = torch.complex((xk * x[:, None]).sum(-1), (xk * y[:, None]).sum(-1))
    assert torch.allclose(u, expected, atol=1e-12)
    assert torch.allclose(F.face_edge_coefficients(v, topo, 3), u**3)


def test_frames_are_orthonormal(closed_mesh):
    v, f = closed_mesh
    topo = Topology(f, v.shape[0])
    for x, y, n in (F.face_frames(v, topo), F.edge_frames(v, topo), F.vertex_frames(v, topo)):
        for a, b in ((x, y), (y, n), (n, x)):
            assert (a * b).sum(1).abs().max() < 1e-12
        for a in (x, y, n):
            assert torch.allclose(a.norm(dim=1), torch.ones(a.shape[0], dtype=a.dtype))
        assert torch.allclose(torch.linalg.cross(n, x), y)


# --------------------------------------------------------------------------- sphere convergence


def test_smooth_field_evaluations_converge_on_the_sphere():
    """Face, vertex and edge 3D vectors of grad(x) match the analytic tangent field."""
    ex = torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)
    errors = []
    for level in (2, 3, 4):
        v, f = ev.icosphere(level)
        topo = Topology(f, v.shape[0])
        z = gradient_field(v, topo, v[:, 0])
        e = topo.edges
        mid = (v[e[:, 0]] + v[e[:, 1]]) / 2
        err = [
            (F.face_vectors(v, topo, z) - tangent_part(v[f].mean(1), ex.expand(topo.num_faces, 3)))
            .norm(dim=1)
            .max(),
            (F.vertex_vectors(v, topo, z) - tangent_part(v, ex.expand(v.shape[0], 3))).norm(dim=1).max(),
            (F.edge_vectors(v, topo, z) - tangent_part(mid, ex.expand(topo.num_edges, 3))).norm(dim=1).max(),
        ]
        errors.append([float(x) for x in err])
    errors = np.array(errors)
    assert (np.diff(errors, axis=0) < 0).all(), errors
    assert errors[-1].max() < 0.01, errors


def test_edge_vertex_edge_round_trip_converges():
    """(6.2): edges -> vertices -> edges on smooth fields, error falling under refinement."""
    for n in (1, 2):
        hs, errs = [], []
        for level in (2, 3, 4):
            v, f = ev.icosphere(level)
            topo = Topology(f, v.shape[0])
            z = gradient_field(v, topo, v[:, 0] + 0.5 * v[:, 1] * v[:, 2])
            z = F.nth_power(z, n)
            m = ev.mass_matrix(v, topo).values()
            back = F.vertices_to_edges(v, topo, F.edges_to_vertices(v, topo, z, n), n)
            errs.append(float(torch.sqrt((m * (back - z).abs() ** 2).sum() / (m * z.abs() ** 2).sum())))
            hs.append(float(ev.geometry.mean_edge_length(v, topo)))
        rate = np.polyfit(np.log(hs), np.log(errs), 1)[0]
        assert all(b < a for a, b in zip(errs, errs[1:])), errs
        assert rate > 1.0, f"n={n}: observed rate {rate:.2f}, errors {errs}"


def test_vertex_transport_rescaling_closes_the_fan(closed_mesh):
    """Around an interior vertex the rescaled angles span 2 pi: transport is consistent."""
    v, f = closed_mesh
    topo = Topology(f, v.shape[0])
    pv, pe, r = F.vertex_transport(v, topo)
    assert torch.allclose(r.abs(), torch.ones_like(r.abs()))
    # each vertex-edge incidence appears exactly once
    keys = pv * topo.num_edges + pe
    assert torch.unique(keys).numel() == keys.numel() == 2 * topo.num_edges
    # a field equal to the transported vertex value is reproduced exactly
    g = torch.Generator().manual_seed(1)
    zv = torch.randn(topo.num_vertices, dtype=C128, generator=g)
    for vert in range(topo.num_vertices):
        sel = pv == vert
        z = torch.zeros(topo.num_edges, dtype=C128)
        z[pe[sel]] = r[sel] * zv[vert]
        assert torch.allclose(F.edges_to_vertices(v, topo, z)[vert], zv[vert])


def test_boundary_vertices_are_not_rescaled():
    # flat, with boundary: a constant field must survive the round trip exactly
    v, f = perturbed_grid(4, 0.1, seed=2, flat=True)
    topo = Topology(f, v.shape[0])
    const = torch.tensor([0.2, 0.9, 0.0], dtype=torch.float64)
    z = planar_field(v, topo, lambda p: const.expand(p.shape[0], 3))
    zv = F.edges_to_vertices(v, topo, z)
    assert torch.allclose(F.vertex_vectors(v, topo, z), const.expand(v.shape[0], 3), atol=1e-12)
    assert torch.allclose(F.vertices_to_edges(v, topo, zv), z, atol=1e-12)


def test_directions_are_the_roots(closed_mesh):
    v, f = closed_mesh
    topo = Topology(f, v.shape[0])
    g = torch.Generator().manual_seed(2)
    z = torch.randn(topo.num_edges, dtype=C128, generator=g)
    for n in (1, 2, 4):
        d = F.edge_directions(v, topo, z, n)
        assert d.shape == (topo.num_edges, n, 3)
        assert torch.allclose(d.norm(dim=-1), z.abs()[:, None].expand(-1, n))
        x, y, _ = F.edge_frames(v, topo)
        assert torch.allclose(d[:, 0], F.to_vectors(x, y, F.nth_root(z, n)))
        assert F.face_directions(v, topo, z, n).shape == (topo.num_faces, n, 3)
        assert F.vertex_directions(v, topo, z, n).shape == (topo.num_vertices, n, 3)
        face, bary = random_points(topo, 5)
        assert F.point_directions(v, topo, z, face, bary, n).shape == (5, n, 3)
    assert torch.allclose(F.edge_directions(v, topo, z, 1)[:, 0], F.edge_vectors(v, topo, z))


# --------------------------------------------------------------------------- one-forms


def test_one_form_is_the_line_integral_and_gives_the_curl(open_mesh):
    v, f = open_mesh
    topo = Topology(f, v.shape[0])
    g = torch.Generator().manual_seed(5)
    z = torch.randn(topo.num_edges, dtype=C128, generator=g)
    c = F.to_one_form(v, topo, z)
    c_perp = F.to_one_form(v, topo, z, orthogonal=True)
    length = ev.edge_lengths(v, topo)
    assert torch.allclose(torch.complex(c, c_perp), length * z)
    # the DEC exterior derivative of c is the face circulation: A_T curl_T
    area = ev.face_areas(v, f)
    d_c = (topo.face_edge_signs.to(torch.float64) * c[topo.face_edges]).sum(1)
    assert torch.allclose(d_c, area * ev.face_curl(v, topo, z))
    # back: the real part is recovered, the imaginary one only with c_perp
    assert torch.allclose(F.from_one_form(v, topo, c), torch.complex(z.real, torch.zeros_like(z.real)))
    assert torch.allclose(F.from_one_form(v, topo, c, c_perp), z)


# --------------------------------------------------------------------------- errors and dtypes


def test_errors(closed_mesh):
    v, f = closed_mesh
    topo = Topology(f, v.shape[0])
    z = torch.ones(topo.num_edges, dtype=C128)
    face = torch.tensor([0, 1])
    bary = torch.full((2, 3), 1 / 3, dtype=torch.float64)
    with pytest.raises(
        ValueError, match=r"face_index out of range \(the mesh has 80 faces\) at points \[1\]"
    ):
        F.interpolate(v, topo, z, torch.tensor([0, 80]), bary)
    with pytest.raises(ValueError, match="face_index must be an integer tensor"):
        F.interpolate(v, topo, z, torch.tensor([0.0, 1.0]), bary)
    with pytest.raises(ValueError, match=r"bary must have shape \(2, 3\)"):
        F.interpolate(v, topo, z, face, bary[:, :2])
    with pytest.raises(ValueError, match=r"summing to 1\); violated at points \[1\]"):
        F.interpolate(v, topo, z, face, torch.tensor([[1 / 3] * 3, [0.5, 0.5, 0.5]], dtype=torch.float64))
    with pytest.raises(ValueError, match=r"non-negative"):
        F.interpolate(v, topo, z, face, torch.tensor([[1 / 3] * 3, [1.5, -0.5, 0.0]], dtype=torch.float64))
    with pytest.raises(ValueError, match=r"z must have shape \(E,\) or \(E, C\) with E = 120"):
        F.face_values(v, topo, z[:10])
    with pytest.raises(ValueError, match=r"z must have shape \(E,\) with E = 120"):
        F.face_values(v, topo, z[:, None].expand(-1, 2))
    with pytest.raises(ValueError, match="expected torch.complex128"):
        F.face_values(v, topo, z.to(torch.complex64))
    with pytest.raises(ValueError, match=r"zv must have shape \(42,\)"):
        F.vertices_to_edges(v, topo, z)
    with pytest.raises(ValueError, match=r"c must have shape \(120,\)"):
        F.from_one_form(v, topo, torch.ones(3, dtype=torch.float64))
    with pytest.raises(ValueError, match="c must be a real floating tensor"):
        F.from_one_form(v, topo, torch.ones(topo.num_edges, dtype=torch.int64))
    with pytest.raises(ValueError, match="n must be an integer >= 1"):
        F.face_directions(v, topo, z, 0)


def test_dtype_follows_float32(closed_mesh):
    v, f = closed_mesh
    v = v.float()
    topo = Topology(f, v.shape[0])
    z = torch.ones(topo.num_edges, dtype=torch.complex64)
    assert F.face_values(v, topo, z).dtype == torch.complex64
    assert F.edges_to_vertices(v, topo, z).dtype == torch.complex64
    assert F.vertex_vectors(v, topo, z).dtype == torch.float32
    assert F.to_one_form(v, topo, z).dtype == torch.float32


# --------------------------------------------------------------------------- gradcheck


def _inputs(seed=0):
    v, f = perturbed_icosphere(0, 0.05, seed=seed)
    topo = Topology(f, v.shape[0])
    g = torch.Generator().manual_seed(seed)
    z = torch.randn(topo.num_edges, dtype=C128, generator=g)
    return v.clone().requires_grad_(True), topo, z.requires_grad_(True)


def test_gradcheck_evaluation():
    v, topo, z = _inputs()
    face, bary = random_points(topo, 6, seed=1)
    checks = [
        lambda v, z: F.interpolate(v, topo, z, face, bary, 2),
        lambda v, z: F.face_values(v, topo, z, 3),
        lambda v, z: F.point_vectors(v, topo, z, face, bary),
        lambda v, z: F.edge_vectors(v, topo, z),
        lambda v, z: F.face_vectors(v, topo, z),
        lambda v, z: F.vertex_vectors(v, topo, z),
        lambda v, z: F.edges_to_vertices(v, topo, z, 2),
        lambda v, z: F.vertices_to_edges(v, topo, z[: topo.num_vertices], 2),
        lambda v, z: F.to_one_form(v, topo, z),
        lambda v, z: F.from_one_form(v, topo, z.real, z.imag),
        lambda v, z: F.face_directions(v, topo, z, 4),
    ]
    for fn in checks:
        assert torch.autograd.gradcheck(fn, (v, z), atol=1e-7, fast_mode=True)


def test_gradcheck_powers():
    g = torch.Generator().manual_seed(3)
    u = (torch.randn(5, dtype=C128, generator=g) + 0.5).requires_grad_(True)
    for n in (2, 3):
        assert torch.autograd.gradcheck(lambda u: F.nth_power(u, n), (u,))
        assert torch.autograd.gradcheck(lambda u: F.nth_root(u, n), (u,))
