"""Every edge-based operator of the thesis as a torch sparse COO tensor.

Each public function takes ``(verts, topo)``: vertex positions ``(V, 3)`` (float32 or
float64; gradients flow back to them) and a :class:`~torch_edgevf.mesh.topology.Topology` (or a
faces array, from which one is built). The sparsity patterns are computed once per
topology and cached on it; re-assembly for new positions is a gather and a scatter.

Where positions cannot be trusted (zero-area faces, or a mesh known only by its edge
lengths), pass a :class:`~torch_edgevf.mesh.geometry.FaceGeometry` in place of ``verts``,
e.g. ``FaceGeometry.from_edge_lengths(lengths, topo)`` or the mollified
``repair(verts, faces).geometry``: every operator depends only on edge lengths, corner
angles and the transport between the edges of a face, which is the corner angle, so all of
them are intrinsic, and differentiable in the lengths.

Per face, with corners ``a, b`` and third corner ``c``, lengths ``l`` of the opposite
edges, area ``A``, signs ``delta`` and transport ``r_ab`` (:func:`transport_coefficients`):

=====================  ===================================================================================
operator               contribution of one face
=====================  ===================================================================================
``M_z``  (E, E)        ``(M_z)_aa += A / 3``                                                     (3.1, A.2)
``L_c^(n)``  (E, E)    ``(L)_aa += l_a^2 / A``, ``(L)_ab += -l_a l_b cos(alpha_c) / A * r_ba^n`` (3.1, A.3)
``G``  (E, V)          ``G[e_a, v_b] += i delta_b l_b / 6 * r_ba``  (``r_aa = 1``)               (4.2, A.4)
``K``  (F, E)          ``K[f, e_a] = delta_a l_a``                                               (3.3)
``D_w``  (E, E)        ``(D)_ab += -delta_b l_b / 3 * Im(w_a r_ab) * r_ba``                      (5.1, A.5)
``M_v`` full  (V, V)   ``A / 6`` on the diagonal, ``A / 12`` off it
``L``  (V, V)          ``G^H M_z^{-1} G`` (real)                                                 (4.2)
=====================  ===================================================================================
"""

from __future__ import annotations

import torch

from .._validation import as_edge_field, check_n
from ..mesh.geometry import OFF_DIAGONAL, PAIR_A, PAIR_B, PAIR_C, pair_columns
from .kernels import (
    cached_pattern,
    connection_laplacian_from,
    covariant_from,
    curl_energy_block,
    curl_values,
    embed_block,
    gradient_values,
    laplace_beltrami_from,
    mass_values,
    prepare,
    vertex_mass_from,
)
from .patterns import diagonal

__all__ = [
    "mass_matrix",
    "connection_laplacian",
    "gradient",
    "curl_div_operator",
    "face_curl",
    "face_div",
    "vertex_div_curl",
    "real_form",
    "curl_energy",
    "div_energy",
    "laplace_beltrami",
    "vertex_mass",
    "covariant_derivative",
    "cotan_laplacian",
]

_A, _B, _C = PAIR_A, PAIR_B, PAIR_C


# --------------------------------------------------------------------------- patterns


# --------------------------------------------------------------------------- helpers


# --------------------------------------------------------------------------- values per face


# --------------------------------------------------------------------------- operators


def mass_matrix(verts, topo=None) -> torch.Tensor:
    """The edge mass matrix ``M_z`` (thesis 3.1, A.2): real, diagonal, exact (not lumped).

    .. math::  (M_z)_{ee} = \\sum_{T \\ni e} A_T / 3

    Returns
    -------
    (E, E) real sparse tensor.
    """
    verts, topo, geom, _ = prepare(verts, topo)
    return diagonal(mass_values(geom, topo))


def connection_laplacian(verts, topo=None, n: int = 1) -> torch.Tensor:
    """The connection Laplacian ``L_c`` acting on representation vectors of n-direction fields.

    .. math::
        (L_c)_{aa} \\mathrel{+}= \\frac{|e_a|^2}{A_T}, \\qquad
        (L_c)_{ab} \\mathrel{+}= -\\frac{|e_a||e_b|}{A_T} \\cos(\\alpha_c)\\, r_{ba}^n

    (thesis 3.1 and A.3). Hermitian positive semi-definite with a real diagonal;
    ``z^H L_c z`` is the Dirichlet energy of the field. ``n = 0`` gives the real scalar
    Crouzeix-Raviart Laplacian.

    Returns
    -------
    (E, E) sparse tensor, complex for ``n >= 1``, real for ``n = 0``.
    """
    n = check_n(n, minimum=0)
    verts, topo, geom, signs = prepare(verts, topo)
    return connection_laplacian_from(geom, signs, topo, n)


