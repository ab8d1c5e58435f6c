"""Projection of an edge-based vector field on the gradients of vertex functions (thesis 4.2).

For a tangent vector field ``U`` with edge values ``z`` and a piecewise-linear vertex
function ``u``, whose gradient has edge values ``M_z^{-1} G u``,

.. math::
    E_z(u) = \\int_{\\mathcal M} |\\nabla u - U|^2
           = u^T L u - 2 \\operatorname{Re}(G^* z)^T u + z^* M_z z,
    \\qquad L = G^* M_z^{-1} G,

because :math:`\\int \\nabla u \\cdot U = \\operatorname{Re}\\langle\\langle \\nabla u, U
\\rangle\\rangle = \\operatorname{Re}((M_z^{-1} G u)^* M_z z) = \\operatorname{Re}(G^* z)^T u`
for real ``u``. The minimizer solves

.. math::  L u = \\operatorname{Re}(G^* z).

Sign check: for ``z = M_z^{-1} G u_0`` the right-hand side is
``Re(G^* M_z^{-1} G u_0) = L u_0``, so ``u = u_0`` up to a constant. (The thesis prints
``+2 Re(G^* z)^T u``, which with this ``G`` would give ``-u_0``; thesis B.4 writes
``div = -M_v^{-1} Re(G^* z)``, consistent with the minus sign used here.)

``L`` has the constants of every connected component in its kernel; the solution is
fixed by pinning one vertex per component and then shifting each component to zero mean
(weighted by the lumped vertex mass). Everything is differentiable with respect to the
vertex positions and ``z`` (the solve goes through :func:`torch_edgevf.linalg.solve`).
"""

from __future__ import annotations

import torch

from .._validation import as_edge_field
from ..linalg import SparseSolver, solve
from ..mesh.geometry import topology_and_verts
from ..mesh.topology import Topology
from ..operators.functional import gradient, laplace_beltrami, mass_matrix, vertex_mass

__all__ = ["gradient_projection_rhs", "project_on_gradients", "gradient_energy", "GradientProjector"]


def gradient_projection_rhs(verts, topo, z) -> torch.Tensor:
    """The right-hand side ``Re(G^* z)``, (V,) or (V, C) real (thesis 4.2)."""
    verts, topo = topology_and_verts(verts, topo)
    z = as_edge_field(z, topo, verts)
    g = gradient(verts, topo)
    return (g.conj().transpose(0, 1) @ z).real


def gradient_energy(verts, topo, u, z) -> torch.Tensor:
    """``E_z(u) = int |grad u - U|^2 = u^T L u - 2 Re(G^* z)^T u + z^* M_z z`` (per column)."""
    verts, topo = topology_and_verts(verts, topo)
    z = as_edge_field(z, topo, verts)
    g = gradient(verts, topo)
    m = mass_matrix(verts, topo).values()
    gu = g @ u.to(z.dtype)
    r = gu / (m if gu.dim() == 1 else m[:, None]) - z
    w = r.abs() ** 2
    return (w * (m if w.dim() == 1 else m[:, None])).sum(0)


def _pins(topo: Topology) -> torch.Tensor:
    """One vertex per connected component (its lowest index)."""
    comp = topo.components
    ok = comp >= 0
    idx = torch.arange(comp.numel())
    first = torch.full((topo.num_components,), comp.numel(), dtype=torch.int64)
    first = first.scatter_reduce(0, comp[ok], idx[ok], reduce="amin")
    return first


def _reduced(L: torch.Tensor, pins: torch.Tensor, unref: torch.Tensor):
    """``L`` with the pinned (and unreferenced) rows/columns removed, and the free indices."""
    L = L.coalesce()
    n = L.shape[0]
    free_mask = torch.ones(n, dtype=torch.bool)
    free_mask[pins] = False
    free_mask[unref] = False
    free = torch.nonzero(free_mask).flatten()
    new = torch.full((n,), -1, dtype=torch.int64)
    new[free] = torch.arange(free.numel())
    idx = L.indices().cpu()
    r, c = new[idx[0]], new[idx[1]]
    keep = (r >= 0) & (c >= 0)
    dev = L.device
    red = torch.sparse_coo_tensor(
        torch.stack([r[keep], c[keep]]).to(dev),
        L.values()[keep.to(dev)],
        (free.numel(), free.numel()),
        check_invariants=False,
    ).coalesce()
    return red, free.to(dev)


def _center(u: torch.Tensor, mass: torch.Tensor, comp: torch.Tensor, ncomp: int) -> torch.Tensor:
    """Subtract the mass-weighted mean of ``u`` on each connected component."""
    ok = comp >= 0
    c = torch.where(ok, comp, torch.zeros_like(comp))
    w = torch.where(ok, mass, torch.zeros_like(mass))
    wu = w * u if u.dim() == 1 else w[:, None] * u
    tot = mass.new_zeros(ncomp).index_add(0, c, w)
    s = u.new_zeros((ncomp,) + tuple(u.shape[1:])).index_add(0, c, wu)
    mean = s / (tot if u.dim() == 1 else tot[:, None])
    out = u - mean[c]
    return torch.where(ok if u.dim() == 1 else ok[:, None], out, torch.zeros_like(out))


class GradientProjector:
    """Prefactored projection on gradients: factor ``L`` once, project many fields.

    Parameters
    ----------
    verts : (V, 3) tensor (may require grad: the factor's values carry the graph)
    faces : (F, 3) int tensor or :class:`Topology`

    Examples
    --------
    >>> proj = GradientProjector(verts, faces)
    >>> u = proj(z)              # (V,), zero mean on each component
    """

    def __init__(self, verts, faces=None):
        verts, topo = topology_and_verts(verts, faces)
        self.verts, self.topo = verts, topo
        self._g = gradient(verts, topo)
        L = laplace_beltrami(verts, topo)
        dev = verts.device
        self._pins = _pins(topo)
        red, self._free = _reduced(L, self._pins, topo.unreferenced_vertices)
        self.solver = SparseSolver(red, hermitian=True)
        self._mass = vertex_mass(verts, topo, lumped=True).values()
        self._comp = topo.components.to(dev)

    def rhs(self, z) -> torch.Tensor:
        z = as_edge_field(z, self.topo, self.verts)
        return (self._g.conj().transpose(0, 1) @ z).real

    def __call__(self, z) -> torch.Tensor:
        """The function ``u`` (V,) or (V, C) minimizing ``int |grad u - U|^2``, zero mean."""
        b = self.rhs(z)
        x = solve(self.solver, b[self._free])
        u = b.new_zeros(b.shape).index_put((self._free,), x)
        return _center(u, self._mass, self._comp, self.topo.num_components)

    solve = __call__


def project_on_gradients(verts, faces, z) -> torch.Tensor:
    """The vertex function whose gradient is closest to the field ``z`` (thesis 4.2).

    .. math::  u = \\arg\\min_u \\int |\\nabla u - U|^2 \\iff L u = \\operatorname{Re}(G^* z),

    normalised to zero (lumped-mass weighted) mean on each connected component.
    Differentiable with respect to ``verts`` and ``z``.

    Parameters
    ----------
    verts : (V, 3) tensor
    faces : (F, 3) int tensor or :class:`Topology`
    z : (E,) or (E, C) complex tensor, edge values of ``U`` (n = 1)

    Returns
    -------
    (V,) or (V, C) real tensor.
    """
    return GradientProjector(verts, faces)(z)
