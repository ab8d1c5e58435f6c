"""Learning layers (torch_edgevf.learning.layers) and the networks on them (torch_edgevf.learning.models).

Properties: exactness against dense references (matrix exponential, dense solves, the
finite-difference identity of the gradient), gauge equivariance of every layer, module and
function agreement, gradcheck in float64, and invariance of the networks to rigid motions
and vertex renumbering.
"""

import numpy as np
import pytest
import scipy.linalg
import torch

import torch_edgevf as ev
from torch_edgevf import learning
from torch_edgevf.learning import layers as enn
from torch_edgevf.learning import models

from conftest import perturbed_icosphere


@pytest.fixture(scope="module")
def mesh():
    v, f = perturbed_icosphere(1, 0.05, seed=1)
    topo = ev.Topology(f, v.shape[0])
    L = ev.connection_laplacian(v, topo, 1)
    m = ev.mass_matrix(v, topo).values()
    w, X = scipy.linalg.eigh(L.to_dense().numpy(), np.diag(m.numpy()))
    return dict(v=v, f=f, topo=topo, L=L, m=m, evals=torch.tensor(w), evecs=torch.tensor(X))


def _z(n, c, seed=0, dtype=torch.complex128):
    g = torch.Generator().manual_seed(seed)
    return torch.randn(n, c, generator=g, dtype=dtype)


def _phases(n, seed=1):
    g = torch.Generator().manual_seed(seed)
    return torch.polar(
        torch.ones(n, dtype=torch.float64), 2 * np.pi * torch.rand(n, generator=g, dtype=torch.float64)
    )


# --------------------------------------------------------------------------- diffusion


def test_spectral_diffusion_full_basis_is_matrix_exponential(mesh):
    z, t = _z(mesh["topo"].num_edges, 3), torch.tensor([0.01, 0.1, 0.5], dtype=torch.float64)
    out = enn.spectral_diffusion(z, mesh["evals"], mesh["evecs"], mesh["m"], t)
    A = np.diag(1 / mesh["m"].numpy()) @ mesh["L"].to_dense().numpy()
    ref = np.stack([scipy.linalg.expm(-t[c].item() * A) @ z[:, c].numpy() for c in range(3)], 1)
    np.testing.assert_allclose(out.numpy(), ref, atol=1e-10)


def test_spectral_diffusion_truncated_is_projection_at_zero(mesh):
    k = 10
    phi, m = mesh["evecs"][:, :k], mesh["m"]
    z = _z(mesh["topo"].num_edges, 2)
    out = enn.spectral_diffusion(z, mesh["evals"][:k], phi, m, torch.zeros(2, dtype=torch.float64))
    again = enn.spectral_diffusion(out, mesh["evals"][:k], phi, m, torch.zeros(2, dtype=torch.float64))
    torch.testing.assert_close(again, out)  # a projector
    # and independent of the phase of each eigenvector
    rotated = phi * _phases(k)[None, :]
    torch.testing.assert_close(
        enn.spectral_diffusion(z, mesh["evals"][:k], rotated, m, torch.ones(2, dtype=torch.float64)),
        enn.spectral_diffusion(z, mesh["evals"][:k], phi, m, torch.ones(2, dtype=torch.float64)),
    )


def test_spectral_diffusion_batch_matches_single(mesh):
    k = 8
    z1, z2 = _z(mesh["topo"].num_edges, 2, 0), _z(mesh["topo"].num_edges, 2, 1)
    t = torch.tensor([0.05, 0.2], dtype=torch.float64)
    ev_, phi, m = mesh["evals"][:k], mesh["evecs"][:, :k], mesh["m"]
    single = [enn.spectral_diffusion(z, ev_, phi, m, t) for z in (z1, z2)]
    ne = z1.shape[0]
    batched = enn.spectral_diffusion(
        torch.cat([z1, z2]),
        torch.stack([ev_, ev_]),
        torch.cat([phi, phi]),
        torch.cat([m, m]),
        t,
        offsets=[0, ne, 2 * ne],
    )
    torch.testing.assert_close(batched, torch.cat(single))


