"""Differentiable losses on edge fields and meshes, for learning and shape optimisation.

Every loss is a function of the vertex positions and (where there is one) of the edge
field, and is differentiable with respect to both: the operators are re-assembled from
``verts`` with :mod:`torch_edgevf.operators`, so gradients reach the geometry. Fields of
shape ``(E, C)`` are ``C`` independent fields; ``reduction`` combines the per-field values.

=========================  ================================================================
loss                       value per field
=========================  ================================================================
smoothness_loss            ``z^H L_c z / z^H M_z z`` (Dirichlet energy per unit norm, 3.1)
alignment_loss             ``1 - Re<w, z>_M / (|w|_M |z|_M)`` (soft alignment, 3.4)
curl_loss, div_loss        ``int curl^2`` / ``int div^2`` (3.3), optionally per ``|z|_M^2``
spectral_loss              mean squared relative error of the first ``k`` eigenvalues of
                           ``(L, M_v)`` against a target (isospectralization, 4.2)
=========================  ================================================================
"""

from __future__ import annotations

import torch

from .._validation import as_edge_field, as_verts
from ..fields.powers import nth_power
from ..linalg import eigsh
from ..mesh.geometry import face_areas, topology_and_verts
from ..operators.functional import (
    connection_laplacian,
    face_curl,
    face_div,
    laplace_beltrami,
    mass_matrix,
    vertex_mass,
)

__all__ = [
    "smoothness_loss",
    "alignment_loss",
    "curl_loss",
    "div_loss",
    "laplace_beltrami_spectrum",
    "spectral_loss",
]

_REDUCTIONS = ("mean", "sum", "none")


def _reduce(x: torch.Tensor, reduction: str) -> torch.Tensor:
    if reduction == "mean":
        return x.mean()
    if reduction == "sum":
        return x.sum()
    return x


def _check_reduction(reduction) -> None:
    if reduction not in _REDUCTIONS:
        raise ValueError(f"reduction must be one of {_REDUCTIONS}, got {reduction!r}")


def _field(verts, topo, z, name="z"):
    verts, topo = topology_and_verts(verts, topo)
    if isinstance(z, torch.Tensor) and not z.is_complex():
        raise ValueError(f"{name} must be a complex edge field, got {z.dtype}")
    z = as_edge_field(z, topo, verts, name)
    return verts, topo, z


def _as_columns(z: torch.Tensor) -> torch.Tensor:
    return z[:, None] if z.dim() == 1 else z


def _squeeze_like(x: torch.Tensor, z: torch.Tensor, reduction: str) -> torch.Tensor:
    return x[0] if (reduction == "none" and z.dim() == 1) else x


