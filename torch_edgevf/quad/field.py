"""The default cross field of :func:`~torch_edgevf.quad.mesh.quad_mesh`: the curvature where it
has a direction, the smoothest field where it has none.

The curvature guide of the thesis (3.4, :meth:`~torch_edgevf.fields.design.FieldDesigner.curvature`)
is the traceless part of the edge-based shape operator, heat-diffused: its magnitude is about
``|k1 - k2| / 2``, but on a near-umbilic surface (a sphere, the caps of a capsule) its
*direction* is the discretization's noise, and the soft alignment, linear in the guide,
follows that noise whatever its magnitude: on a sphere it gives dozens of cones where the
smoothest field has 8. The *anisotropy* of the curvature

.. math::  r_e = \\frac{|D(z^{(2)})_e|}{D(|z^{(2)}|)_e} \\in [0, 1]

compares the diffused line field ``z^(2)`` (whose terms, one per edge, cancel where their
directions disagree) with the same diffusion of their magnitudes (scalar, no cancellation,
``kappa_e``): about ``|k1 - k2| / (|k1| + |k2|)`` on a smooth surface, 1 on a cylinder or a
saddle, 0 at an umbilic point, below 0.02 on a sphere meshed by icosahedral subdivision (0
where the surface is flat). With the weight ``a_e = a(r_e)``, 0 below ``r = 0.1`` and 1 above
``r = 0.3`` (a smooth step between), the guide is

.. math::  g_e = a_e\\, w_e + (1 - a_e)\\, \\kappa_e\\, e^{i \\alpha} \\frac{s_e}{|s_e|}

``w`` the curvature guide (``n = 4``), ``s`` the smoothest cross field (on meshes with
constrained edges, the smoothest one that follows them) turned by the global phase
``alpha`` that best matches ``a w``: anisotropic regions follow the curvature, umbilic and
flat ones the smoothest field, at the strength of their curvature. Where ``a`` is 0 on every
edge (a sphere) there is no guide and the field is the smoothest one. The thresholds were
chosen on the benchmark meshes (``benchmarks/results/quad.md``).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl
import torch

from ..fields.powers import nth_power
from ..mesh.geometry import dihedral_angles, edge_lengths
from ..operators import kernels

__all__ = ["curvature_anisotropy", "anisotropy_weight", "curvature_guide"]

ANISOTROPY_LOW = 0.1
ANISOTROPY_HIGH = 0.3


def _diffusion_time(designer) -> float:
    """The physical time of :meth:`FieldDesigner.curvature`'s default diffusion."""
    radius = math.sqrt(float(designer._geom.area.sum()) / (4 * math.pi))
    return float(designer.mean_edge_length) * radius / 10


def _line_field(designer) -> tuple[torch.Tensor, torch.Tensor]:
    """The diffused curvature line field (``n = 2``) and the magnitudes of its raw terms."""
    d2 = designer if designer.n == 2 else designer._companion(2)
    z2 = d2.curvature()
    beta = dihedral_angles(d2.verts, d2.topology)
    terms = (beta * edge_lengths(d2.verts, d2.topology) / (3 * d2.mass)).abs()
    return z2, terms


def _scalar_diffusion(designer, x: np.ndarray, t: float, steps: int = 4) -> np.ndarray:
    """``steps`` implicit Euler steps of the scalar (Crouzeix-Raviart) heat equation on edges."""
    lap = kernels.connection_laplacian_from(designer._geom, designer._signs, designer.topology, 0).coalesce()
    i = lap.indices().cpu().numpy()
    L = sp.csc_matrix((lap.values().detach().cpu().double().numpy(), (i[0], i[1])), shape=tuple(lap.shape))
    m = designer.mass.detach().cpu().double().numpy()
    solve = spl.factorized((sp.diags(m) + (t / steps) * L).tocsc())
    for _ in range(steps):
        x = solve(m * x)
    return x


def curvature_anisotropy(designer) -> torch.Tensor:
    """(E,) float64 ``r_e`` in [0, 1], the anisotropy of the curvature (module docstring),
    of the mesh of a :class:`~torch_edgevf.fields.design.FieldDesigner` (0 where the surface
    is flat)."""
    z2, terms = _line_field(designer)
    return _anisotropy(designer, z2, terms)


def _anisotropy(designer, z2: torch.Tensor, terms: torch.Tensor, spread=None) -> torch.Tensor:
    if spread is None:
        spread = _scalar_diffusion(designer, terms.detach().cpu().double().numpy(), _diffusion_time(designer))
    top = float(spread.max(initial=0.0))
    coherent = z2.detach().cpu().abs().double().numpy()
    r = np.where(spread > 1e-12 * top, coherent / np.maximum(spread, 1e-300), 0.0) if top > 0 else 0 * spread
    return torch.from_numpy(np.clip(r, 0.0, 1.0))


def anisotropy_weight(
    r: torch.Tensor, low: float = ANISOTROPY_LOW, high: float = ANISOTROPY_HIGH
) -> torch.Tensor:
    """The weight of the curvature guide: 0 for ``r <= low``, 1 for ``r >= high``, a smooth
    step (``3 t^2 - 2 t^3``) between."""
    if not 0 <= low < high:
        raise ValueError(f"need 0 <= low < high, got low={low!r}, high={high!r}")
    t = ((r - low) / (high - low)).clamp(0.0, 1.0)
    return t * t * (3 - 2 * t)


def curvature_guide(designer, smoothest=None) -> torch.Tensor | None:
    """The guide ``g`` of the default cross field (``n = 4``, module docstring), or ``None``
    where the anisotropy weight is 0 on every edge.

    Parameters
    ----------
    designer : :class:`~torch_edgevf.fields.design.FieldDesigner` with ``n = 4``
    smoothest : (E,) complex tensor, optional: the smooth cross field of the umbilic regions
        (default: ``designer.smoothest()``); only its directions are used
    """
    if designer.n != 4:
        raise ValueError(f"the quad field is a cross field: n must be 4, got n = {designer.n}")
    z2, terms = _line_field(designer)
    spread = _scalar_diffusion(designer, terms.detach().cpu().double().numpy(), _diffusion_time(designer))
    a = anisotropy_weight(_anisotropy(designer, z2, terms, spread)).to(z2.device, z2.real.dtype)
    if not bool((a > 0).any()):
        return None
    w = nth_power(z2, 2)
    zs = designer.smoothest() if smoothest is None else smoothest.to(w)
    u = zs / zs.abs().clamp_min(1e-300)
    phase = (designer.mass * a * w * u.conj()).sum()
    if float(phase.abs()) > 0:
        u = u * (phase / phase.abs())
    kappa = torch.from_numpy(spread).to(w.device, a.dtype)
    return a * w + (1 - a) * kappa * u