def test_implicit_diffusion_matches_dense_solve(mesh):
    z, t = _z(mesh["topo"].num_edges, 2), torch.tensor([0.05, 0.3], dtype=torch.float64)
    out = enn.implicit_diffusion(z, mesh["L"], mesh["m"], t)
    Ld, M = mesh["L"].to_dense().numpy(), np.diag(mesh["m"].numpy())
    ref = np.stack([np.linalg.solve(M + t[c].item() * Ld, M @ z[:, c].numpy()) for c in range(2)], 1)
    np.testing.assert_allclose(out.detach().numpy(), ref, atol=1e-10)


def test_diffusion_gradcheck(mesh, gradcheck):
    k = 6
    z = _z(mesh["topo"].num_edges, 2).requires_grad_()
    t = torch.tensor([0.05, 0.3], dtype=torch.float64, requires_grad=True)
    evals, phi, m = mesh["evals"][:k], mesh["evecs"][:, :k], mesh["m"]
    assert gradcheck(lambda z, t: enn.spectral_diffusion(z, evals, phi, m, t), (z, t))
    assert gradcheck(lambda z, t: enn.implicit_diffusion(z, mesh["L"], m, t), (z, t))


def test_learned_diffusion_module_wraps_functions(mesh):
    k = 8
    z = _z(mesh["topo"].num_edges, 3).to(torch.complex64)
    for method in ("spectral", "implicit"):
        layer = enn.LearnedDiffusion(3, method=method)
        assert bool((layer.times > 0).all())
        t = layer.times
        if method == "spectral":
            out = layer(
                z,
                mesh["m"].float(),
                evals=mesh["evals"][:k].float(),
                evecs=mesh["evecs"][:, :k].to(torch.complex64),
            )
            ref = enn.spectral_diffusion(
                z, mesh["evals"][:k].float(), mesh["evecs"][:, :k].to(torch.complex64), mesh["m"].float(), t
            )
        else:
            L = mesh["L"].to(torch.complex64)
            out = layer(z, mesh["m"].float(), L=L)
            ref = enn.implicit_diffusion(z, L, mesh["m"].float(), t)
        assert out.dtype == torch.complex64
        torch.testing.assert_close(out, ref)
        out.abs().sum().backward()
        assert layer.raw_times.grad is not None and torch.isfinite(layer.raw_times.grad).all()
    abs_layer = enn.LearnedDiffusion(2, positivity="abs", init_times=0.1)
    torch.testing.assert_close(abs_layer.times, torch.full((2,), 0.1))


def test_clamped_times_start_at_zero_and_pass_the_gradient():
    layer = enn.LearnedDiffusion(3, positivity="clamp")
    torch.testing.assert_close(layer.times, torch.full((3,), enn.MIN_TIME))  # initial raw time 0
    layer.times.sum().backward()  # straight through: the clamp does not stop the gradient
    torch.testing.assert_close(layer.raw_times.grad, torch.ones(3))
    with torch.no_grad():
        layer.raw_times.copy_(torch.tensor([-1.0, 0.0, 0.5]))
    torch.testing.assert_close(layer.times.detach(), torch.tensor([enn.MIN_TIME, enn.MIN_TIME, 0.5]))
    with pytest.raises(ValueError, match="positive"):
        enn.LearnedDiffusion(2, init_times=0.0)  # zero only with the clamp
    with pytest.raises(ValueError, match="mode"):
        enn.positive_time(torch.zeros(1), "relu")


# --------------------------------------------------------------------------- gradient features


