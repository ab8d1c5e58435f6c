"""Losses: values against independent formulas, invariances, float64 gradcheck in verts and z."""

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.learning import losses
from torch_edgevf.linalg import eigsh

from conftest import perturbed_icosphere


@pytest.fixture(scope="module")
def small():
    v, f = perturbed_icosphere(0, 0.1, seed=4)  # 12 vertices, 30 edges
    topo = ev.Topology(f, v.shape[0])
    g = torch.Generator().manual_seed(0)
    z = torch.randn(topo.num_edges, 2, generator=g, dtype=torch.complex128)
    w = torch.randn(topo.num_edges, 2, generator=g, dtype=torch.complex128)
    return v, topo, z, w


def test_smoothness_is_rayleigh_quotient(small):
    v, topo, z, _ = small
    L = ev.connection_laplacian(v, topo, 2).to_dense()
    m = ev.mass_matrix(v, topo).values()
    ref = [(z[:, c].conj() @ L @ z[:, c]).real / (m * z[:, c].abs() ** 2).sum() for c in range(2)]
    out = losses.smoothness_loss(v, topo, z, n=2, reduction="none")
    torch.testing.assert_close(out, torch.stack(ref))
    torch.testing.assert_close(losses.smoothness_loss(v, topo, z, n=2), torch.stack(ref).mean())
    torch.testing.assert_close(
        losses.smoothness_loss(v, topo, 3j * z, n=2, reduction="sum"), torch.stack(ref).sum()
    )
    # the smoothest field attains the smallest eigenvalue
    lam, X = eigsh(ev.connection_laplacian(v, topo, 1), m, k=1)
    torch.testing.assert_close(losses.smoothness_loss(v, topo, X[:, 0]), lam[0])


def test_alignment(small):
    v, topo, z, w = small
    assert float(losses.alignment_loss(v, topo, 2.5 * w, w)) == pytest.approx(0.0, abs=1e-12)
    assert float(losses.alignment_loss(v, topo, -w, w)) == pytest.approx(2.0, abs=1e-12)
    assert float(losses.alignment_loss(v, topo, 1j * w, w)) == pytest.approx(1.0, abs=1e-12)
    # n-aware: the representation vector of the guide's cross field is aligned, for any of its 4 directions
    u = w[:, 0]
    rep = ev.fields.nth_power(u, 4)
    for k in range(4):
        rot = u * np.exp(2j * np.pi * k / 4)
        assert float(losses.alignment_loss(v, topo, rep, rot, n=4)) == pytest.approx(0.0, abs=1e-12)
    m = ev.mass_matrix(v, topo).values()
    c = 0
    ref = 1 - (m * (w[:, c].conj() * z[:, c])).sum().real / torch.sqrt(
        (m * w[:, c].abs() ** 2).sum() * (m * z[:, c].abs() ** 2).sum()
    )
    torch.testing.assert_close(losses.alignment_loss(v, topo, z, w, reduction="none")[c], ref)
    # guide broadcast over the columns
    out = losses.alignment_loss(v, topo, z, w[:, 0], reduction="none")
    assert out.shape == (2,)


def test_curl_div_match_energy_matrices(small):
    v, topo, z, _ = small
    x = torch.cat([z.real, z.imag])  # (2E, C)
    for fn, mat in ((losses.curl_loss, ev.curl_energy), (losses.div_loss, ev.div_energy)):
        E = mat(v, topo).to_dense()
        ref = torch.einsum("ic,ij,jc->c", x, E, x)
        torch.testing.assert_close(fn(v, topo, z, reduction="none"), ref)
        m = ev.mass_matrix(v, topo).values()
        torch.testing.assert_close(
            fn(v, topo, z, normalize=True, reduction="none"), ref / (m[:, None] * z.abs() ** 2).sum(0)
        )
    # a gradient field is curl free
    f = torch.randn(v.shape[0], dtype=torch.float64)
    zg = torch.linalg.solve(
        torch.diag(ev.mass_matrix(v, topo).values()).to(torch.complex128),
        ev.gradient(v, topo).to_dense() @ f.to(torch.complex128),
    )
    assert float(losses.curl_loss(v, topo, zg)) < 1e-20


