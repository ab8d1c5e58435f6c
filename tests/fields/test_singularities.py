"""Singularity detection, location and splitting (thesis 4.1, B.2)."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import torch

import torch_edgevf as ev
from torch_edgevf.fields.singularities import (
    face_frame_angles,
    face_rotations,
    locate_singularities,
    singularities,
    split_faces,
    split_singular_faces,
)
from torch_edgevf.mesh.topology import Topology

from conftest import SHARED

SHARED_MESHES = SHARED / "meshes"


# --------------------------------------------------------------------------- helpers


def _scipy(a: torch.Tensor) -> sp.csc_matrix:
    a = a.coalesce()
    i = a.indices().numpy()
    return sp.csc_matrix((a.values().detach().numpy(), (i[0], i[1])), shape=tuple(a.shape))


def smoothest_field(verts, faces, n: int = 1) -> torch.Tensor:
    """The smoothest n-field (thesis 3.1): library version if present, else SciPy."""
    try:
        from torch_edgevf.fields.design import smoothest_field as lib
    except ImportError:
        lib = None
    if lib is not None:
        return lib(verts, faces, n=n)
    topo = Topology(faces, verts.shape[0])
    lc = _scipy(ev.connection_laplacian(verts, topo, n))
    mz = _scipy(ev.mass_matrix(verts, topo))
    _, x = sla.eigsh(lc, k=1, M=mz, sigma=-1e-3, which="LM")
    return torch.from_numpy(x[:, 0])


def planar_field(verts, topo, fun, n: int = 1) -> torch.Tensor:
    """Edge values of the planar n-field whose representation vector is ``fun(x + iy)``."""
    e = topo.edges
    a, b = verts[e[:, 0]], verts[e[:, 1]]
    mid, d = (a + b) / 2, b - a
    t = torch.complex(d[:, 0], d[:, 1])
    t = t / t.abs()
    return fun(torch.complex(mid[:, 0], mid[:, 1])) * t.conj() ** n


def disk(rings: int = 8, shift=(0.0, 0.0)):
    """A flat Delaunay disk of radius 1 (concentric rings), shifted in the plane."""
    from scipy.spatial import Delaunay

    pts = [np.zeros((1, 2))]
    for k in range(1, rings + 1):
        th = np.arange(6 * k) * 2 * np.pi / (6 * k) + 0.1 * k
        pts.append(k / rings * np.stack([np.cos(th), np.sin(th)], 1))
    p = np.concatenate(pts)
    tri = Delaunay(p).simplices.astype(np.int64)
    a = p[tri]
    cross = (a[:, 1, 0] - a[:, 0, 0]) * (a[:, 2, 1] - a[:, 0, 1]) - (a[:, 1, 1] - a[:, 0, 1]) * (
        a[:, 2, 0] - a[:, 0, 0]
    )
    tri[cross < 0] = tri[cross < 0][:, [0, 2, 1]]
    v = np.concatenate([p + np.asarray(shift), np.zeros((len(p), 1))], 1)
    return torch.from_numpy(v), torch.from_numpy(tri)


def flat_grid(m: int):
    """A ``m x m`` grid of [-1, 1]^2 (m odd) shifted so the origin is the centroid of a face.

    The origin sits at the same relative position in its cell at every ``m``, which makes
    refinement studies clean.
    """
    v, f = ev.meshes.grid(m, m, size=(2.0, 2.0))
    h = 2.0 / m
    k = (m - 1) // 2
    v = v.clone()
    v[:, 0] -= (k + 2 / 3) * h
    v[:, 1] -= (k + 1 / 3) * h
    return v, f, h


def load_shared(name: str):
    path = SHARED_MESHES / name
    if not path.exists():
        pytest.skip(f"{path} is not available")
    from torch_edgevf.io import load_mesh

    return load_mesh(path)


def random_field(num_edges: int, seed: int, zeros_every: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    z = torch.randn(num_edges, dtype=torch.complex128, generator=g)
    if zeros_every:
        z[::zeros_every] = 0
    return z


# --------------------------------------------------------------------------- detection


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_smoothest_fields_on_ellipsoid_have_2n_singularities_of_index_1_over_n(n):
    v, f = ev.meshes.ellipsoid((1.0, 0.8, 0.6), level=3)
    z = smoothest_field(v, f, n)
    s = singularities(v, f, z, n=n)
    assert s.counts() == {1.0 / n: 2 * n}, s
    assert s.total == 2
    assert s.max_rounding_error < 1e-9


def test_single_face_hand_case():
    """One face, field rotating once along the mid-segment loop: face index exactly +1."""
    v = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=torch.float64)
    f = torch.tensor([[0, 1, 2]])
    topo = Topology(f)
    z = planar_field(v, topo, lambda p: p - complex(1 / 3, 1 / 3))  # source at the centroid
    s = singularities(v, topo, z, boundary="exclude")
    assert s.face_index.tolist() == [1.0]
    omega = face_rotations(v, topo, z)
    assert torch.allclose(omega.sum(), torch.tensor(2 * np.pi, dtype=torch.float64))
    loc = locate_singularities(v, topo, z)
    assert torch.allclose(loc.barycentric, torch.full((1, 3), 1 / 3, dtype=torch.float64))


def test_face_frame_angles_reproduce_transport_coefficients():
    v, f = ev.meshes.ellipsoid((1.0, 0.8, 0.6), level=1)
    g = torch.Generator().manual_seed(3)
    perm = torch.randperm(v.shape[0], generator=g)
    inv = torch.empty_like(perm)
    inv[perm] = torch.arange(perm.numel())
    v, f = v[perm], inv[f]
    topo = Topology(f)
    th = face_frame_angles(v, topo)
    d = th[:, :, None] - th[:, None, :]
    for n in (1, 4):
        r = ev.transport_coefficients(v, topo, n)
        assert torch.allclose(r, torch.polar(torch.ones_like(d), n * d), atol=1e-12)


@pytest.mark.parametrize("n", [1, 2, 4])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_poincare_hopf_random_fields_on_perturbed_spheres(n, seed):
    v, f = ev.icosphere(2)
    g = torch.Generator().manual_seed(seed)
    v = v + 0.05 * torch.randn(v.shape, generator=g, dtype=v.dtype)
    perm = torch.randperm(v.shape[0], generator=g)
    inv = torch.empty_like(perm)
    inv[perm] = torch.arange(perm.numel())
    v, f = v[perm], inv[f]
    topo = Topology(f)
    z = random_field(topo.num_edges, seed, zeros_every=0)
    s = singularities(v, topo, z, n=n)
    assert int(s.face_winding.sum() + s.vertex_winding.sum()) == n * 2
    assert s.total == 2
    assert s.num_singularities > 50  # random fields are very singular
    assert s.max_rounding_error < 1e-9
    # random fields reach indices beyond +-1/n at vertices: kept, not clipped
    assert float(s.vertex_index.abs().max()) > 1.0 / n


@pytest.mark.parametrize("n", [1, 4])
def test_poincare_hopf_with_zero_values_and_antipodal_pairs(n):
    v, f = ev.icosphere(2)
    topo = Topology(f)
    z = random_field(topo.num_edges, 7, zeros_every=3)
    z[1::5] = -1e-300  # tiny values: no underflow to NaN
    s = singularities(v, topo, z, n=n)
    assert torch.isfinite(s.face_index).all() and torch.isfinite(s.vertex_index).all()
    assert s.total == 2
    z0 = torch.zeros(topo.num_edges, dtype=torch.complex128)
    s0 = singularities(v, topo, z0, n=n)
    assert s0.total == 2
    # antipodal values across every face: omega = +-pi everywhere, still exact
    z1 = torch.ones(topo.num_edges, dtype=torch.complex128)
    s1 = singularities(v, topo, z1 * -(1 ** torch.arange(topo.num_edges)), n=n)
    assert s1.total == 2


def test_poincare_hopf_float32():
    v, f = ev.icosphere(3, dtype=torch.float32)
    topo = Topology(f)
    z = random_field(topo.num_edges, 11).to(torch.complex64)
    s = singularities(v, topo, z, n=4)
    assert s.total == 2 and s.max_rounding_error < 1e-3
    assert s.face_index.dtype == torch.float32


@pytest.mark.parametrize(("name", "chi"), [("torus.obj", 0), ("skull_low_resolution.obj", -2)])
@pytest.mark.parametrize("n", [1, 4])
def test_poincare_hopf_on_real_meshes(name, chi, n):
    v, f = load_shared(name)
    topo = Topology(f, v.shape[0])
    assert topo.euler_characteristic == chi
    z = smoothest_field(v, topo.faces, n)
    s = singularities(v, topo, z, n=n)
    assert s.total == chi, s
    zr = random_field(topo.num_edges, 5)
    assert singularities(v, topo, zr, n=n).total == chi


def test_sphere_smoothest_vector_field_finds_both_poles():
    """libigl-style detectors miss the poles of the sphere; the region partition does not."""
    v, f = ev.icosphere(3)
    z = smoothest_field(v, f, 1)
    s = singularities(v, f, z)
    assert s.counts() == {1.0: 2}


# --------------------------------------------------------------------------- boundary


@pytest.mark.parametrize("shift", [(0.0, 0.0), (0.037, 0.051)])
@pytest.mark.parametrize(("fun", "index"), [(lambda p: p, 1.0), (lambda p: 1j * p, 1.0), (lambda p: -p, 1.0)])
def test_disk_fields_at_constant_angle_to_the_boundary(shift, fun, index):
    v, f = disk(8, shift)
    topo = Topology(f)
    p0 = complex(*shift)
    z = planar_field(v, topo, lambda p: fun(p - p0))
    s = singularities(v, topo, z)
    assert s.total == topo.euler_characteristic == 1
    assert s.counts() == {index: 1}
    assert not bool(s.vertex_winding[topo.boundary_vertices].any())
    assert abs(s.boundary_turning) < 1e-9


def test_disk_field_winding_against_the_boundary():
    """``conj(p)`` turns -1 around the origin and -2 relative to the boundary."""
    v, f = disk(8, (0.037, 0.051))
    topo = Topology(f)
    z = planar_field(v, topo, lambda p: (p - complex(0.037, 0.051)).conj())
    for mode in ("round", "exclude"):
        s = singularities(v, topo, z, boundary=mode)
        assert s.counts() == {-1.0: 1}
        assert s.total == pytest.approx(s.euler_characteristic + s.boundary_turning)
        assert s.boundary_turning == pytest.approx(-2.0)


def test_boundary_exclude_zeroes_boundary_vertices_and_keeps_the_identity():
    v, f = ev.meshes.grid(6, 6)
    topo = Topology(f)
    z = random_field(topo.num_edges, 2)
    for mode in ("round", "exclude"):
        s = singularities(v, topo, z, n=4, boundary=mode)
        assert s.total == pytest.approx(topo.euler_characteristic + s.boundary_turning, abs=1e-9)
        if mode == "exclude":
            assert not bool(s.vertex_winding[topo.boundary_vertices].any())


# --------------------------------------------------------------------------- location


@pytest.mark.parametrize("n", [1, 4])
def test_linear_field_is_located_exactly(n):
    v, f, _ = flat_grid(15)
    topo = Topology(f)
    z = planar_field(v, topo, lambda p: (1 + 0.5j) * p, n)
    s = singularities(v, topo, z, n=n)
    assert s.singular_faces.numel() >= 1
    loc = locate_singularities(v, topo, z, n)
    centre = loc.points.norm(dim=1).argmin()
    assert float(loc.points[centre].norm()) < 1e-12
    assert float(s.face_index[loc.faces[centre]]) == pytest.approx(1.0 / n)
    assert bool(loc.inside.all())


def test_location_converges_at_second_order():
    errors, hs = [], []
    for m in (5, 15, 45):
        v, f, h = flat_grid(m)
        topo = Topology(f)
        z = planar_field(v, topo, lambda p: p + 0.5 * p * p + 0.3j * p.conj() ** 2)
        loc = locate_singularities(v, topo, z)
        assert loc.faces.numel() == 1
        errors.append(float(loc.points.norm()))
        hs.append(h)
    rate = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    assert 1.8 < rate < 2.3, f"observed rate {rate:.3f}, errors {errors}"


def test_location_gradients():
    v, f, _ = flat_grid(5)
    topo = Topology(f)
    z = planar_field(v, topo, lambda p: p + 0.5 * p * p)
    face = locate_singularities(v, topo, z).faces
    v = v.clone().requires_grad_(True)
    z = z.clone().requires_grad_(True)

    def fn(verts, field):
        return locate_singularities(verts, topo, field, 1, which=face).points

    assert torch.autograd.gradcheck(fn, (v, z), eps=1e-6, atol=1e-6)


# --------------------------------------------------------------------------- splitting


@pytest.mark.parametrize("n", [1, 4])
def test_split_moves_the_singularity_to_a_vertex_and_keeps_the_field(n):
    v, f = ev.meshes.ellipsoid((1.0, 0.8, 0.6), level=2)
    g = torch.Generator().manual_seed(0)
    v = v + 0.02 * torch.randn(v.shape, generator=g, dtype=v.dtype)
    topo = Topology(f)
    z = smoothest_field(v, f, n)
    z = z + 2.0 * random_field(topo.num_edges, 1) * z.abs().mean()  # singularities inside faces
    s = singularities(v, topo, z, n)
    assert s.singular_faces.numel() > 0
    out = split_singular_faces(v, topo, z, n)
    k = s.singular_faces.numel()
    assert out.verts.shape[0] == v.shape[0] + k and out.faces.shape[0] == f.shape[0] + 2 * k
    assert torch.equal(out.z[out.edge_map], z)
    s2 = singularities(out.verts, out.faces, out.z, n)
    assert s2.total == 2
    assert s2.singular_faces.numel() == 0
    assert torch.equal(s2.vertex_index[out.new_vertices], s.face_index[s.singular_faces])
    assert torch.equal(s2.vertex_index[: v.shape[0]], s.vertex_index)


def test_split_reproduces_the_interpolated_field():
    """The carried field in each sub-face equals the old affine field (so zeros stay put)."""
    v, f, _ = flat_grid(5)
    topo = Topology(f)
    g = torch.Generator().manual_seed(4)
    which = torch.tensor([0, 7, 12, 31, 49])
    bary = torch.rand((5, 3), generator=g, dtype=torch.float64) + 0.1
    bary = bary / bary.sum(1, keepdim=True)
    for n in (1, 2, 4):
        fun = lambda p: (0.7 - 0.2j) * p + 0.1 + 0.3j * p.conj()  # noqa: E731
        z = planar_field(v, topo, fun, n)
        out = split_faces(v, topo, z, which, bary, n)
        expected = planar_field(out.verts, Topology(out.faces), fun, n)
        assert torch.allclose(out.z, expected, atol=1e-12)
    # located zero of an affine field becomes a vertex with the face's index
    z = planar_field(v, topo, lambda p: (0.7 - 0.2j) * p)
    loc = locate_singularities(v, topo, z)
    assert loc.faces.numel() == 1
    out = split_singular_faces(v, topo, z)
    assert float(out.verts[out.new_vertices].norm()) < 1e-12
    s2 = singularities(out.verts, out.faces, out.z, boundary="exclude")
    assert s2.as_list() == [("vertex", int(out.new_vertices[0]), 1.0)]


def test_validation_errors():
    v, f = ev.icosphere(1)
    topo = Topology(f)
    z = torch.zeros(topo.num_edges, dtype=torch.complex128)
    with pytest.raises(ValueError, match="n must be an integer"):
        singularities(v, topo, z, n=0)
    with pytest.raises(ValueError, match="boundary must be"):
        singularities(v, topo, z, boundary="ignore")
    with pytest.raises(ValueError, match="shape"):
        singularities(v, topo, z[:-1])
    with pytest.raises(ValueError, match="barycentric"):
        split_faces(v, topo, z, [0], [[1.0, 0.0, 0.0]])