def test_gradient_features_finite_difference_and_adjoint(mesh):
    v, topo = mesh["v"], mesh["topo"]
    G = ev.gradient(v, topo)
    f = torch.randn(v.shape[0], 2, dtype=torch.float64)
    z = enn.gradient_features(f, G, mesh["m"])
    e = topo.edges
    length = (v[e[:, 1]] - v[e[:, 0]]).norm(dim=1)
    torch.testing.assert_close(z.real, (f[e[:, 1]] - f[e[:, 0]]) / length[:, None])  # thesis (4.1)
    w = _z(topo.num_edges, 2)
    mv = ev.vertex_mass(v, topo, lumped=True).values()
    dc = enn.divergence_features(w, G, mv)
    div, curl = ev.vertex_div_curl(v, topo, w)
    torch.testing.assert_close(dc.real, div)
    torch.testing.assert_close(dc.imag, curl)
    # adjointness: <grad f, w>_{M_z} = f^T G^H w = -f^T M_v (div + i curl)
    lhs = ((mesh["m"][:, None] * z).conj() * w).sum()
    rhs = -(f * mv[:, None] * dc).sum()
    torch.testing.assert_close(lhs, rhs)
    # curl of a gradient vanishes at every vertex
    assert enn.divergence_features(z, G, mv).imag.abs().max() < 1e-10
    assert torch.equal(enn.GradientFeatures()(f, G, mesh["m"]), z)
    assert torch.equal(enn.DivergenceFeatures()(w, G, mv), dc)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_gradient_and_divergence_features_are_the_quotients_bit_for_bit(mesh, dtype):
    """The features multiply by the reciprocal masses: the numbers of dividing by them."""
    from torch_edgevf.learning.layers.sparse import _spmm

    v, topo = mesh["v"], mesh["topo"]
    G = ev.gradient(v.to(dtype), topo)
    m, mv = mesh["m"].to(dtype), ev.vertex_mass(v, topo, lumped=True).values().to(dtype)
    f = torch.randn(v.shape[0], 3, dtype=dtype)
    w = _z(topo.num_edges, 3, dtype=G.dtype)
    assert torch.equal(enn.gradient_features(f, G, m), enn.gradient_features(f, G) / m[:, None])
    assert torch.equal(enn.divergence_features(w, G, mv), -_spmm(G, w, adjoint=True) / mv[:, None])


def test_adjoint_on_basis_gives_the_gradient_coefficients_and_the_divergence(mesh):
    """``G^H Phi``: the divergence and curl of fields in the span of an ``M_z``-orthonormal
    basis, and the coefficients of gradient fields; computed once for constant operators."""
    from torch_edgevf.learning.layers.sparse import _BASIS_CACHE, adjoint_on_basis

    v, topo, m = mesh["v"], mesh["topo"], mesh["m"]
    G = ev.gradient(v, topo)
    phi = mesh["evecs"][:, :6].to(G.dtype)
    mv = ev.vertex_mass(v, topo, lumped=True).values()
    basis = adjoint_on_basis(G, phi)
    torch.testing.assert_close(basis, G.to_dense().mH @ phi)
    c = _z(6, 3)
    torch.testing.assert_close(-(basis @ c) / mv[:, None], enn.divergence_features(phi @ c, G, mv))
    f = torch.randn(v.shape[0], 3, dtype=torch.float64)
    coeffs = phi.mH @ (m[:, None] * enn.gradient_features(f, G, m))
    torch.testing.assert_close(basis.mH @ f.to(basis.dtype), coeffs)
    assert adjoint_on_basis(G, phi) is basis  # kept for the pair
    key = (id(G), id(phi))
    del G
    assert key not in _BASIS_CACHE  # and let go with its operator


def test_adjoint_on_basis_is_differentiable_in_the_operators(mesh, gradcheck):
    from torch_edgevf.learning.layers import adjoint_on_basis

    G = ev.gradient(mesh["v"], mesh["topo"]).coalesce()
    vals = G.values().detach().clone().requires_grad_(True)
    phi = mesh["evecs"][:, :3].to(G.dtype).clone().requires_grad_(True)

    def f(vals, phi):
        A = torch.sparse_coo_tensor(G.indices(), vals, G.shape, is_coalesced=True)
        return torch.view_as_real(adjoint_on_basis(A, phi))

    assert gradcheck(f, (vals, phi))


