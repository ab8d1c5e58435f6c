"""The vectorised torch operators agree with the naive per-face reference (``naive_reference``).

Every operator is compared on several small random meshes (closed and with boundary, flat and
curved, vertices randomly renumbered and face corners randomly rotated, so that both edge
orientations occur in every face position) to 1e-12, relative to the largest entry.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torch_edgevf import EdgeOperators, Topology
from torch_edgevf import geometry as tgeo
from torch_edgevf import operators as tops

import naive_reference as ref

REL = 1e-12

MESHES = [
    ("sphere", 0),
    ("sphere", 1),
    ("octahedron", 2),
    ("flat", 3),
    ("bumpy", 4),
    ("bumpy", 5),
]


def _dense(a) -> np.ndarray:
    if isinstance(a, torch.Tensor):
        if a.is_sparse:
            a = a.to_dense()
        return a.detach().cpu().numpy()
    return np.asarray(a)


class TorchBackend:
    """The torch implementation behind the same call signatures as ``naive_reference``.

    Every method takes numpy ``verts`` (V, 3) float64 and ``faces`` (F, 3) and returns a dense
    numpy array, so that tests can run identically on both backends.
    """

    name = "torch"

    @staticmethod
    def _t(verts, faces):
        v = torch.as_tensor(np.asarray(verts, dtype=np.float64))
        topo = Topology(torch.as_tensor(np.asarray(faces, dtype=np.int64)), num_vertices=v.shape[0])
        return v, topo

    def edges(self, faces):
        return _dense(Topology(torch.as_tensor(np.asarray(faces, dtype=np.int64))).edges)

    def face_edge_table(self, faces):
        topo = Topology(torch.as_tensor(np.asarray(faces, dtype=np.int64)))
        return _dense(topo.face_edges), _dense(topo.face_edge_signs)

    def boundary_edge_mask(self, faces):
        return _dense(Topology(torch.as_tensor(np.asarray(faces, dtype=np.int64))).boundary_edges)

    def edge_lengths(self, verts, faces):
        return _dense(tgeo.edge_lengths(*self._t(verts, faces)))

    def face_areas(self, verts, faces):
        v, topo = self._t(verts, faces)
        return _dense(tgeo.face_areas(v, topo.faces))

    def corner_angles(self, verts, faces):
        v, topo = self._t(verts, faces)
        return _dense(tgeo.corner_angles(v, topo.faces))

    def transport(self, verts, faces):
        return _dense(tgeo.transport_coefficients(*self._t(verts, faces), n=1))

    def dihedral_angles(self, verts, faces):
        return _dense(tgeo.dihedral_angles(*self._t(verts, faces)))

    def angle_defects(self, verts, faces):
        return _dense(tgeo.angle_defects(*self._t(verts, faces)))

    def mass(self, verts, faces):
        return _dense(tops.mass_matrix(*self._t(verts, faces)))

    def connection_laplacian(self, verts, faces, n=1):
        return _dense(tops.connection_laplacian(*self._t(verts, faces), n=n))

    def gradient(self, verts, faces):
        return _dense(tops.gradient(*self._t(verts, faces)))

    def curl_div_K(self, verts, faces):
        return _dense(tops.curl_div_operator(*self._t(verts, faces)))

    def real_form(self, A):
        A = np.asarray(A)
        sparse = torch.as_tensor(A).to_sparse()
        return _dense(tops.real_form(sparse))

    def curl_energy(self, verts, faces):
        return _dense(tops.curl_energy(*self._t(verts, faces)))

    def div_energy(self, verts, faces):
        return _dense(tops.div_energy(*self._t(verts, faces)))

    def laplace_beltrami(self, verts, faces):
        return _dense(tops.laplace_beltrami(*self._t(verts, faces)))

    def vertex_mass(self, verts, faces, lumped=False):
        return _dense(tops.vertex_mass(*self._t(verts, faces), lumped=lumped))

    def vertex_div_curl(self, verts, faces, z, lumped=True):
        if not lumped:
            raise NotImplementedError("torch_edgevf.operators.vertex_div_curl uses the lumped mass")
        div, curl = tops.vertex_div_curl(*self._t(verts, faces), torch.as_tensor(np.asarray(z)))
        return _dense(div), _dense(curl)

    def covariant_derivative(self, verts, faces, w):
        w = torch.as_tensor(np.asarray(w, dtype=np.complex128))
        return _dense(tops.covariant_derivative(*self._t(verts, faces), w))

    def cotan_laplacian(self, verts, faces):
        return _dense(tops.cotan_laplacian(*self._t(verts, faces)))


torch_backend = TorchBackend()


def assert_close(actual, expected, rel=REL, what=""):
    """``max|actual - expected| <= rel * max(1, max|expected|)``, same shape, no spurious
    imaginary part."""
    actual = np.asarray(actual)
    expected = np.asarray(expected)
    assert actual.shape == expected.shape, f"{what}: shape {actual.shape} != {expected.shape}"
    if np.iscomplexobj(actual) and not np.iscomplexobj(expected):
        expected = expected.astype(actual.dtype)
    scale = max(1.0, float(np.max(np.abs(expected), initial=0.0)))
    err = float(np.max(np.abs(actual - expected), initial=0.0))
    assert err <= rel * scale, f"{what}: max abs error {err:.3e} > {rel:.0e} * {scale:.3e}"


@pytest.fixture(params=MESHES, ids=[f"{k}-{s}" for k, s in MESHES])
def mesh(request):
    kind, seed = request.param
    return ref.random_mesh(seed, kind)


# --------------------------------------------------------------------------- topology


def test_topology_matches_reference(mesh):
    _, faces = mesh
    topo = Topology(torch.as_tensor(faces))
    np.testing.assert_array_equal(_dense(topo.edges), ref.edges(faces))
    fe, sg = ref.face_edge_table(faces)
    np.testing.assert_array_equal(_dense(topo.face_edges), fe)
    np.testing.assert_array_equal(_dense(topo.face_edge_signs), sg)
    np.testing.assert_array_equal(_dense(topo.boundary_edges), ref.boundary_edge_mask(faces))
    assert topo.edges.dtype == torch.int64
    assert topo.face_edges.dtype == torch.int64


def test_test_meshes_mix_orientations(mesh):
    """The renumbering must exercise both signs at every corner position."""
    _, faces = mesh
    _, sg = ref.face_edge_table(faces)
    for k in range(3):
        assert (sg[:, k] > 0).any() and (sg[:, k] < 0).any()


# --------------------------------------------------------------------------- geometry


def test_geometry_matches_reference(mesh):
    verts, faces = mesh
    for name in ("edge_lengths", "face_areas", "corner_angles", "dihedral_angles", "angle_defects"):
        assert_close(getattr(torch_backend, name)(verts, faces), getattr(ref, name)(verts, faces), what=name)


def test_transport_matches_reference(mesh):
    verts, faces = mesh
    r = ref.transport(verts, faces)
    assert_close(torch_backend.transport(verts, faces), r, what="transport")
    assert_close(
        torch_backend.transport(verts, faces),
        ref.transport_from_frames(verts, faces),
        what="transport vs 3D frames",
    )
    v, topo = TorchBackend._t(verts, faces)
    for n in (0, 2, 3):
        assert_close(_dense(tgeo.transport_coefficients(v, topo, n=n)), r**n, what=f"transport n={n}")


# --------------------------------------------------------------------------- edge operators


def test_mass_matches_reference(mesh):
    verts, faces = mesh
    M = torch_backend.mass(verts, faces)
    assert not np.iscomplexobj(M)
    assert_close(M, ref.mass(verts, faces), what="M_z")


@pytest.mark.parametrize("n", [0, 1, 2, 3, 4])
def test_connection_laplacian_matches_reference(mesh, n):
    verts, faces = mesh
    L = torch_backend.connection_laplacian(verts, faces, n=n)
    expected = ref.connection_laplacian(verts, faces, n=n)
    if n == 0:
        assert not np.iscomplexobj(L), "n = 0 must give the real CR Laplacian"
        assert np.abs(expected.imag).max() == 0
        expected = expected.real
    assert_close(L, expected, what=f"L_c^({n})")


def test_gradient_matches_reference(mesh):
    verts, faces = mesh
    assert_close(torch_backend.gradient(verts, faces), ref.gradient(verts, faces), what="G")


def test_curl_div_K_matches_reference(mesh):
    verts, faces = mesh
    K = torch_backend.curl_div_K(verts, faces)
    assert not np.iscomplexobj(K)
    assert_close(K, ref.curl_div_K(verts, faces), what="K")


def test_face_curl_div_match_reference(mesh):
    verts, faces = mesh
    rng = np.random.default_rng(7)
    ne = len(ref.edges(faces))
    z = rng.normal(size=ne) + 1j * rng.normal(size=ne)
    K, area = ref.curl_div_K(verts, faces), ref.face_areas(verts, faces)
    v, topo = TorchBackend._t(verts, faces)
    assert_close(_dense(tops.face_curl(v, topo, torch.as_tensor(z))), K @ z.real / area, what="face curl")
    assert_close(_dense(tops.face_div(v, topo, torch.as_tensor(z))), -K @ z.imag / area, what="face div")


def test_real_form_matches_reference(mesh):
    verts, faces = mesh
    L = ref.connection_laplacian(verts, faces, n=1)
    assert_close(torch_backend.real_form(L), ref.real_form(L), what="real_form(L_c)")
    G = ref.gradient(verts, faces)  # rectangular
    assert_close(torch_backend.real_form(G), ref.real_form(G), what="real_form(G)")
    M = ref.mass(verts, faces)  # real input: zero imaginary part
    assert_close(torch_backend.real_form(M), ref.real_form(M), what="real_form(M_z)")


def test_curl_div_energy_match_reference(mesh):
    verts, faces = mesh
    assert_close(torch_backend.curl_energy(verts, faces), ref.curl_energy(verts, faces), what="L_curl")
    assert_close(torch_backend.div_energy(verts, faces), ref.div_energy(verts, faces), what="L_div")


def test_laplace_beltrami_matches_reference(mesh):
    verts, faces = mesh
    L = torch_backend.laplace_beltrami(verts, faces)
    assert not np.iscomplexobj(L)
    assert_close(L, ref.laplace_beltrami(verts, faces), what="Laplace-Beltrami")


@pytest.mark.parametrize("lumped", [False, True])
def test_vertex_mass_matches_reference(mesh, lumped):
    verts, faces = mesh
    assert_close(
        torch_backend.vertex_mass(verts, faces, lumped=lumped),
        ref.vertex_mass(verts, faces, lumped=lumped),
        what=f"M_v lumped={lumped}",
    )


def test_vertex_div_curl_matches_reference(mesh):
    verts, faces = mesh
    rng = np.random.default_rng(11)
    ne = len(ref.edges(faces))
    z = rng.normal(size=ne) + 1j * rng.normal(size=ne)
    div, curl = torch_backend.vertex_div_curl(verts, faces, z, lumped=True)
    rdiv, rcurl = ref.vertex_div_curl(verts, faces, z, lumped=True)
    assert_close(div, rdiv, what="div_v")
    assert_close(curl, rcurl, what="curl_v")


def test_covariant_derivative_matches_reference(mesh):
    verts, faces = mesh
    rng = np.random.default_rng(3)
    ne = len(ref.edges(faces))
    w = rng.normal(size=ne) + 1j * rng.normal(size=ne)
    assert_close(
        torch_backend.covariant_derivative(verts, faces, w),
        ref.covariant_derivative(verts, faces, w),
        what="D_w",
    )
    # real w is taken as having zero imaginary part
    v, topo = TorchBackend._t(verts, faces)
    D_real = _dense(tops.covariant_derivative(v, topo, torch.as_tensor(w.real)))
    assert_close(D_real, ref.covariant_derivative(verts, faces, w.real + 0j), what="D_w, real w")


def test_cotan_laplacian_matches_reference(mesh):
    verts, faces = mesh
    assert_close(torch_backend.cotan_laplacian(verts, faces), ref.cotan_laplacian(verts, faces), what="cotan")


# --------------------------------------------------------------------------- module


@pytest.mark.parametrize("n", [0, 1, 2])
def test_edge_operators_module_matches_reference(mesh, n):
    verts, faces = mesh
    ops = EdgeOperators(torch.as_tensor(verts), torch.as_tensor(faces), n=n)
    np.testing.assert_array_equal(_dense(ops.edges), ref.edges(faces))
    L = ref.connection_laplacian(verts, faces, n=n)
    assert_close(_dense(ops.connection_laplacian), L.real if n == 0 else L, what="module L_c")
    assert_close(_dense(ops.mass), ref.mass(verts, faces), what="module M_z")
    assert_close(_dense(ops.gradient), ref.gradient(verts, faces), what="module G")
    assert_close(_dense(ops.curl_div), ref.curl_div_K(verts, faces), what="module K")
    assert_close(_dense(ops.laplace_beltrami), ref.laplace_beltrami(verts, faces), what="module LB")
    assert_close(_dense(ops.vertex_mass), ref.vertex_mass(verts, faces), what="module M_v")
    assert_close(
        _dense(ops.lumped_vertex_mass), ref.vertex_mass(verts, faces, lumped=True), what="module lumped M_v"
    )
    assert_close(_dense(ops.face_area), ref.face_areas(verts, faces), what="module areas")
    assert_close(_dense(ops.edge_length), ref.edge_lengths(verts, faces), what="module lengths")
    assert_close(_dense(ops.cotan_laplacian()), ref.cotan_laplacian(verts, faces), what="module cotan")
    assert_close(_dense(ops.curl_energy()), ref.curl_energy(verts, faces), what="module L_curl")
    assert_close(_dense(ops.div_energy()), ref.div_energy(verts, faces), what="module L_div")


def test_edge_operators_update_matches_reference():
    """Re-assembly for new positions of the same topology gives the new reference operators."""
    verts0, faces = ref.random_mesh(8, "bumpy")
    verts1 = verts0 + 0.02 * np.random.default_rng(9).normal(size=verts0.shape)
    ops = EdgeOperators(torch.as_tensor(verts0), torch.as_tensor(faces))
    ops.update(torch.as_tensor(verts1))
    assert_close(_dense(ops.connection_laplacian), ref.connection_laplacian(verts1, faces), what="L_c")
    assert_close(_dense(ops.gradient), ref.gradient(verts1, faces), what="G")
    assert_close(_dense(ops.laplace_beltrami), ref.laplace_beltrami(verts1, faces), what="LB")
    w = np.exp(1j * np.arange(ops.num_edges))
    assert_close(
        _dense(ops.covariant_derivative(torch.as_tensor(w))),
        ref.covariant_derivative(verts1, faces, w),
        what="D_w",
    )


# --------------------------------------------------------------------------- derivatives


def _phases(ne):
    return np.exp(1j * np.arange(ne))


_DIFFERENTIABLE = {
    "mass": (tops.mass_matrix, ref.mass),
    "L_c^(1)": (
        lambda v, t: tops.connection_laplacian(v, t, n=1),
        lambda v, f: ref.connection_laplacian(v, f, 1),
    ),
    "L_c^(2)": (
        lambda v, t: tops.connection_laplacian(v, t, n=2),
        lambda v, f: ref.connection_laplacian(v, f, 2),
    ),
    "G": (tops.gradient, ref.gradient),
    "K": (tops.curl_div_operator, ref.curl_div_K),
    "LB": (tops.laplace_beltrami, ref.laplace_beltrami),
    "M_v": (tops.vertex_mass, ref.vertex_mass),
    "cotan": (tops.cotan_laplacian, ref.cotan_laplacian),
    "D_w": (
        lambda v, t: tops.covariant_derivative(v, t, torch.as_tensor(_phases(t.num_edges))),
        lambda v, f: ref.covariant_derivative(v, f, _phases(len(ref.edges(f)))),
    ),
    "dihedral": (tgeo.dihedral_angles, ref.dihedral_angles),
    "defects": (tgeo.angle_defects, ref.angle_defects),
    "angles": (lambda v, t: tgeo.corner_angles(v, t.faces), ref.corner_angles),
}


@pytest.mark.parametrize("kind,seed", [("octahedron", 20), ("bumpy", 21)])
@pytest.mark.parametrize("name", list(_DIFFERENTIABLE))
def test_autograd_matches_finite_differences_of_reference(kind, seed, name):
    """Directional derivatives of torch autograd agree with central differences of the
    reference, for a random linear functional s(verts) = Re <W, Op(verts)>."""
    verts, faces = ref.random_mesh(seed, kind)
    torch_op, ref_op = _DIFFERENTIABLE[name]
    rng = np.random.default_rng(seed)
    shape = ref_op(verts, faces).shape
    W = rng.normal(size=shape) + 1j * rng.normal(size=shape)

    def s_ref(v):
        return float(np.sum((W.conj() * ref_op(v, faces)).real))

    v = torch.tensor(verts, requires_grad=True)
    topo = Topology(torch.as_tensor(faces), num_vertices=v.shape[0])
    out = torch_op(v, topo)
    out = out.to_dense() if out.is_sparse else out
    Wt = torch.as_tensor(W if out.is_complex() else W.real)
    s = (Wt.conj() * out).real.sum()
    (grad,) = torch.autograd.grad(s, v)
    grad = grad.numpy()
    h = 1e-6
    for _ in range(3):
        d = rng.normal(size=verts.shape)
        fd = (s_ref(verts + h * d) - s_ref(verts - h * d)) / (2 * h)
        an = float(np.sum(grad * d))
        assert abs(an - fd) <= 1e-6 * max(1.0, abs(fd)), f"{name}: autograd {an} vs central diff {fd}"