def _quadratic_form(A: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
    """``Re(z_c^H A z_c)`` per column of ``z`` ``(N, C)``, gradients to ``z`` and ``A``'s values."""
    A = A.coalesce()
    rows, cols = A.indices()
    vals = A.values()
    return (z[rows].conj() * vals[:, None] * z[cols]).real.sum(0)


def _mass_norm2(mass: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
    return (mass[:, None] * (z.real**2 + z.imag**2)).sum(0)


def _nonzero(den: torch.Tensor, name: str) -> torch.Tensor:
    if bool((den.detach() <= 0).any()):
        raise ValueError(f"{name} is zero: the loss is undefined for a zero field")
    return den


def smoothness_loss(verts, topo, z, n: int = 1, reduction: str = "mean") -> torch.Tensor:
    r"""Dirichlet energy per unit norm: the Rayleigh quotient of the connection Laplacian.

    .. math::  E(z) = \frac{z^H L_c z}{z^H M_z z}

    (thesis 3.1), scale invariant; its minimum over fields is the smallest eigenvalue of
    :math:`(L_c, M_z)`.

    Parameters
    ----------
    verts : (V, 3) float tensor
    topo : Topology or (F, 3) faces
    z : (E,) or (E, C) complex tensor (``n``-field representation vectors)
    n : int, symmetry order of ``L_c``
    reduction : {"mean", "sum", "none"} over the ``C`` fields

    Returns
    -------
    scalar, or (C,) with ``reduction="none"`` (scalar for ``(E,)`` input).
    """
    _check_reduction(reduction)
    verts, topo, z = _field(verts, topo, z)
    zc = _as_columns(z)
    L = connection_laplacian(verts, topo, n)
    mass = mass_matrix(verts, topo).values()
    value = _quadratic_form(L, zc) / _nonzero(_mass_norm2(mass, zc), "z^H M_z z")
    return _squeeze_like(_reduce(value, reduction), z, reduction)


def alignment_loss(verts, topo, z, guide, n: int = 1, reduction: str = "mean") -> torch.Tensor:
    r"""Misalignment of a field with a guide: one minus their ``M_z`` cosine.

    .. math::  1 - \frac{\mathrm{Re}\langle w, z\rangle_M}{\|w\|_M \|z\|_M}, \qquad
               \langle w, z\rangle_M = \sum_e (M_z)_{ee} \bar w_e z_e

    (the soft alignment energy of thesis 3.4, normalised), in ``[0, 2]``: 0 when ``z``
    is a positive multiple of ``w``. For ``n``-direction fields the guide is a direction
    field and its angle-based ``n``-th power (thesis 2.2) is compared with the
    representation vector ``z``; any of the ``n`` equivalent directions of the guide gives
    the same loss. With ``n = 1`` the guide is used as is (pass ``n = 1`` for a guide that
    already is a representation vector).

    Parameters
    ----------
    z : (E,) or (E, C) complex tensor
    guide : complex tensor of the shape of ``z``, or (E,) broadcast over the columns
    n : int >= 1
    reduction : {"mean", "sum", "none"}
    """
    _check_reduction(reduction)
    if not isinstance(n, int) or isinstance(n, bool) or n < 1:
        raise ValueError(f"n must be an integer >= 1, got {n!r}")
    verts, topo, z = _field(verts, topo, z)
    _, _, w = _field(verts, topo, guide, "guide")
    zc, wc = _as_columns(z), _as_columns(w)
    if wc.shape[1] not in (1, zc.shape[1]):
        raise ValueError(f"guide has {wc.shape[1]} columns but z has {zc.shape[1]}")
    if n > 1:
        wc = nth_power(wc, n)
    mass = mass_matrix(verts, topo).values()
    inner = (mass[:, None] * (wc.conj() * zc)).real.sum(0)
    norms = torch.sqrt(
        _nonzero(_mass_norm2(mass, wc), "|guide|_M") * _nonzero(_mass_norm2(mass, zc), "|z|_M")
    )
    value = 1 - inner / norms
    return _squeeze_like(_reduce(value, reduction), z, reduction)


def _face_energy(verts, topo, z, which: str, normalize: bool, reduction: str) -> torch.Tensor:
    _check_reduction(reduction)
    verts, topo, z = _field(verts, topo, z)
    zc = _as_columns(z)
    per_face = (face_curl if which == "curl" else face_div)(verts, topo, zc)  # (F, C)
    area = face_areas(verts, topo.faces)
    value = (area[:, None] * per_face**2).sum(0)
    if normalize:
        value = value / _nonzero(_mass_norm2(mass_matrix(verts, topo).values(), zc), "z^H M_z z")
    return _squeeze_like(_reduce(value, reduction), z, reduction)


def curl_loss(verts, topo, z, normalize: bool = False, reduction: str = "mean") -> torch.Tensor:
    r"""The curl energy :math:`\int_M \mathrm{curl}(\psi)^2 = \sum_T A_T\, \mathrm{curl}_T^2` (thesis 3.3).

    ``curl_T = K Re(z) / A_T`` per face (:func:`~torch_edgevf.operators.face_curl`);
    equal to ``x^T L_curl x`` with ``x = (Re z, Im z)``. With ``normalize``, divided by
    :math:`z^H M_z z` (scale invariant). Shapes as in :func:`smoothness_loss`.
    """
    return _face_energy(verts, topo, z, "curl", normalize, reduction)


def div_loss(verts, topo, z, normalize: bool = False, reduction: str = "mean") -> torch.Tensor:
    r"""The divergence energy (thesis 3.3).

    .. math::  \int_M \mathrm{div}(\psi)^2 = \sum_T A_T\, \mathrm{div}_T^2

    ``div_T = -K Im(z) / A_T``. See :func:`curl_loss`.
    """
    return _face_energy(verts, topo, z, "div", normalize, reduction)


def laplace_beltrami_spectrum(verts, topo, k: int, lumped: bool = False, **eigsh_kwargs) -> torch.Tensor:
    r"""The ``k`` smallest eigenvalues of :math:`L f = \lambda M_v f`, differentiable in ``verts``.

    ``L = G^* M_z^{-1} G`` (thesis 4.2) and the full (or lumped) vertex mass; computed
    with :func:`~torch_edgevf.linalg.eigsh`, whose eigenvalue gradients are exact for
    simple eigenvalues (a degenerate eigenvalue has no derivative; symmetric shapes need
    a perturbation, or a loss symmetric in each eigenspace).

    Returns
    -------
    (k,) real tensor, ascending (the first is 0 on a closed mesh).
    """
    verts, topo = topology_and_verts(verts, topo)
    if not isinstance(k, int) or isinstance(k, bool) or not 1 <= k < topo.num_vertices:
        raise ValueError(f"k must be an integer with 1 <= k < V = {topo.num_vertices}, got {k!r}")
    L = laplace_beltrami(verts, topo)
    M = vertex_mass(verts, topo, lumped=lumped)
    if lumped:
        M = M.values()
    return eigsh(L, M, k=k, **eigsh_kwargs).values


def spectral_loss(
    verts,
    topo,
    target,
    k: int | None = None,
    skip_zero: bool = True,
    relative: bool = True,
    lumped: bool = False,
    **eigsh_kwargs,
) -> torch.Tensor:
    r"""Mismatch of the first Laplace-Beltrami eigenvalues with a target spectrum.

    .. math::  \frac{1}{k'} \sum_i \left(\frac{\lambda_i(V) - \mu_i}{\mu_i}\right)^2

    over the first ``k`` eigenvalues of :math:`(L, M_v)` (:func:`laplace_beltrami_spectrum`),
    leaving out the zero eigenvalue of a closed mesh (``skip_zero``); absolute squared
    errors with ``relative=False``. The isospectralization loss of Cosmo et al. (2019).

    Parameters
    ----------
    verts : (V, 3) float tensor (requires grad to optimise)
    topo : Topology or faces
    target : (k,) real tensor, the target's eigenvalues (including its zero one)
    k : int, default ``len(target)``
    """
    if not isinstance(target, torch.Tensor) or target.dim() != 1 or target.is_complex():
        raise ValueError("target must be a real (k,) tensor of eigenvalues")
    k = target.shape[0] if k is None else k
    if k > target.shape[0]:
        raise ValueError(f"k = {k} exceeds the {target.shape[0]} target eigenvalues")
    verts = as_verts(verts)
    lam = laplace_beltrami_spectrum(verts, topo, k, lumped=lumped, **eigsh_kwargs)
    mu = target[:k].to(device=lam.device, dtype=lam.dtype)
    start = 1 if skip_zero else 0
    lam, mu = lam[start:], mu[start:]
    if lam.numel() == 0:
        raise ValueError("no eigenvalue left to compare: increase k")
    err = lam - mu
    if relative:
        if bool((mu.abs() <= 0).any()):
            raise ValueError("relative spectral loss needs nonzero target eigenvalues (use skip_zero)")
        err = err / mu
    return (err**2).mean()