def test_gradient_features_gradcheck(mesh, gradcheck):
    G = ev.gradient(mesh["v"], mesh["topo"])
    f = torch.randn(mesh["v"].shape[0], 2, dtype=torch.float64, requires_grad=True)
    w = _z(mesh["topo"].num_edges, 2).requires_grad_()
    mv = ev.vertex_mass(mesh["v"], mesh["topo"], lumped=True).values()
    assert gradcheck(lambda f: enn.gradient_features(f, G, mesh["m"]), (f,))
    assert gradcheck(lambda w: enn.divergence_features(w, G, mv), (w,))


@pytest.mark.parametrize("dtype", [torch.complex128, torch.complex64, torch.float64])
def test_sparse_product_of_constant_operator_equals_gather(mesh, dtype):
    """The CSR product of a constant operator and the gather product agree, values and gradients."""
    from torch_edgevf.learning.layers.sparse import _CSR_CACHE, _spmm

    G = ev.gradient(mesh["v"], mesh["topo"]).coalesce()
    if not dtype.is_complex:
        G = torch.sparse_coo_tensor(G.indices(), G.values().real, G.shape).coalesce()
    G = G.to(dtype)
    tracked = torch.sparse_coo_tensor(G.indices(), G.values().clone().requires_grad_(), G.shape).coalesce()
    gen = torch.Generator().manual_seed(3)
    for adjoint, n in ((False, G.shape[1]), (True, G.shape[0])):
        x = torch.randn(n, 3, dtype=dtype, generator=gen).requires_grad_()
        y_fast = _spmm(G, x, adjoint=adjoint)
        y_ref = _spmm(tracked, x, adjoint=adjoint)
        tol = dict(rtol=1e-5, atol=1e-5) if dtype == torch.complex64 else dict(rtol=1e-12, atol=1e-12)
        torch.testing.assert_close(y_fast, y_ref, **tol)
        w = torch.randn(y_ref.shape, dtype=dtype, generator=gen)
        (g_fast,) = torch.autograd.grad((y_fast * w.conj()).real.sum(), x)
        (g_ref,) = torch.autograd.grad((y_ref * w.conj()).real.sum(), x)
        torch.testing.assert_close(g_fast, g_ref, **tol)
    assert id(G) in _CSR_CACHE  # converted once, kept with the operator
    key = id(G)
    del G
    assert key not in _CSR_CACHE


# --------------------------------------------------------------------------- pointwise layers


def test_pointwise_layers_are_gauge_equivariant():
    torch.manual_seed(0)
    z = _z(50, 4).to(torch.complex64)
    u = _phases(50).to(torch.complex64)[:, None]
    lin, act, read = enn.ComplexLinear(4, 3), enn.ModReLU(4, bias=-0.3), enn.InvariantReadout(4)
    torch.testing.assert_close(lin(u * z), u * lin(z))
    torch.testing.assert_close(act(u * z), u * act(z))
    torch.testing.assert_close(read(u * z), read(z))
    assert read(z).shape == (50, 8) and not read(z).is_complex()
    # modules wrap functions
    torch.testing.assert_close(lin(z), enn.complex_linear(z, torch.view_as_complex(lin.weight)))
    torch.testing.assert_close(act(z), enn.modulus_relu(z, act.bias))
    torch.testing.assert_close(read(z), enn.invariant_features(z, read.weight))
    # ModReLU: modulus relu(|z| + b), phase kept
    out = enn.modulus_relu(z, torch.full((4,), -0.3))
    torch.testing.assert_close(out.abs(), torch.relu(z.abs() - 0.3))
    keep = out.abs() > 0
    torch.testing.assert_close(torch.angle(out[keep]), torch.angle(z[keep]))


def test_modulus_relu_is_safe_at_zero():
    z = torch.zeros(3, 2, dtype=torch.complex128, requires_grad=True)
    for b in (-0.5, 0.0, 0.5):
        out = enn.modulus_relu(z, torch.full((2,), b, dtype=torch.float64))
        assert torch.equal(out.detach(), torch.zeros_like(out))
        (g,) = torch.autograd.grad(out.abs().sum() + out.real.sum(), z)
        assert torch.isfinite(torch.view_as_real(g)).all()