def gradient(verts, topo=None) -> torch.Tensor:
    """The gradient ``G`` from vertex functions to edge fields (thesis 4.2, A.4).

    ``M_z z = G f`` gives the edge field ``z`` of ``grad f``; per face,

    .. math::  G_{e_a, v_b} \\mathrel{+}= \\imath \\delta_b \\frac{|e_b|}{6} r_{ba}, \\quad r_{aa} = 1.

    Returns
    -------
    (E, V) complex sparse tensor.
    """
    verts, topo, geom, signs = prepare(verts, topo)
    return cached_pattern(topo, "EV").assemble(gradient_values(geom, signs))


def curl_div_operator(verts, topo=None) -> torch.Tensor:
    """``K = G_{e->t} M_e``, the signed face-edge incidence scaled by edge lengths (thesis 3.3).

    ``M_t curl_T = K Re(z)`` and ``M_t div_T = -K Im(z)``, with ``M_t`` the face areas.

    Returns
    -------
    (F, E) real sparse tensor.
    """
    verts, topo, geom, signs = prepare(verts, topo)
    return cached_pattern(topo, "FE").assemble(curl_values(geom, signs))


def _face_circulation(verts, topo, z) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    verts, topo, geom, signs = prepare(verts, topo)
    z = as_edge_field(z, topo, verts)
    fe = topo.face_edges.to(verts.device)
    weights = signs * geom.lengths
    zf = z[fe]  # (F, 3) or (F, 3, C)
    if z.dim() == 2:
        weights = weights[..., None]
    area = geom.area if z.dim() == 1 else geom.area[:, None]
    return (weights * zf.real).sum(1), (weights * zf.imag).sum(1), area


def face_curl(verts, topo, z) -> torch.Tensor:
    """(F,) or (F, C) face-wise curl ``curl_T = K Re(z) / A_T`` (circulation theorem, 3.3)."""
    re, _, area = _face_circulation(verts, topo, z)
    return re / area


def face_div(verts, topo, z) -> torch.Tensor:
    """(F,) or (F, C) face-wise divergence ``div_T = -K Im(z) / A_T`` (3.3)."""
    _, im, area = _face_circulation(verts, topo, z)
    return -im / area


def vertex_div_curl(verts, topo, z) -> tuple[torch.Tensor, torch.Tensor]:
    """Vertex-wise divergence and curl from the adjoint of the gradient (thesis 4.2, B.4).

    .. math::  M_v (\\operatorname{div}_v + \\imath \\operatorname{curl}_v) = -G^* z

    with the lumped vertex mass ``M_v``. Unreferenced vertices get 0.

    Returns
    -------
    div, curl : (V,) or (V, C) real tensors.
    """
    verts, topo, geom, signs = prepare(verts, topo)
    z = as_edge_field(z, topo, verts)
    g = cached_pattern(topo, "EV").assemble(gradient_values(geom, signs))
    gz = -(g.conj().transpose(0, 1) @ z)
    mass = vertex_mass(verts, topo, lumped=True).values()
    mass = torch.where(mass > 0, mass, torch.ones_like(mass))
    out = gz / (mass if z.dim() == 1 else mass[:, None])
    return out.real, out.imag


def real_form(a: torch.Tensor) -> torch.Tensor:
    """The real ``(2M, 2N)`` form of a complex ``(M, N)`` sparse matrix (thesis 3.3).

    .. math::  \\begin{pmatrix} \\operatorname{Re} A & -\\operatorname{Im} A \\\\
               \\operatorname{Im} A & \\operatorname{Re} A \\end{pmatrix},

    acting on ``(Re z, Im z)``. A real input is treated as having zero imaginary part.
    """
    if not a.is_sparse:
        raise ValueError("real_form expects a sparse COO tensor")
    a = a.coalesce()
    m, n = a.shape
    idx, val = a.indices(), a.values()
    re, im = (val.real, val.imag) if val.is_complex() else (val, torch.zeros_like(val))
    shift_r = torch.tensor([[m], [0]], device=idx.device)
    shift_c = torch.tensor([[0], [n]], device=idx.device)
    indices = torch.cat([idx, idx + shift_c, idx + shift_r, idx + shift_r + shift_c], dim=1)
    values = torch.cat([re, -im, im, re])
    return torch.sparse_coo_tensor(indices, values, (2 * m, 2 * n), check_invariants=False).coalesce()


