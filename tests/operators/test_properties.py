"""Property-based tests: operator identities on random meshes (hypothesis).

Meshes: random Delaunay spheres (convex hulls of random points, hypothesis-chosen size and
seed), randomly perturbed grids (boundary), both with random vertex renumbering, so that
edge orientations (lower to higher index) are mixed. Identities checked densely:

* ``L_c^(n)`` Hermitian positive semi-definite with a real diagonal (``n = 0, 1, 2, 4``);
* ``curl o grad = 0`` face by face, and ``Re(M_z^{-1} G f)_e = (f_j - f_i) / |e|``;
* ``L = G^* M_z^{-1} G`` symmetric PSD with the constants in its kernel;
* ``D_w`` has a zero diagonal on closed meshes (any ``w``);
* renumbering the vertices permutes every operator consistently: with ``P`` the edge
  permutation and ``s_e = -1`` where an edge's orientation flips, an ``n``-field maps by
  ``Q_n = diag(s^n) P`` and ``L_c' = Q_n L_c Q_n^T``, ``G' = Q_1 G P_v^T``, ...;
* singularity indices sum to the Euler characteristic (closed meshes) for any field.

The default run is small (``max_examples`` ~10 per property, deterministic); set
``EDGEVF_HYPOTHESIS_EXAMPLES=200`` to explore more (random, not derandomized).
"""

from __future__ import annotations

import os

import pytest
import torch

import torch_edgevf as ev

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, assume, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_EXAMPLES = int(os.environ.get("EDGEVF_HYPOTHESIS_EXAMPLES", "0"))


def props(examples: int):
    """Small and deterministic by default; larger and random with the environment variable."""
    return settings(
        max_examples=_EXAMPLES or examples,
        deadline=None,
        derandomize=not _EXAMPLES,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )


# --------------------------------------------------------------------------- meshes


def renumber(verts: torch.Tensor, faces: torch.Tensor, seed: int):
    """New index ``perm_inv[i]`` for old vertex ``i``; returns the new mesh and ``perm_inv``."""
    g = torch.Generator().manual_seed(seed)
    perm = torch.randperm(verts.shape[0], generator=g)  # new vertex k is old vertex perm[k]
    inv = torch.empty_like(perm)
    inv[perm] = torch.arange(perm.numel())
    return verts[perm], inv[faces], inv


def _valid(verts, faces):
    try:
        ev.face_geometry(verts, faces)
    except ValueError as exc:  # a random hull may have a (near-)zero-area sliver
        assume("zero-area" not in str(exc))
        raise
    return verts, faces


@st.composite
def sphere_meshes(draw, max_points: int = 40):
    n = draw(st.integers(8, max_points))
    seed = draw(st.integers(0, 2**31 - 1))
    v, f = ev.meshes.sphere_delaunay(n, seed)
    v, f, _ = renumber(v, f, draw(st.integers(0, 2**31 - 1)))
    return _valid(v, f)


@st.composite
def grid_meshes(draw):
    nx, ny = draw(st.integers(1, 5)), draw(st.integers(1, 5))
    v, f = ev.meshes.grid(nx, ny)
    seed = draw(st.integers(0, 2**31 - 1))
    scale = draw(st.floats(0.0, 0.3))
    g = torch.Generator().manual_seed(seed)
    noise = torch.randn(v.shape, generator=g, dtype=v.dtype) * scale / max(nx, ny)
    v, f, _ = renumber(v + noise, f, seed + 1)
    return _valid(v, f)


any_meshes = st.one_of(sphere_meshes(), grid_meshes())


def dense(a: torch.Tensor) -> torch.Tensor:
    return a.to_dense()


def assert_hermitian_psd(a: torch.Tensor, what: str, rtol: float = 1e-10):
    scale = float(a.abs().max())
    herm = float((a - a.conj().T).abs().max())
    assert herm <= rtol * scale, f"{what} not Hermitian: {herm:.3g} (scale {scale:.3g})"
    evals = torch.linalg.eigvalsh((a + a.conj().T) / 2)
    assert float(evals.min()) >= -1e-9 * scale, (
        f"{what} not PSD: smallest eigenvalue {float(evals.min()):.3g}"
    )
    return evals