def test_pointwise_gradcheck():
    z = _z(6, 3).requires_grad_()
    w = _z(3, 3, seed=2).requires_grad_()
    b = torch.tensor([-0.2, 0.1, -1.0], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(enn.complex_linear, (z, w))
    assert torch.autograd.gradcheck(lambda z, b: enn.modulus_relu(z, b), (z, b))
    assert torch.autograd.gradcheck(lambda z, w: enn.invariant_features(z, w), (z, w))


def test_normalize_modulus():
    z = _z(20, 2)
    w = torch.rand(20, dtype=torch.float64) + 0.1
    batch = torch.tensor([0] * 8 + [1] * 12)
    out = enn.normalize_modulus(z * 7, w, batch)
    power = enn.pool_global(out.abs() ** 2, w, batch)
    torch.testing.assert_close(power, torch.ones(2, 2, dtype=torch.float64), atol=1e-6, rtol=1e-6)
    torch.testing.assert_close(enn.ModulusNorm()(z, w, batch), enn.normalize_modulus(z, w, batch))


# --------------------------------------------------------------------------- dropout


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("p", [0.5, 0.1, 0.7, 1e-9])
@pytest.mark.parametrize("transposed", [False, True])
def test_dropout_is_torch_dropout_seed_for_seed(dtype, p, transposed):
    """The same outputs, gradients and generator state afterwards as ``F.dropout``."""
    x = torch.randn(37, 29, dtype=dtype)
    if transposed:
        x = x.t()
    runs = []
    for fn in (torch.nn.functional.dropout, enn.dropout):
        xg = x.clone().requires_grad_()
        torch.manual_seed(3)
        out = fn(xg, p, True)
        (out * torch.arange(out.numel(), dtype=dtype).view_as(out)).sum().backward()
        runs.append((out.detach(), xg.grad, torch.rand(4)))
    for a, b in zip(*runs):
        assert torch.equal(a, b)
    kept = (runs[1][0] != 0).double().mean()
    assert abs(float(kept) - (1 - p)) < 0.05


def test_dropout_module_and_the_cases_it_leaves_to_torch():
    x = torch.randn(50, 8, dtype=torch.float64)
    layer = enn.Dropout(0.5)
    torch.manual_seed(0)
    a = layer(x)
    torch.manual_seed(0)
    assert torch.equal(a, torch.nn.Dropout(0.5)(x))
    assert torch.equal(layer.eval()(x), x)
    assert torch.equal(enn.dropout(x, 0.0), x)
    assert torch.equal(enn.dropout(x, 1.0), torch.zeros_like(x))
    torch.manual_seed(0)
    a = enn.dropout(x, np.float32(0.25))  # any real number
    torch.manual_seed(0)
    assert torch.equal(a, torch.nn.functional.dropout(x, 0.25))
    # complex entries are kept or dropped whole, with the mask of their real parts
    z = _z(50, 8)
    torch.manual_seed(0)
    a = enn.dropout(z, 0.5)
    torch.manual_seed(0)
    assert torch.equal(a.real, enn.dropout(z.real, 0.5)) and torch.equal(a.imag == 0, a.real == 0)
    phases = _phases(50)[:, None]
    torch.manual_seed(0)
    b = enn.dropout(z * phases, 0.5)
    torch.testing.assert_close(b, a * phases)  # gauge equivariant
    before = x.clone()
    enn.dropout(x, 0.5)
    assert torch.equal(x, before)  # the input is left alone
    for bad in (-0.1, 1.5, True, "a"):
        with pytest.raises(ValueError, match="p must be a probability"):
            enn.dropout(x, bad)
    with pytest.raises(ValueError, match="x must be a floating or complex tensor"):
        enn.dropout(torch.ones(3, dtype=torch.int64), 0.5)


def test_networks_use_the_fast_dropout():
    for net in (models.EdgeFieldNet(4, 3), models.DiffusionNet(4, 3)):
        layers = [m for m in net.modules() if isinstance(m, torch.nn.Dropout)]
        assert layers and all(isinstance(m, enn.Dropout) for m in layers)


# --------------------------------------------------------------------------- pooling


def test_pooling(mesh):
    topo = mesh["topo"]
    w = mesh["m"]
    x = torch.randn(topo.num_edges, 3, dtype=torch.float64)
    const = torch.ones(topo.num_edges, 2, dtype=torch.float64)
    for out in (
        enn.pool_edges_to_vertices(const, topo.edges, topo.num_vertices, w),
        enn.pool_edges_to_faces(const, topo.face_edges, w),
        enn.pool_global(const, w),
    ):
        torch.testing.assert_close(out, torch.ones_like(out))
    pv = enn.pool_edges_to_vertices(x, topo.edges, topo.num_vertices, w)
    vtx = 5
    inc = ((topo.edges == vtx).any(1)).nonzero().flatten()
    torch.testing.assert_close(pv[vtx], (w[inc, None] * x[inc]).sum(0) / w[inc].sum())
    pf = enn.pool_edges_to_faces(x, topo.face_edges, w)
    fe = topo.face_edges[7]
    torch.testing.assert_close(pf[7], (w[fe, None] * x[fe]).sum(0) / w[fe].sum())
    torch.testing.assert_close(enn.pool_global(x, w), ((w[:, None] * x).sum(0) / w.sum())[None])
    # modules wrap functions
    torch.testing.assert_close(
        enn.EdgePooling("vertex")(x, w, edges=topo.edges, num_vertices=topo.num_vertices), pv
    )
    torch.testing.assert_close(enn.EdgePooling("face")(x, w, face_edges=topo.face_edges), pf)
    torch.testing.assert_close(enn.EdgePooling("global")(x, w), enn.pool_global(x, w))


def test_pooling_to_vertices_by_the_cached_matrix_is_the_weighted_mean(mesh):
    """Constant weights take the cached sparse matrix, weights with a gradient the sums;
    both give the weighted mean at every vertex, 0 at a vertex without edges, and the
    same gradient in ``x``."""
    from torch_edgevf.learning.layers.pooling import _POOL_CACHE

    topo = mesh["topo"]
    n = topo.num_vertices + 1  # one more vertex, on no edge
    w = mesh["m"].clone()
    x = torch.randn(topo.num_edges, 3, dtype=torch.float64, requires_grad=True)
    cached = enn.pool_edges_to_vertices(x, topo.edges, n, w)
    assert (id(topo.edges), id(w), n) in _POOL_CACHE
    summed = enn.pool_edges_to_vertices(x, topo.edges, n, w.clone().requires_grad_(True))
    want = torch.stack(
        [
            (w[inc, None] * x[inc]).sum(0) / w[inc].sum() if len(inc) else x.new_zeros(3)
            for inc in (((topo.edges == v).any(1)).nonzero().flatten() for v in range(n))
        ]
    )
    torch.testing.assert_close(cached, want)
    torch.testing.assert_close(summed, want)
    g = torch.randn(n, 3, dtype=torch.float64)
    for out in (cached, summed):
        got, ref = (torch.autograd.grad(o, x, g, retain_graph=True)[0] for o in (out, want))
        torch.testing.assert_close(got, ref)
    bad = topo.edges.clone()
    bad[3, 1] = n
    with pytest.raises(ValueError, match=r"edges must hold vertex indices in \[0, "):
        enn.pool_edges_to_vertices(x, bad, n, w)


# --------------------------------------------------------------------------- errors


def test_errors(mesh):
    ne = mesh["topo"].num_edges
    z = _z(ne, 2)
    t = torch.ones(2, dtype=torch.float64)
    with pytest.raises(ValueError, match="shape"):
        enn.spectral_diffusion(z[:, 0], mesh["evals"], mesh["evecs"], mesh["m"], t)
    with pytest.raises(ValueError, match="times"):
        enn.spectral_diffusion(z, mesh["evals"], mesh["evecs"], mesh["m"], torch.ones(3, dtype=torch.float64))
    with pytest.raises(ValueError, match="mass"):
        enn.spectral_diffusion(z, mesh["evals"], mesh["evecs"], mesh["m"][:-1], t)
    with pytest.raises(ValueError, match="offsets"):
        enn.spectral_diffusion(z, mesh["evals"][None], mesh["evecs"], mesh["m"], t, offsets=[0, 5])
    with pytest.raises(ValueError, match="complex"):
        enn.complex_linear(z.real, torch.ones(2, 2, dtype=torch.complex128))
    with pytest.raises(ValueError, match="weight"):
        enn.complex_linear(z, torch.ones(3, 2, dtype=torch.complex128))
    with pytest.raises(ValueError, match="sparse"):
        enn.gradient_features(torch.ones(42, 1, dtype=torch.float64), torch.ones(ne, 42), mesh["m"])
    with pytest.raises(ValueError, match="bias"):
        enn.modulus_relu(z, torch.ones(3, dtype=torch.float64))
    with pytest.raises(ValueError, match="method"):
        enn.LearnedDiffusion(2, method="euler")
    with pytest.raises(ValueError, match="positive"):
        enn.LearnedDiffusion(2, init_times=-1.0)
    with pytest.raises(ValueError, match="to must be"):
        enn.EdgePooling("edge")
    with pytest.raises(ValueError, match="head"):
        models.EdgeFieldNet(4, 2, head="edge")


# --------------------------------------------------------------------------- networks


def _sample(v, f, k_edge=24, k_vertex=16):
    o = learning.compute_operators(v, f, k_edge=k_edge, k_vertex=k_vertex, vertex_gradient=True)
    x = learning.heat_kernel_signature(o.vertex_evals, o.vertex_evecs, count=8, area=o.face_area.sum())
    return learning.MeshSample(o, x, 0)


@pytest.fixture(scope="module")
def moved_pair():
    v, f = perturbed_icosphere(2, 0.05, seed=3, renumber=False)
    g = torch.Generator().manual_seed(5)
    Q, _ = torch.linalg.qr(torch.randn(3, 3, generator=g, dtype=torch.float64))
    perm = torch.randperm(v.shape[0], generator=g)
    inv = torch.empty_like(perm)
    inv[perm] = torch.arange(perm.numel())
    fperm = torch.randperm(f.shape[0], generator=g)
    v2 = (v @ Q.T + torch.tensor([0.5, -2.0, 3.0], dtype=torch.float64))[perm]
    f2 = inv[f][fperm]
    return _sample(v, f), _sample(v2, f2), inv, fperm


@pytest.mark.parametrize("model", [models.EdgeFieldNet, models.DiffusionNet])
@pytest.mark.parametrize("head", ["global", "vertex", "face"])
def test_networks_invariant_to_rigid_motion_and_renumbering(moved_pair, model, head):
    s1, s2, inv, fperm = moved_pair
    torch.manual_seed(0)
    net = model(8, 5, width=8, num_blocks=2, head=head).double().eval()  # no dropout
    y1 = net(learning.MeshBatch.from_operators(s1.operators, s1.features))
    y2 = net(learning.MeshBatch.from_operators(s2.operators, s2.features))
    if head == "vertex":
        y2 = y2[inv]  # vertex a of mesh 1 is vertex inv[a] of mesh 2
    elif head == "face":
        y1 = y1[fperm]
    torch.testing.assert_close(y2, y1, atol=1e-8, rtol=1e-7)


def test_edge_features_equivariant_to_renumbering(moved_pair):
    """Complex edge features follow the edge permutation, with a sign where an edge flips."""
    s1, s2, inv, _ = moved_pair
    o1, o2 = s1.operators, s2.operators
    torch.manual_seed(0)
    block = enn.LearnedDiffusion(8).double()
    z1 = enn.gradient_features(s1.features, o1.gradient, o1.edge_mass)
    z2 = enn.gradient_features(s2.features, o2.gradient, o2.edge_mass)
    # edge e1 = (a, b) of mesh 1 is (inv[a], inv[b]) in mesh 2
    mapped = inv[o1.edges]
    key2 = {tuple(e): i for i, e in enumerate(o2.edges.tolist())}
    index = torch.tensor([key2[tuple(sorted(e))] for e in mapped.tolist()])
    sign = torch.where(mapped[:, 0] < mapped[:, 1], 1.0, -1.0).to(torch.float64)[:, None]
    torch.testing.assert_close(z2[index], sign * z1)
    d1 = block(z1, o1.edge_mass, evals=o1.edge_evals, evecs=o1.edge_evecs)
    d2 = block(z2, o2.edge_mass, evals=o2.edge_evals, evecs=o2.edge_evecs)
    torch.testing.assert_close(d2[index], sign * d1, atol=1e-8, rtol=1e-7)


def test_networks_batch_equals_single_and_float32(moved_pair):
    s1, s2, _, _ = moved_pair
    torch.manual_seed(0)
    for model in (models.EdgeFieldNet, models.DiffusionNet):
        net = model(8, 3, width=8, num_blocks=1).double().eval()
        both = net(learning.collate_meshes([s1, s2]))
        single = torch.cat([net(learning.collate_meshes([s])) for s in (s1, s2)])
        torch.testing.assert_close(both, single)
        net32 = model(8, 3, width=8, num_blocks=1)
        b32 = learning.collate_meshes(
            [learning.MeshSample(s.operators.to(torch.float32), s.features.float(), 1) for s in (s1, s2)]
        )
        out = net32(b32)
        assert out.dtype == torch.float32 and out.shape == (2, 3)
        loss = torch.nn.functional.cross_entropy(out, b32.labels)
        loss.backward()
        assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in net32.parameters())


