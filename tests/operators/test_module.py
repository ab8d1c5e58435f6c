"""EdgeOperators: the module agrees with the functions, converts dtypes, round-trips."""

import io

import pytest
import torch

import torch_edgevf as ev

from conftest import perturbed_icosphere


@pytest.fixture
def mesh():
    return perturbed_icosphere(1, 0.05, seed=11)


def test_module_matches_functions(mesh):
    v, f = mesh
    ops = ev.EdgeOperators(v, f, n=2)
    t = ops.topology
    pairs = {
        "mass": ev.mass_matrix(v, t),
        "connection_laplacian": ev.connection_laplacian(v, t, 2),
        "gradient": ev.gradient(v, t),
        "curl_div": ev.curl_div_operator(v, t),
        "laplace_beltrami": ev.laplace_beltrami(v, t),
        "vertex_mass": ev.vertex_mass(v, t),
        "lumped_vertex_mass": ev.vertex_mass(v, t, lumped=True),
    }
    for name, expected in pairs.items():
        got = getattr(ops, name)
        assert got.is_sparse and got.is_coalesced(), name
        torch.testing.assert_close(got.to_dense(), expected.to_dense(), msg=name)
    torch.testing.assert_close(ops.edges, t.edges)
    torch.testing.assert_close(ops.edge_length, ev.edge_lengths(v, t))
    w = torch.randn(t.num_edges, dtype=torch.complex128)
    torch.testing.assert_close(
        ops.covariant_derivative(w).to_dense(), ev.covariant_derivative(v, t, w).to_dense()
    )
    torch.testing.assert_close(
        ops.connection_laplacian_n(0).to_dense(), ev.connection_laplacian(v, t, 0).to_dense()
    )


def test_float32_conversion_keeps_imaginary_parts(mesh):
    v, f = mesh
    ops = ev.EdgeOperators(v, f)
    L64 = ops.connection_laplacian.to_dense()
    ops32 = ev.EdgeOperators(v, f).to(torch.float32)
    assert ops32.connection_laplacian.dtype == torch.complex64
    assert ops32.mass.dtype == torch.float32 and ops32.verts.dtype == torch.float32
    assert ops32.edges.dtype == torch.int64
    torch.testing.assert_close(ops32.connection_laplacian.to_dense(), L64.to(torch.complex64))
    back = ops32.double()
    assert back.gradient.dtype == torch.complex128 and back.mass.dtype == torch.float64
    assert ev.EdgeOperators(v.float(), f).connection_laplacian.dtype == torch.complex64
    with pytest.raises(ValueError, match="floating dtype"):
        ops.to(torch.int32)


def test_state_dict_round_trip(mesh):
    v, f = mesh
    ops = ev.EdgeOperators(v, f)
    buf = io.BytesIO()
    torch.save(ops.state_dict(), buf)
    buf.seek(0)
    state = torch.load(buf, weights_only=True)
    other = ev.EdgeOperators(v * 1.5, f)
    other.load_state_dict(state)
    for name in ("mass", "connection_laplacian", "laplace_beltrami", "gradient"):
        torch.testing.assert_close(getattr(other, name).to_dense(), getattr(ops, name).to_dense())


def test_update_and_gradients_flow_to_vertices(mesh):
    v, f = mesh
    ops = ev.EdgeOperators(v, f)
    v2 = (v * torch.tensor([1.0, 0.8, 1.2], dtype=v.dtype)).requires_grad_()
    ops.update(v2)
    fresh = ev.EdgeOperators(v2.detach(), f)
    torch.testing.assert_close(ops.laplace_beltrami.to_dense(), fresh.laplace_beltrami.to_dense())
    z = torch.randn(ops.num_edges, dtype=torch.complex128)
    energy = torch.vdot(z, ops.connection_laplacian @ z).real + ops.mass.values().sum()
    energy.backward()
    assert v2.grad is not None and torch.isfinite(v2.grad).all() and v2.grad.abs().sum() > 0


def test_bad_arguments(mesh):
    v, f = mesh
    with pytest.raises(ValueError, match="integer >= 0"):
        ev.EdgeOperators(v, f, n=-2)
    with pytest.raises(ValueError, match="rows but the topology"):
        ev.EdgeOperators(v[:-1], ev.Topology(f))
    assert "E=120" in repr(ev.EdgeOperators(v, f))


def test_failed_update_keeps_the_previous_operators():
    v, f = ev.icosphere(1)
    ops = ev.EdgeOperators(v, f)
    before = {name: buf.clone() for name, buf in ops.named_buffers()}
    bad = v.clone()
    bad[3, 0] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        ops.update(bad)
    degenerate = v.clone()
    degenerate[f[5]] = v[f[5, 0]]  # three corners at one point: zero-area faces
    with pytest.raises(ValueError, match="zero-area"):
        ops.update(degenerate)
    for name, buf in ops.named_buffers():
        b = before[name]
        same = torch.equal(buf.to_dense(), b.to_dense()) if buf.is_sparse else torch.equal(buf, b)
        assert same, name