def random_complex(n: int, seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.complex(
        torch.randn(n, generator=g, dtype=torch.float64), torch.randn(n, generator=g, dtype=torch.float64)
    )


# --------------------------------------------------------------------------- identities


@props(12)
@given(mesh=any_meshes, n=st.sampled_from([0, 1, 2, 4]))
def test_connection_laplacian_hermitian_psd(mesh, n):
    v, f = mesh
    lc = dense(ev.connection_laplacian(v, f, n))
    assert_hermitian_psd(lc, f"L_c^({n})")
    diag = torch.diagonal(lc)
    if diag.is_complex():
        assert float(diag.imag.abs().max()) == 0.0
    assert bool((diag.real > 0).all())


@props(10)
@given(mesh=any_meshes, seed=st.integers(0, 10_000))
def test_gradient_tangential_part_and_curl_free(mesh, seed):
    v, f = mesh
    topo = ev.Topology(f, v.shape[0])
    g = torch.Generator().manual_seed(seed)
    fv = torch.randn(v.shape[0], generator=g, dtype=torch.float64)
    mass = ev.mass_matrix(v, topo).coalesce().values()
    z = (ev.gradient(v, topo) @ fv.to(torch.complex128)[:, None])[:, 0] / mass
    e = topo.edges
    length = torch.linalg.vector_norm(v[e[:, 1]] - v[e[:, 0]], dim=1)
    expected = (fv[e[:, 1]] - fv[e[:, 0]]) / length
    scale = float(expected.abs().max())
    torch.testing.assert_close(z.real, expected, atol=1e-10 * scale, rtol=0)
    curl = ev.face_curl(v, topo, z)
    area = ev.face_areas(v, topo)
    # circulation per face (curl * area) relative to the sizes in play
    circ = (curl * area).abs().max()
    assert float(circ) <= 1e-10 * scale * float(length.max()), float(circ)


@props(10)
@given(mesh=any_meshes)
def test_laplace_beltrami_symmetric_psd_constants_in_kernel(mesh):
    v, f = mesh
    lap = dense(ev.laplace_beltrami(v, f))
    assert lap.dtype == torch.float64
    evals = assert_hermitian_psd(lap, "L")
    ones = torch.ones(v.shape[0], dtype=torch.float64)
    assert float((lap @ ones).abs().max()) <= 1e-10 * float(lap.abs().max())
    # on a connected mesh the kernel is exactly the constants
    assert float(evals[1]) > 1e-8 * float(evals[-1])


@props(10)
@given(mesh=sphere_meshes(), seed=st.integers(0, 10_000))
def test_covariant_derivative_zero_diagonal_on_closed_meshes(mesh, seed):
    v, f = mesh
    topo = ev.Topology(f, v.shape[0])
    w = random_complex(topo.num_edges, seed)
    d = dense(ev.covariant_derivative(v, topo, w))
    scale = float(d.abs().max())
    assert float(torch.diagonal(d).abs().max()) <= 1e-12 * scale


# --------------------------------------------------------------------------- renumbering


def edge_map(topo_old: ev.Topology, topo_new: ev.Topology, inv: torch.Tensor):
    """For each old edge: its index in the new mesh and the orientation sign (+-1)."""
    a, b = inv[topo_old.edges[:, 0]], inv[topo_old.edges[:, 1]]
    sign = torch.where(a < b, 1.0, -1.0).to(torch.float64)
    lo, hi = torch.minimum(a, b), torch.maximum(a, b)
    nv = topo_new.num_vertices
    keys_new = topo_new.edges[:, 0] * nv + topo_new.edges[:, 1]
    pos = torch.searchsorted(keys_new, lo * nv + hi)
    assert bool((keys_new[pos] == lo * nv + hi).all())
    return pos, sign


def embed(perm: torch.Tensor, sign: torch.Tensor, size: int) -> torch.Tensor:
    """``Q`` with ``Q[perm[e], e] = sign[e]`` (maps old coordinates to new ones)."""
    q = torch.zeros(size, perm.numel(), dtype=torch.float64)
    q[perm, torch.arange(perm.numel())] = sign
    return q


@props(10)
@given(mesh=any_meshes, seed=st.integers(0, 2**31 - 1), n=st.sampled_from([1, 2, 3, 4]))
def test_renumbering_permutes_operators(mesh, seed, n):
    v, f = mesh
    topo = ev.Topology(f, v.shape[0])
    v2, f2, inv = renumber(v, f, seed)
    topo2 = ev.Topology(f2, v2.shape[0])
    pos, sign = edge_map(topo, topo2, inv)
    ne, nv = topo.num_edges, topo.num_vertices
    q1 = embed(pos, sign, ne).to(torch.complex128)
    qn = embed(pos, sign**n, ne).to(torch.complex128)
    pe = embed(pos, torch.ones(ne, dtype=torch.float64), ne)
    pv = embed(inv, torch.ones(nv, dtype=torch.float64), nv)

    def close(new, old_mapped, what):
        scale = float(old_mapped.abs().max()) or 1.0
        err = float((new - old_mapped).abs().max())
        assert err <= 1e-12 * scale, f"{what}: renumbered operator differs by {err:.3g}"

    close(
        dense(ev.connection_laplacian(v2, topo2, n)),
        qn @ dense(ev.connection_laplacian(v, topo, n)) @ qn.T,
        f"L_c^({n})",
    )
    close(dense(ev.mass_matrix(v2, topo2)), pe @ dense(ev.mass_matrix(v, topo)) @ pe.T, "M_z")
    close(dense(ev.gradient(v2, topo2)), q1 @ dense(ev.gradient(v, topo)) @ pv.T.to(torch.complex128), "G")
    close(dense(ev.laplace_beltrami(v2, topo2)), pv @ dense(ev.laplace_beltrami(v, topo)) @ pv.T, "L")
    close(dense(ev.vertex_mass(v2, topo2)), pv @ dense(ev.vertex_mass(v, topo)) @ pv.T, "M_v")
    w = random_complex(ne, seed % 10_000)
    close(
        dense(ev.covariant_derivative(v2, topo2, q1 @ w)),
        q1 @ dense(ev.covariant_derivative(v, topo, w)) @ q1.T,
        "D_w",
    )
    # face operators: faces keep their order, so K only sees the edge map
    k_old = dense(ev.curl_div_operator(v, topo))
    close(dense(ev.curl_div_operator(v2, topo2)), k_old @ embed(pos, sign, ne).T, "K")


@props(8)
@given(mesh=sphere_meshes(), seed=st.integers(0, 2**31 - 1), n=st.sampled_from([1, 2, 4]))
def test_singularities_sum_to_euler_characteristic_and_follow_renumbering(mesh, seed, n):
    sing = pytest.importorskip("torch_edgevf.fields.singularities")
    v, f = mesh
    topo = ev.Topology(f, v.shape[0])
    z = random_complex(topo.num_edges, seed % 10_000)
    s = sing.singularities(v, topo, z, n)
    assert s.total == topo.euler_characteristic == 2
    v2, f2, inv = renumber(v, f, seed)
    topo2 = ev.Topology(f2, v2.shape[0])
    pos, sign = edge_map(topo, topo2, inv)
    z2 = torch.zeros_like(z)
    z2[pos] = z * sign.to(torch.complex128) ** n
    s2 = sing.singularities(v2, topo2, z2, n)
    assert torch.equal(s2.face_index, s.face_index)
    assert torch.equal(s2.vertex_index[inv], s.vertex_index)


@props(6)
@given(mesh=any_meshes)
def test_module_matches_functions(mesh):
    v, f = mesh
    op = ev.EdgeOperators(v, f, n=2)
    for name, fn in (
        ("connection_laplacian", lambda: ev.connection_laplacian(v, f, 2)),
        ("gradient", lambda: ev.gradient(v, f)),
        ("laplace_beltrami", lambda: ev.laplace_beltrami(v, f)),
    ):
        torch.testing.assert_close(dense(getattr(op, name)), dense(fn()), rtol=1e-12, atol=1e-12)