def test_edge_diffusion_block_implicit_diffusion(moved_pair):
    s1, _, _, _ = moved_pair
    torch.manual_seed(0)
    batch = learning.MeshBatch.from_operators(s1.operators, s1.features)
    block = models.EdgeDiffusionBlock(4, diffusion="implicit").double()
    z = enn.gradient_features(s1.features[:, :4], batch.gradient, batch.edge_mass)
    out = block(z, batch)
    assert out.shape == z.shape and torch.isfinite(out).all()


def test_gradient_features_of_complex_scalars_are_gradient_plus_rotated_gradient(mesh):
    G = ev.gradient(mesh["v"], mesh["topo"])
    g = torch.Generator().manual_seed(2)
    a, b = (torch.randn(mesh["v"].shape[0], 2, generator=g, dtype=torch.float64) for _ in range(2))
    both = enn.gradient_features(torch.complex(a, b), G, mesh["m"])
    expected = enn.gradient_features(a, G, mesh["m"]) + 1j * enn.gradient_features(b, G, mesh["m"])
    torch.testing.assert_close(both, expected)
    # without the mass: G f itself
    torch.testing.assert_close(
        enn.gradient_features(a, G), both.real.new_tensor(0) + G.to_dense() @ a.to(G.dtype)
    )


def test_network_errors(moved_pair):
    s1, _, _, _ = moved_pair
    batch = learning.MeshBatch.from_operators(s1.operators, s1.features)
    with pytest.raises(ValueError, match="batch.features"):
        models.EdgeFieldNet(3, 2).double()(batch)
    no_grad = learning.MeshBatch.from_operators(
        learning.compute_operators(s1.operators.verts, s1.operators.faces, k_edge=4, k_vertex=4), s1.features
    )
    with pytest.raises(ValueError, match="vertex_gradient"):
        models.DiffusionNet(8, 2).double()(no_grad)
    with pytest.raises(ValueError, match="width"):
        models.DiffusionNet(8, 2, width=0)
