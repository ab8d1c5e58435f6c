"""Vertex scalars to edge vectors with the gradient G, and back with its adjoint (divergence and curl)."""

from __future__ import annotations

import torch
from torch import nn

from ..._device import check_devices
from ..._dtypes import complex_dtype
from .sparse import _check_features, _check_sparse, _check_vector, _spmm

# --------------------------------------------------------------------------- gradient


def gradient_features(f, G, mass=None) -> torch.Tensor:
    r"""Edge gradient fields of vertex scalars: :math:`z = M_z^{-1} G f` (thesis 4.2).

    ``Re(z_e) = (f_j - f_i) / |e|`` along the edge (4.1); ``Im(z_e)`` is the normal
    component. Gauge-equivariant and intrinsic. A complex ``f = a + i b`` gives
    ``grad a + J grad b`` (``J`` the rotation by a quarter turn): gradients and
    co-gradients in one product. Without ``mass``, ``G f`` itself (for an operator that
    gives the field directly, such as
    :func:`~torch_edgevf.learning.precompute.vertex_gradient_operator`).

    Parameters
    ----------
    f : (V, C) real or complex tensor
    G : (E, V) complex sparse tensor (:func:`~torch_edgevf.operators.gradient`)
    mass : (E,) real tensor, the diagonal of ``M_z``, optional

    Returns
    -------
    (E, C) complex tensor.
    """
    f = _check_features(f, "f")
    check_devices(f=f, G=G, mass=mass)
    G = _check_sparse(G, "G", cols=f.shape[0])
    if mass is not None:
        mass = _check_vector(mass, G.shape[0], "mass")
    return _gradient_features(f, G, mass)


def _gradient_features(f, G, mass=None) -> torch.Tensor:
    """:func:`gradient_features` on inputs known to be valid (``G`` coalesced COO)."""
    z = _spmm(G, f if f.is_complex() else f.to(complex_dtype(f.dtype)))
    if mass is None:
        return z
    # times the reciprocal: the same numbers as the quotient (a complex number divided
    # by a real one is multiplied by its reciprocal), several times faster
    return z * mass.to(z.real.dtype).reciprocal()[:, None]


def divergence_features(z, G, vertex_mass) -> torch.Tensor:
    r"""Divergence and curl per vertex from the adjoint of the gradient (thesis 4.2, B.4).

    .. math::  M_v (\operatorname{div}_v + \imath \operatorname{curl}_v) = -G^* z

    Both parts are gauge invariant (real scalars per vertex), so the output can be fed
    to any real layer.

    Parameters
    ----------
    z : (E, C) complex tensor
    G : (E, V) complex sparse tensor
    vertex_mass : (V,) real tensor, the (lumped) vertex masses

    Returns
    -------
    (V, C) complex tensor, ``div + i curl``.
    """
    z = _check_features(z, complex_only=True)
    check_devices(z=z, G=G, vertex_mass=vertex_mass)
    G = _check_sparse(G, "G", rows=z.shape[0])
    vertex_mass = _check_vector(vertex_mass, G.shape[1], "vertex_mass")
    out = -_spmm(G, z, adjoint=True)
    return out * vertex_mass.to(out.real.dtype).reciprocal()[:, None]  # as in gradient_features


class GradientFeatures(nn.Module):
    """Module form of :func:`gradient_features`: ``forward(f, G, mass)``."""

    def forward(self, f, G, mass):
        return gradient_features(f, G, mass)


class DivergenceFeatures(nn.Module):
    """Module form of :func:`divergence_features`: ``forward(z, G, vertex_mass)``."""

    def forward(self, z, G, vertex_mass):
        return divergence_features(z, G, vertex_mass)