def curl_energy(verts, topo=None) -> torch.Tensor:
    """``L_curl = [[K^T M_t^{-1} K, 0], [0, 0]]``, ``(2E, 2E)`` real (thesis 3.3).

    ``x^T L_curl x = int curl(psi)^2`` for ``x = (Re z, Im z)``.
    """
    block, ne = curl_energy_block(verts, topo)
    return embed_block(block, 0, 2 * ne)


def div_energy(verts, topo=None) -> torch.Tensor:
    """``L_div = [[0, 0], [0, K^T M_t^{-1} K]]``, ``(2E, 2E)`` real (thesis 3.3)."""
    block, ne = curl_energy_block(verts, topo)
    return embed_block(block, ne, 2 * ne)


def laplace_beltrami(verts, topo=None) -> torch.Tensor:
    """The Laplace-Beltrami stiffness ``L = Re(G^* M_z^{-1} G)`` (thesis 4.2).

    Real, symmetric, positive semi-definite, constants in its kernel; acts on the 2-ring.
    On closed meshes ``G^* M_z^{-1} G`` is real; with a boundary its imaginary part is the
    antisymmetric form ``int grad g x grad f`` (a boundary integral), and ``L`` is the real
    part, the Dirichlet form ``int grad g . grad f``.
    Pair it with :func:`vertex_mass` (full) for the generalized eigenproblem ``L f = lambda M_v f``.

    Returns
    -------
    (V, V) real sparse tensor.
    """
    verts, topo, geom, signs = prepare(verts, topo)
    g = cached_pattern(topo, "EV").assemble(gradient_values(geom, signs))
    return laplace_beltrami_from(g.values(), mass_values(geom, topo), topo)


def vertex_mass(verts, topo=None, lumped: bool = False) -> torch.Tensor:
    """The P1 vertex mass matrix ``M_v``: full FEM (default) or lumped (``A/3`` per face).

    Returns
    -------
    (V, V) real sparse tensor (diagonal when ``lumped``).
    """
    verts, topo, geom, _ = prepare(verts, topo)
    return vertex_mass_from(geom, topo, lumped)


def covariant_derivative(verts, topo, w, n: int = 1) -> torch.Tensor:
    """The covariant derivative ``D_w`` along the edge field ``w`` (thesis 5.1, A.5).

    ``M_z x = D_w z`` gives the edge field ``x`` of ``nabla_w psi``; per face,

    .. math::  (D_w)_{ab} \\mathrel{+}= -\\delta_b \\frac{|e_b|}{3}
               \\operatorname{Im}(w_a r_{ab})\\, r_{ba}^n

    including ``a = b`` (``r_aa = 1``), whose contributions cancel on interior edges and
    leave the boundary diagonal. Real-linear (not complex-linear) in ``w``.  For ``n > 1``
    it acts on the representation vectors of ``n``-direction fields (frames ``u^n``, as
    in the connection Laplacian ``L_c^(n)``); ``w`` is always a vector field.

    Parameters
    ----------
    w : (E,) complex tensor (a real tensor is taken as having zero imaginary part)
    n : int >= 1, the symmetry of the fields the operator acts on

    Returns
    -------
    (E, E) complex sparse tensor.
    """
    n = check_n(n)
    verts, topo, geom, signs = prepare(verts, topo)
    w = as_edge_field(w, topo, verts, name="w")
    if w.dim() != 1:
        raise ValueError(f"w must have shape (E,), got {tuple(w.shape)}")
    return covariant_from(geom, signs, topo, w, n)


def cotan_laplacian(verts, topo=None) -> torch.Tensor:
    """The cotangent Laplacian, as a positive semi-definite stiffness matrix (for comparison).

    .. math::  C_{ij} = -\\tfrac12 (\\cot \\alpha_{ij} + \\cot \\beta_{ij}), \\quad C_{ii} = -\\sum_j C_{ij}

    Returns
    -------
    (V, V) real sparse tensor.
    """
    verts, topo, geom, _ = prepare(verts, topo)
    cot = geom.cotangents
    off = torch.as_tensor(OFF_DIAGONAL, device=cot.device)
    diag = 0.5 * (cot.sum(1, keepdim=True) - pair_columns(cot, "a"))
    vals = torch.where(off, -0.5 * pair_columns(cot, "c"), diag)
    return cached_pattern(topo, "VV").assemble(vals.flatten())
