"""Operator identities, exactness on linear fields, hand cases, gradients and dtypes."""

import numpy as np
import pytest
import torch

import torch_edgevf as ev

from conftest import dense, perturbed_grid, perturbed_icosphere

MESHES = {
    "closed": lambda: perturbed_icosphere(1, 0.05, seed=1),
    "open": lambda: perturbed_grid(4, 0.3, seed=2),
}


def _edge_frames_2d(v, t):
    """Complex coordinates (in the plane z=0) of each edge's unit frame."""
    e = t.edges
    d = v[e[:, 1]] - v[e[:, 0]]
    d = d / d.norm(dim=1, keepdim=True)
    return torch.complex(d[:, 0], d[:, 1])


@pytest.mark.parametrize("kind", MESHES)
@pytest.mark.parametrize("n", [0, 1, 2, 4])
def test_connection_laplacian_hermitian_psd(kind, n):
    v, f = MESHES[kind]()
    L = dense(ev.connection_laplacian(v, f, n))
    np.testing.assert_allclose(L, L.conj().T, atol=1e-13)
    assert np.abs(np.imag(np.diag(L))).max() == 0
    assert np.linalg.eigvalsh(L).min() > -1e-12 * np.abs(L).max()
    if n == 0:
        assert not np.iscomplexobj(L)
        np.testing.assert_allclose(L.sum(1), 0, atol=1e-12)  # constants in the CR kernel


