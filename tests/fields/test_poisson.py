"""Projection on gradient fields (thesis 4.2)."""

import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.fields.poisson import (
    GradientProjector,
    gradient_energy,
    gradient_projection_rhs,
    project_on_gradients,
)
from torch_edgevf.mesh.topology import Topology


def perturbed(level=2, scale=0.05, seed=0):
    v, f = ev.icosphere(level)
    g = torch.Generator().manual_seed(seed)
    v = v + scale * torch.randn(v.shape, generator=g, dtype=v.dtype)
    perm = torch.randperm(v.shape[0], generator=g)
    inv = torch.empty_like(perm)
    inv[perm] = torch.arange(perm.numel())
    return v[perm], inv[f]


def grad_field(v, topo, u):
    """Edge values ``z = M_z^{-1} G u`` of ``grad u``."""
    g = ev.gradient(v, topo)
    m = ev.mass_matrix(v, topo).values()
    gu = g @ u.to(torch.complex128)
    return gu / (m if gu.dim() == 1 else m[:, None])


def test_recovers_u_up_to_a_constant_on_a_closed_mesh():
    v, f = perturbed()
    topo = Topology(f)
    u0 = v[:, 0] * v[:, 1] + v[:, 2] ** 3 + 3.0
    u = project_on_gradients(v, topo, grad_field(v, topo, u0))
    d = u - u0
    assert float(d.max() - d.min()) < 1e-12
    mass = ev.vertex_mass(v, topo, lumped=True).values()
    assert abs(float((mass * u).sum())) < 1e-12


def test_recovers_u_on_a_mesh_with_boundary_and_several_columns():
    v, f = ev.meshes.grid(6, 5)
    topo = Topology(f)
    u0 = torch.stack([v[:, 0] ** 2 - v[:, 1], torch.sin(3 * v[:, 1]) * v[:, 0]], 1)
    u = project_on_gradients(v, topo, grad_field(v, topo, u0))
    d = u - u0
    assert float((d.max(0).values - d.min(0).values).max()) < 1e-12


def test_sign_convention_and_energy():
    """L u = Re(G^* z): the energy vanishes at u0, and any perturbation raises it."""
    v, f = perturbed(1)
    topo = Topology(f)
    u0 = v[:, 2] ** 2 - v[:, 0]
    z = grad_field(v, topo, u0)
    L = ev.laplace_beltrami(v, topo)
    assert torch.allclose(L @ u0, gradient_projection_rhs(v, topo, z), atol=1e-12)
    g = torch.Generator().manual_seed(1)
    zn = z + 0.3 * torch.randn(z.shape, dtype=z.dtype, generator=g)
    u = project_on_gradients(v, topo, zn)
    e = gradient_energy(v, topo, u, zn)
    for _ in range(3):
        du = 1e-3 * torch.randn(u.shape, dtype=u.dtype, generator=g)
        assert float(gradient_energy(v, topo, u + du, zn)) > float(e)
    assert float(gradient_energy(v, topo, u0, z)) < 1e-24


def test_rotated_gradient_projects_to_zero():
    """J grad f is divergence free on a closed surface: its best gradient is 0 (Hodge)."""
    v, f = perturbed(2)
    topo = Topology(f)
    z = 1j * grad_field(v, topo, v[:, 0] * v[:, 2])
    u = project_on_gradients(v, topo, z)
    assert float(u.abs().max()) < 1e-10


def test_components_are_centred_separately():
    v1, f1 = ev.icosphere(1)
    v2 = v1 + torch.tensor([3.0, 0, 0], dtype=v1.dtype)
    v = torch.cat([v1, v2])
    f = torch.cat([f1, f1 + v1.shape[0]])
    topo = Topology(f)
    u0 = torch.cat([v1[:, 0] + 5, v1[:, 1] * v1[:, 2] - 2])
    u = project_on_gradients(v, topo, grad_field(v, topo, u0))
    mass = ev.vertex_mass(v, topo, lumped=True).values()
    for part in (slice(0, v1.shape[0]), slice(v1.shape[0], None)):
        d = (u - u0)[part]
        assert float(d.max() - d.min()) < 1e-12
        assert abs(float((mass[part] * u[part]).sum())) < 1e-12


def test_prefactored_matches_function():
    v, f = perturbed(2)
    topo = Topology(f)
    g = torch.Generator().manual_seed(2)
    proj = GradientProjector(v, topo)
    for _ in range(2):
        z = torch.randn(topo.num_edges, dtype=torch.complex128, generator=g)
        assert torch.allclose(proj(z), project_on_gradients(v, topo, z), atol=1e-13)


def test_gradcheck_wrt_verts_and_z():
    v, f = perturbed(0, seed=3)
    topo = Topology(f)
    g = torch.Generator().manual_seed(3)
    v = v.clone().requires_grad_(True)
    z = torch.randn(topo.num_edges, dtype=torch.complex128, generator=g).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda a, b: project_on_gradients(a, topo, b), (v, z), fast_mode=True)


def test_validation():
    v, f = ev.icosphere(1)
    topo = Topology(f)
    with pytest.raises(ValueError, match="shape"):
        project_on_gradients(v, topo, torch.zeros(3, dtype=torch.complex128))