def test_losses_invariant_to_rigid_motion(small):
    v, topo, z, w = small
    Q, _ = torch.linalg.qr(torch.randn(3, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(3)))
    if torch.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    v2 = v @ Q.T + 1.5
    for fn in (losses.smoothness_loss, losses.curl_loss, losses.div_loss):
        torch.testing.assert_close(fn(v2, topo, z), fn(v, topo, z))
    torch.testing.assert_close(losses.alignment_loss(v2, topo, z, w), losses.alignment_loss(v, topo, z, w))
    torch.testing.assert_close(
        losses.laplace_beltrami_spectrum(v2, topo, 5), losses.laplace_beltrami_spectrum(v, topo, 5)
    )


def test_gradcheck_wrt_verts_and_field(small, gradcheck):
    v, topo, z, w = small
    v = v.clone().requires_grad_()
    z = z.clone().requires_grad_()
    checks = [
        lambda v, z: losses.smoothness_loss(v, topo, z, n=1),
        lambda v, z: losses.smoothness_loss(v, topo, z, n=3, reduction="none"),
        lambda v, z: losses.alignment_loss(v, topo, z, w, n=2),
        lambda v, z: losses.curl_loss(v, topo, z),
        lambda v, z: losses.div_loss(v, topo, z, normalize=True),
    ]
    for fn in checks:
        assert gradcheck(fn, (v, z))


def test_spectral_loss_gradcheck_and_value(small, gradcheck):
    v, topo, _, _ = small
    target = losses.laplace_beltrami_spectrum(v, topo, 6) * 1.1
    vv = v.clone().requires_grad_()
    assert gradcheck(lambda x: losses.spectral_loss(x, topo, target), (vv,))
    assert gradcheck(lambda x: losses.laplace_beltrami_spectrum(x, topo, 4, lumped=True)[1:], (vv,))
    # value: relative errors of 1/1.1 - 1
    assert float(losses.spectral_loss(v, topo, target)) == pytest.approx((1 / 1.1 - 1) ** 2, rel=1e-10)
    # against a dense generalized eigensolver
    import scipy.linalg

    lam = scipy.linalg.eigh(
        ev.laplace_beltrami(v, topo).to_dense().numpy(),
        ev.vertex_mass(v, topo).to_dense().numpy(),
        eigvals_only=True,
    )[:6]
    np.testing.assert_allclose(losses.laplace_beltrami_spectrum(v, topo, 6).numpy(), lam, atol=1e-10)


def test_float32(small):
    v, topo, z, w = small
    v32, z32, w32 = v.float().requires_grad_(), z.to(torch.complex64).requires_grad_(), w.to(torch.complex64)
    total = (
        losses.smoothness_loss(v32, topo, z32)
        + losses.alignment_loss(v32, topo, z32, w32)
        + losses.curl_loss(v32, topo, z32, normalize=True)
        + losses.div_loss(v32, topo, z32, normalize=True)
    )
    assert total.dtype == torch.float32
    total.backward()
    assert torch.isfinite(v32.grad).all() and torch.isfinite(torch.view_as_real(z32.grad)).all()


def test_errors(small):
    v, topo, z, w = small
    with pytest.raises(ValueError, match="complex"):
        losses.smoothness_loss(v, topo, z.real)
    with pytest.raises(ValueError, match="shape"):
        losses.smoothness_loss(v, topo, z[:-1])
    with pytest.raises(ValueError, match="dtype"):
        losses.smoothness_loss(v, topo, z.to(torch.complex64))
    with pytest.raises(ValueError, match="reduction"):
        losses.curl_loss(v, topo, z, reduction="max")
    with pytest.raises(ValueError, match="zero field"):
        losses.alignment_loss(v, topo, torch.zeros_like(z), w)
    with pytest.raises(ValueError, match="n must"):
        losses.alignment_loss(v, topo, z, w, n=0)
    with pytest.raises(ValueError, match="columns"):
        losses.alignment_loss(v, topo, z, torch.ones(topo.num_edges, 3, dtype=torch.complex128))
    with pytest.raises(ValueError, match="k must"):
        losses.laplace_beltrami_spectrum(v, topo, 12)
    with pytest.raises(ValueError, match="target"):
        losses.spectral_loss(v, topo, torch.ones(3, 2))
    with pytest.raises(ValueError, match="exceeds"):
        losses.spectral_loss(v, topo, torch.ones(3, dtype=torch.float64), k=4)