@pytest.mark.parametrize("kind", MESHES)
def test_curl_of_gradient_vanishes_and_tangent_is_finite_difference(kind):
    v, f = MESHES[kind]()
    t = ev.Topology(f)
    G, M = ev.gradient(v, t), dense(ev.mass_matrix(v, t)).diagonal()
    fv = torch.randn(t.num_vertices, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    z = (G @ fv.to(G.dtype)) / torch.from_numpy(M.copy())
    curl = ev.face_curl(v, t, z)
    assert curl.abs().max() < 1e-12 * z.abs().max() / ev.face_areas(v, f).min()
    e = t.edges
    fd = (fv[e[:, 1]] - fv[e[:, 0]]) / ev.edge_lengths(v, t)
    torch.testing.assert_close(z.real, fd, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("kind", MESHES)
def test_gradient_adjoint_is_minus_div_plus_i_curl(kind):
    """-G^* z = M_v (div_v + i curl_v) (B.4), and div_v is the adjoint of the gradient."""
    v, f = MESHES[kind]()
    t = ev.Topology(f)
    g = torch.Generator().manual_seed(1)
    z = torch.randn(t.num_edges, dtype=torch.complex128, generator=g)
    div, curl = ev.vertex_div_curl(v, t, z)
    Mv = ev.vertex_mass(v, t, lumped=True)
    G = ev.gradient(v, t)
    lhs = -(G.conj().transpose(0, 1) @ z)
    torch.testing.assert_close(lhs, Mv.to(torch.complex128) @ torch.complex(div, curl))
    # <z, grad f>_M = z^* G f = -<div z, f>_{M_v} - i <curl z, f>_{M_v} for real f
    fv = torch.randn(t.num_vertices, dtype=torch.float64, generator=g)
    inner = torch.vdot(z, G @ fv.to(G.dtype))
    torch.testing.assert_close(inner.real, -(div * (Mv @ fv)).sum())


@pytest.mark.parametrize("kind", MESHES)
def test_laplace_beltrami_real_symmetric_with_constant_kernel(kind):
    v, f = MESHES[kind]()
    t = ev.Topology(f)
    G, M = dense(ev.gradient(v, t)), dense(ev.mass_matrix(v, t)).diagonal()
    full = G.conj().T @ (G / M[:, None])
    # Im(G^* M^-1 G) is the antisymmetric form int grad g x grad f = boundary integral of
    # g df/dt: zero on closed meshes; L is the real part, the Dirichlet form.
    np.testing.assert_allclose(full.imag, -full.imag.T, atol=1e-13)
    if kind == "closed":
        assert np.abs(full.imag).max() < 1e-13 * np.abs(full).max()
    else:
        assert np.abs(full.imag).max() > 1e-3
    L = dense(ev.laplace_beltrami(v, t))
    np.testing.assert_allclose(L, full.real, atol=1e-13)
    np.testing.assert_allclose(L, L.T, atol=1e-14)
    np.testing.assert_allclose(L @ np.ones(t.num_vertices), 0, atol=1e-12)
    assert np.linalg.eigvalsh(L).min() > -1e-12


def test_covariant_derivative_diagonal_closed_vs_boundary():
    g = torch.Generator().manual_seed(3)
    v, f = MESHES["closed"]()
    t = ev.Topology(f)
    w = torch.randn(t.num_edges, dtype=torch.complex128, generator=g)
    D = ev.covariant_derivative(v, t, w).to_dense()
    assert D.diagonal().abs().max() == 0
    v, f = MESHES["open"]()
    t = ev.Topology(f)
    w = torch.randn(t.num_edges, dtype=torch.complex128, generator=g)
    D = ev.covariant_derivative(v, t, w).to_dense().diagonal()
    assert D[~t.boundary_edges].abs().max() == 0
    assert (D[t.boundary_edges].abs() > 0).all()


def _linear_field(v, t, B, c):
    """Edge values of the planar field psi(p) = B p + c, sampled at midpoints in edge frames."""
    e = t.edges
    mid = 0.5 * (v[e[:, 0], :2] + v[e[:, 1], :2])
    val = mid @ B.T + c
    return torch.complex(val[:, 0], val[:, 1]) * _edge_frames_2d(v, t).conj()


def test_flat_linear_fields_are_exact():
    """On a flat mesh the CR interpolation is exact for linear fields, so energies are exact."""
    v, f = perturbed_grid(5, 0.1, seed=4, flat=True)
    t = ev.Topology(f)
    g = torch.Generator().manual_seed(5)
    B, c = (
        torch.randn(2, 2, dtype=torch.float64, generator=g),
        torch.randn(2, dtype=torch.float64, generator=g),
    )
    z = _linear_field(v, t, B, c)
    area = ev.face_areas(v, f).sum()
    # Dirichlet energy = area * |B|_F^2
    L = ev.connection_laplacian(v, t, 1)
    torch.testing.assert_close(torch.vdot(z, L @ z).real, area * (B**2).sum())
    # mass: z^* M z = int |psi|^2 is exact for linear psi too (midpoint rule is exact for quadratics)
    # curl and div are constant: curl = B10 - B01, div = B00 + B11
    torch.testing.assert_close(
        ev.face_curl(v, t, z), torch.full((t.num_faces,), float(B[1, 0] - B[0, 1]), dtype=v.dtype)
    )
    torch.testing.assert_close(
        ev.face_div(v, t, z), torch.full((t.num_faces,), float(B[0, 0] + B[1, 1]), dtype=v.dtype)
    )
    # covariant derivative along a linear w: nabla_w psi = B w(p), exactly, boundary included
    B2, c2 = (
        torch.randn(2, 2, dtype=torch.float64, generator=g),
        torch.randn(2, dtype=torch.float64, generator=g),
    )
    w = _linear_field(v, t, B2, c2)
    e = t.edges
    mid = 0.5 * (v[e[:, 0], :2] + v[e[:, 1], :2])
    wv = mid @ B2.T + c2
    x = wv @ B.T
    x = torch.complex(x[:, 0], x[:, 1]) * _edge_frames_2d(v, t).conj()
    D = ev.covariant_derivative(v, t, w)
    M = ev.mass_matrix(v, t).to(torch.complex128)
    torch.testing.assert_close(D @ z, M @ x)
    # gradient of a linear function is its constant gradient on every edge
    a = torch.randn(2, dtype=torch.float64, generator=g)
    fv = v[:, :2] @ a
    zg = (ev.gradient(v, t) @ fv.to(torch.complex128)) / ev.mass_matrix(v, t).to_dense().diagonal()
    torch.testing.assert_close(zg, complex(a[0], a[1]) * _edge_frames_2d(v, t).conj())


def test_integral_property():
    """int_{e_i} psi_i = |e_i| X_i and the integral over the two other edges is 0 (3.2).

    Along the edge opposite corner k the barycentric coordinate of corner k is 0 and the
    mid-edge hat phi_i = 1 - 2 lambda_i; integrate with 2-point Gauss-Legendre (exact)."""
    v, f = perturbed_grid(2, 0.1, seed=6, flat=True)
    geom = ev.face_geometry(v, f)
    s = np.array([0.5 - 0.5 / 3**0.5, 0.5 + 0.5 / 3**0.5])
    for fi in range(f.shape[0]):
        for i in range(3):
            for k in range(3):
                # points on the edge opposite corner k: lambda_{k+1} = 1 - s, lambda_{k+2} = s
                lam = np.zeros((2, 3))
                lam[:, (k + 1) % 3], lam[:, (k + 2) % 3] = 1 - s, s
                phi = 1 - 2 * lam[:, i]
                integral = float(geom.lengths[fi, k]) * phi.mean()
                expected = float(geom.lengths[fi, k]) if i == k else 0.0
                assert abs(integral - expected) < 1e-14


def test_real_forms_and_curl_div_energies(open_mesh):
    v, f = open_mesh
    t = ev.Topology(f)
    L = ev.connection_laplacian(v, t)
    R = dense(ev.real_form(L))
    g = torch.Generator().manual_seed(7)
    z = torch.randn(t.num_edges, dtype=torch.complex128, generator=g)
    x = torch.cat([z.real, z.imag]).numpy()
    np.testing.assert_allclose(x @ R @ x, torch.vdot(z, L @ z).real.item(), rtol=1e-12)
    area = ev.face_areas(v, f)
    curl, div = ev.face_curl(v, t, z), ev.face_div(v, t, z)
    np.testing.assert_allclose(x @ dense(ev.curl_energy(v, t)) @ x, (area * curl**2).sum().item(), rtol=1e-12)
    np.testing.assert_allclose(x @ dense(ev.div_energy(v, t)) @ x, (area * div**2).sum().item(), rtol=1e-12)
    K = dense(ev.curl_div_operator(v, t))
    np.testing.assert_allclose(K @ z.numpy(), (area * torch.complex(curl, -div)).numpy(), atol=1e-12)


def test_cotan_and_vertex_mass(closed_mesh):
    v, f = closed_mesh
    C = dense(ev.cotan_laplacian(v, f))
    np.testing.assert_allclose(C, C.T, atol=1e-14)
    np.testing.assert_allclose(C.sum(1), 0, atol=1e-12)
    Mv, Ml = dense(ev.vertex_mass(v, f)), dense(ev.vertex_mass(v, f, lumped=True))
    np.testing.assert_allclose(Mv.sum(), ev.face_areas(v, f).sum().item())
    np.testing.assert_allclose(Mv.sum(1), Ml.diagonal(), atol=1e-15)
    # on a flat mesh the cotan Laplacian reproduces the Dirichlet energy of linear functions
    vg, fg = perturbed_grid(4, 0.1, seed=8, flat=True)
    a = np.array([0.3, -1.2])
    u = vg[:, :2].numpy() @ a
    energy = ev.face_areas(vg, fg).sum().item() * (a**2).sum()
    assert abs(u @ dense(ev.cotan_laplacian(vg, fg)) @ u - energy) < 1e-12
    assert abs(u @ dense(ev.laplace_beltrami(vg, fg)) @ u - energy) < 1e-12


def test_two_triangle_square_by_hand():
    """Unit square split along (0, 2): hand-computed scalar CR Laplacian and mass."""
    v = torch.tensor([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=torch.float64)
    f = torch.tensor([[0, 1, 2], [0, 2, 3]])
    t = ev.Topology(f)
    assert t.edges.tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]
    M = dense(ev.mass_matrix(v, t)).diagonal()
    np.testing.assert_allclose(M, [1 / 6, 1 / 3, 1 / 6, 1 / 6, 1 / 6])
    L0 = dense(ev.connection_laplacian(v, t, 0))
    # face (0,1,2), A = 1/2: diagonal |e|^2/A: edge (1,2): 2, (0,2): 4, (0,1): 2;
    # off-diagonal -|e_a||e_b|cos(alpha_c)/A: (0,1)-(1,2) meet at vertex 1 at 90 degrees -> 0;
    # (0,1)-(0,2) meet at 0 at 45 degrees: -1*sqrt2*(1/sqrt2)/(1/2) = -2
    expected = np.array(
        [[2, -2, 0, 0, 0], [-2, 8, -2, -2, -2], [0, -2, 2, 0, 0], [0, -2, 0, 2, 0], [0, -2, 0, 0, 2]], float
    )
    np.testing.assert_allclose(L0, expected, atol=1e-14)


@pytest.mark.parametrize("kind", MESHES)
def test_operator_values_gradcheck(kind, gradcheck):
    v, f = perturbed_icosphere(0, 0.1, seed=9) if kind == "closed" else perturbed_grid(2, 0.3, seed=9)
    t = ev.Topology(f)
    v = v.clone().requires_grad_()
    w = torch.randn(t.num_edges, dtype=torch.complex128, generator=torch.Generator().manual_seed(10))
    fns = [
        lambda x: ev.mass_matrix(x, t).values(),
        lambda x: torch.view_as_real(ev.connection_laplacian(x, t, 1).values()),
        lambda x: torch.view_as_real(ev.connection_laplacian(x, t, 3).values()),
        lambda x: torch.view_as_real(ev.gradient(x, t).values()),
        lambda x: ev.curl_div_operator(x, t).values(),
        lambda x: ev.laplace_beltrami(x, t).values(),
        lambda x: ev.vertex_mass(x, t).values(),
        lambda x: torch.view_as_real(ev.covariant_derivative(x, t, w).values()),
        lambda x: ev.cotan_laplacian(x, t).values(),
        lambda x: ev.curl_energy(x, t).values(),
    ]
    for fn in fns:
        assert gradcheck(fn, (v,))


def test_float32_follows_and_matches_float64(closed_mesh):
    v, f = closed_mesh
    t = ev.Topology(f)
    L64 = ev.connection_laplacian(v, t, 2)
    L32 = ev.connection_laplacian(v.float(), t, 2)
    assert L32.dtype == torch.complex64 and L64.dtype == torch.complex128
    torch.testing.assert_close(L32.to_dense().to(torch.complex128), L64.to_dense(), rtol=1e-5, atol=1e-5)
    assert ev.laplace_beltrami(v.float(), t).dtype == torch.float32
    with pytest.raises(ValueError, match="expected torch.complex64"):
        ev.covariant_derivative(v.float(), t, torch.zeros(t.num_edges, dtype=torch.complex128))


def test_reassembly_reuses_pattern_and_inputs_untouched(closed_mesh):
    from torch_edgevf.operators import kernels

    v, f = closed_mesh
    t = ev.Topology(f)
    v0, f0 = v.clone(), f.clone()
    a = ev.connection_laplacian(v, t)
    pattern = kernels.cached_pattern(t, "EE")
    b = ev.connection_laplacian(v * 2, t)
    assert kernels.cached_pattern(t, "EE") is pattern
    assert torch.equal(a.indices(), b.indices()) and b.is_coalesced()
    torch.testing.assert_close(b.values(), a.values())  # scale invariant (2D conformal)
    assert torch.equal(v, v0) and torch.equal(f, f0)


def test_bad_field_inputs(closed_mesh):
    v, f = closed_mesh
    t = ev.Topology(f)
    with pytest.raises(ValueError, match=r"shape \(E,\)"):
        ev.covariant_derivative(v, t, torch.zeros(3, dtype=torch.complex128))
    w = torch.zeros(t.num_edges, dtype=torch.complex128)
    w[5] = float("nan")
    with pytest.raises(ValueError, match=r"NaN or Inf values at edges \[5\]"):
        ev.face_curl(v, t, w)
    with pytest.raises(ValueError, match="integer >= 0"):
        ev.connection_laplacian(v, t, -1)


@pytest.mark.parametrize("mesh", ["closed", "open", "tetrahedron"])
def test_gather_patterns_match_the_generic_sorted_pattern(mesh):
    """The gather-only G (E, V) and vertex-pair (V, V) patterns equal the sort-and-sum Pattern."""
    from torch_edgevf.mesh.geometry import PAIR_A, PAIR_B
    from torch_edgevf.operators import kernels
    from torch_edgevf.operators.patterns import Pattern

    if mesh == "closed":
        v, f = perturbed_icosphere(2, seed=1)
    elif mesh == "open":
        v, f = perturbed_grid(6, seed=2)
    else:  # opposite vertices across every edge are joined by an edge
        v, f = (
            perturbed_icosphere(0, seed=3)[0][:4],
            torch.tensor([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]]),
        )
    t = ev.Topology(f, num_vertices=v.shape[0])
    fe, ff = t.face_edges.numpy(), t.faces.numpy()
    x = torch.randn(9 * t.num_faces, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    generic = {
        "EV": Pattern(fe[:, PAIR_A].T, ff[:, PAIR_B].T, (t.num_edges, t.num_vertices)),  # pair-major
        "VV": Pattern(ff[:, PAIR_A], ff[:, PAIR_B], (t.num_vertices, t.num_vertices)),  # face-major
    }
    for name, reference in generic.items():
        a, b = reference.assemble(x), kernels.cached_pattern(t, name).assemble(x)
        assert a.shape == b.shape and b.is_coalesced()
        assert torch.equal(a.indices(), b.indices()), name
        torch.testing.assert_close(b.values(), a.values(), rtol=0, atol=1e-14)


@pytest.mark.parametrize("mesh", ["tetrahedron", "octahedron", "open", "closed"])
def test_laplace_beltrami_equals_dense_product(mesh):
    """L = Re(G^H M_z^-1 G), also where a diamond's diagonal is an edge (tetrahedron) or is
    shared by two edges (octahedron)."""
    if mesh == "tetrahedron":
        v = torch.tensor([[1.0, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=torch.float64)
        f = torch.tensor([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]])
    elif mesh == "octahedron":
        v = torch.tensor(
            [[0.0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, -1]], dtype=torch.float64
        ) + 0.05 * torch.randn(6, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
        f = torch.tensor(
            [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1], [5, 2, 1], [5, 3, 2], [5, 4, 3], [5, 1, 4]]
        )
    elif mesh == "open":
        v, f = perturbed_grid(5, seed=4)
    else:
        v, f = perturbed_icosphere(1, seed=5)
    t = ev.Topology(f, num_vertices=v.shape[0])
    G = ev.gradient(v, t).to_dense()
    m = ev.mass_matrix(v, t).to_dense().diagonal()
    expected = (G.conj().T @ (G / m[:, None])).real
    L = ev.laplace_beltrami(v, t)
    assert L.is_coalesced()
    torch.testing.assert_close(L.to_dense(), expected, rtol=0, atol=1e-13)
    # the pattern is exactly the structural nonzeros of G^H G (pairs of vertices in a row of G)
    reach = (G != 0).to(torch.float64).T @ (G != 0).to(torch.float64) > 0
    pattern = torch.zeros_like(reach)
    pattern[L.indices()[0], L.indices()[1]] = True
    assert torch.equal(pattern, reach)
