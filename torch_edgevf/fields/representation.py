"""Evaluating, converting and drawing edge-based fields (thesis 2.1, 2.2, 6.2, 6.3).

An edge field is a complex ``(E,)`` tensor ``z``: ``z[e]`` is the field's value at the
midpoint of edge ``e = (i, j)``, ``i < j``, in the frame ``X_e = (v_j - v_i) / |e|``
(``Y_e`` is ``X_e`` turned by +90 degrees about the surface normal, so
``psi = Re(z) X_e + Im(z) Y_e``). An ``n``-direction field is stored by its
*representation vector*, the angle-based ``n``-th power of one of its directions
(thesis 2.2): :func:`~torch_edgevf.fields.powers.nth_power` and
:func:`~torch_edgevf.fields.powers.nth_root`.

Frames used here (all right-handed about the outward normal, ``Y = N x X``):

=============  ===========================================================================
where          ``X``
=============  ===========================================================================
edge midpoint  the unit edge vector from the lower to the higher vertex index; ``N`` is the
               normalised sum of the adjacent face normals
face           the unit vector of the face's first edge, ``f0 -> f1``; ``N`` the face normal
vertex         the *first outgoing edge* of the vertex (see :func:`vertex_frames`), in the
               angle-rescaled tangent plane of thesis 6.2; ``N`` the angle-weighted normal
=============  ===========================================================================

Inside a face ``T`` with corners ``k = 0, 1, 2``, barycentric coordinates ``b_k`` and the
mid-edge hat functions ``phi_k = 1 - 2 b_k`` (``phi_k = 1`` at the midpoint of the edge
opposite corner ``k`` and 0 at the two other midpoints), the field is (thesis 2.1)

.. math::  \\psi(p) = \\sum_k \\phi_k(p)\\, u_k^n\\, z_{e_k},

where ``u_k`` is the unit complex number of ``X_{e_k}`` in the face frame ``X_T`` and
``e_k`` the edge opposite corner ``k``. Every function is differentiable with respect to
``verts`` and ``z``; dtype and device follow ``verts``.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import torch

from .._dtypes import complex_dtype
from .._validation import as_edge_field, check_n, list_some
from ..mesh.geometry import (
    FaceGeometry,
    face_geometry,
    face_geometry_of,
    face_normals,
    topology_and_verts,
    vertex_normals,
)
from ..mesh.topology import Topology
from .powers import _as_complex, nth_roots

__all__ = [
    "face_frames",
    "edge_frames",
    "vertex_frames",
    "face_edge_coefficients",
    "interpolate",
    "face_values",
    "to_vectors",
    "point_vectors",
    "edge_vectors",
    "edges_from_vectors",
    "face_vectors",
    "vertex_vectors",
    "edge_directions",
    "face_directions",
    "vertex_directions",
    "point_directions",
    "vertex_transport",
    "edges_to_vertices",
    "vertices_to_edges",
    "to_one_form",
    "from_one_form",
]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- frames


def _normalize(x: torch.Tensor) -> torch.Tensor:
    norm = torch.linalg.vector_norm(x, dim=-1, keepdim=True)
    return x / torch.where(norm > 0, norm, torch.ones_like(norm))


def face_frames(verts, topo) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The face frames ``X_T`` (first edge ``f0 -> f1``), ``Y_T = N_T x X_T`` and ``N_T``.

    Returns
    -------
    X, Y, N : (F, 3) tensors, orthonormal per face.
    """
    verts, topo = topology_and_verts(verts, topo)
    faces = topo.faces.to(verts.device)
    normal = face_normals(verts, topo)
    x = _normalize(verts[faces[:, 1]] - verts[faces[:, 0]])
    return x, torch.linalg.cross(normal, x), normal


def edge_frames(verts, topo) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The edge-midpoint frames ``X_e`` (from the lower to the higher index), ``Y_e``, ``N_e``.

    ``N_e`` is the normalised sum of the normals of the (one or two) adjacent faces, so it
    is orthogonal to the edge and ``Y_e = N_e x X_e`` bisects the two unfolded faces'
    in-plane normals of the edge.

    Returns
    -------
    X, Y, N : (E, 3) tensors.
    """
    verts, topo = topology_and_verts(verts, topo)
    e = topo.edges.to(verts.device)
    ef = topo.edge_faces.to(verts.device)
    nf = face_normals(verts, topo)
    present = (ef >= 0).to(verts.dtype)[..., None]
    normal = _normalize((nf[ef.clamp(min=0)] * present).sum(1))
    x = _normalize(verts[e[:, 1]] - verts[e[:, 0]])
    return x, torch.linalg.cross(normal, x), normal


def face_edge_coefficients(verts, topo, n: int = 1, geom: FaceGeometry | None = None) -> torch.Tensor:
    """``u[f, k]**n``: the unit complex number of the edge frame ``X_{e_k}`` in the face frame.

    With ``delta_k`` the orientation signs and ``alpha_k`` the corner angles,

    .. math::  u_0 = -\\delta_0 e^{-\\imath \\alpha_1}, \\quad
               u_1 = -\\delta_1 e^{\\imath \\alpha_0}, \\quad u_2 = \\delta_2,

    since the edge opposite corner 2 runs ``f0 -> f1`` counter-clockwise.

    Returns
    -------
    (F, 3) complex tensor.
    """
    n = check_n(n)
    verts, topo = topology_and_verts(verts, topo)
    geom = face_geometry(verts, topo) if geom is None else geom
    return _face_edge_coefficients(geom, topo, n)


def _face_edge_coefficients(geom: FaceGeometry, topo: Topology, n: int) -> torch.Tensor:
    alpha = geom.angles
    zero = torch.zeros_like(alpha[:, 0])
    phase = torch.stack([math.pi - alpha[:, 1], math.pi + alpha[:, 0], zero], dim=1)
    signs = topo.face_edge_signs.to(device=alpha.device, dtype=alpha.dtype) ** n
    return torch.polar(torch.ones_like(phase), n * phase) * signs


def to_vectors(x: torch.Tensor, y: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """3D vectors ``Re(w) X + Im(w) Y`` from complex values in a frame.

    Parameters
    ----------
    x, y : (P, 3) tensors, the frame
    w : (P,) or (P, K) complex tensor

    Returns
    -------
    (P, 3) or (P, K, 3) tensor.
    """
    if w.dim() == 2:
        x, y = x[:, None, :], y[:, None, :]
    return w.real[..., None] * x + w.imag[..., None] * y


# --------------------------------------------------------------------------- inside faces


def _check_points(face_index, bary, topo: Topology, like: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    face_index = torch.as_tensor(face_index, device=like.device)
    if face_index.is_floating_point() or face_index.is_complex() or face_index.dtype == torch.bool:
        raise ValueError(f"face_index must be an integer tensor, got {face_index.dtype}")
    face_index = face_index.to(torch.int64)
    if face_index.dim() != 1:
        raise ValueError(f"face_index must have shape (P,), got {tuple(face_index.shape)}")
    bad = torch.nonzero((face_index < 0) | (face_index >= topo.num_faces)).flatten().tolist()
    if bad:
        raise ValueError(
            f"face_index out of range (the mesh has {topo.num_faces} faces) at points [{list_some(bad)}]"
        )
    bary = torch.as_tensor(bary, device=like.device)
    if not bary.is_floating_point():
        raise ValueError(f"bary must be a floating tensor, got {bary.dtype}")
    bary = bary.to(like.dtype)
    if bary.shape != (face_index.shape[0], 3):
        raise ValueError(f"bary must have shape ({face_index.shape[0]}, 3), got {tuple(bary.shape)}")
    tol = 1e-6 if like.dtype == torch.float64 else 1e-4
    b = bary.detach()
    outside = torch.nonzero(((b.sum(1) - 1).abs() > tol) | (b < -tol).any(1) | ~torch.isfinite(b).all(1))
    if outside.numel():
        raise ValueError(
            "bary must hold barycentric coordinates of points inside their faces "
            f"(non-negative, summing to 1); violated at points [{list_some(outside.flatten().tolist())}]"
        )
    return face_index, bary


def interpolate(verts, topo, z, face_index, bary, n: int = 1) -> torch.Tensor:
    """The field at points inside faces, in the face frame ``X_T`` (thesis 2.1, eq. 2.1).

    .. math::  \\psi(p) = \\sum_{k=0}^{2} (1 - 2 b_k)\\, u_k^n\\, z_{e_k}

    with ``b`` the barycentric coordinates of ``p`` and ``u_k`` from
    :func:`face_edge_coefficients`. For ``n > 1``, ``z`` is a representation vector and so
    is the result (take :func:`~torch_edgevf.fields.powers.nth_root`, or use :func:`point_directions`).

    Parameters
    ----------
    verts : (V, 3) tensor
    topo : Topology or (F, 3) faces
    z : (E,) complex tensor
    face_index : (P,) integer tensor
    bary : (P, 3) tensor, barycentric coordinates w.r.t. the face's corners ``f0, f1, f2``
    n : int, symmetry order of the representation vector

    Returns
    -------
    (P,) complex tensor.
    """
    verts, topo, z, n = _field_of(verts, topo, z, n)
    face_index, bary = _check_points(face_index, bary, topo, verts)
    u = _face_edge_coefficients(face_geometry_of(verts, topo), topo, n)[face_index]
    fe = topo.face_edges.to(verts.device)[face_index]
    return ((1 - 2 * bary).to(u.dtype) * u * z[fe]).sum(1)


def _field_of(verts, topo, z, n: int):
    """The checked arguments of a function of one edge field: ``(verts, topo, z, n)``."""
    n = check_n(n)
    verts, topo = topology_and_verts(verts, topo)
    return verts, topo, _edge_vector(z, topo, verts), n


def _edge_vector(z, topo: Topology, verts: torch.Tensor, name: str = "z") -> torch.Tensor:
    z = as_edge_field(z, topo, verts, name)
    if z.dim() != 1:
        raise ValueError(f"{name} must have shape (E,) with E = {topo.num_edges}, got {tuple(z.shape)}")
    return z


def face_values(verts, topo, z, n: int = 1) -> torch.Tensor:
    """The field at face barycenters in the face frame: a face-based field (thesis 6.1).

    .. math::  w_T = \\tfrac13 \\sum_k u_k^n z_{e_k}

    (every ``phi_k = 1/3`` at the barycenter), which is also the mean of the field over the
    face.

    Returns
    -------
    (F,) complex tensor.
    """
    verts, topo, z, n = _field_of(verts, topo, z, n)
    u = _face_edge_coefficients(face_geometry_of(verts, topo), topo, n)
    return (u * z[topo.face_edges.to(verts.device)]).sum(1) / 3


def point_vectors(verts, topo, z, face_index, bary) -> torch.Tensor:
    """(P, 3) 3D vectors of a vector field (``n = 1``) at points inside faces."""
    verts, topo = topology_and_verts(verts, topo)
    w = interpolate(verts, topo, z, face_index, bary)
    x, y, _ = face_frames(verts, topo)
    idx = torch.as_tensor(face_index, device=verts.device).to(torch.int64)
    return to_vectors(x[idx], y[idx], w)


def edge_vectors(verts, topo, z) -> torch.Tensor:
    """(E, 3) 3D vectors ``Re(z) X_e + Im(z) Y_e`` of a vector field at edge midpoints."""
    verts, topo = topology_and_verts(verts, topo)
    z = _edge_vector(z, topo, verts)
    x, y, _ = edge_frames(verts, topo)
    return to_vectors(x, y, z)


def edges_from_vectors(verts, topo, vectors) -> torch.Tensor:
    """The edge field of ambient vectors at edge midpoints: the inverse of :func:`edge_vectors`.

    .. math::  z_e = \\langle v_e, X_e \\rangle + \\imath \\langle v_e, Y_e \\rangle

    with the edge frames ``X_e, Y_e`` of :func:`edge_frames`: the projection of ``v_e`` on
    the tangent plane at the edge midpoint (its component along ``N_e`` is dropped), so
    ``edges_from_vectors(verts, topo, edge_vectors(verts, topo, z)) == z``.

    Parameters
    ----------
    vectors : (E, 3) real tensor, one vector per edge in the order of ``topo.edges``

    Returns
    -------
    (E,) complex tensor, in the complex dtype of ``verts``.
    """
    verts, topo = topology_and_verts(verts, topo)
    vectors = torch.as_tensor(vectors)
    if vectors.shape != (topo.num_edges, 3):
        raise ValueError(
            f"vectors must have shape (E, 3) with E = {topo.num_edges}, got {tuple(vectors.shape)}"
        )
    if not vectors.is_floating_point():
        raise ValueError(f"vectors must be a real floating tensor, got {vectors.dtype}")
    vectors = vectors.to(device=verts.device, dtype=verts.dtype)
    x, y, _ = edge_frames(verts, topo)
    return torch.complex((vectors * x).sum(1), (vectors * y).sum(1))


def face_vectors(verts, topo, z) -> torch.Tensor:
    """(F, 3) 3D vectors of a vector field at face barycenters (:func:`face_values`)."""
    verts, topo = topology_and_verts(verts, topo)
    x, y, _ = face_frames(verts, topo)
    return to_vectors(x, y, face_values(verts, topo, z))


def vertex_vectors(verts, topo, z) -> torch.Tensor:
    """(V, 3) 3D vectors of a vector field at vertices (:func:`edges_to_vertices`).

    The vertex value lives in the angle-rescaled tangent plane (thesis 6.2); it is drawn in
    the 3D frame of :func:`vertex_frames`, whose angles match the rescaled ones only up to
    the rescaling (exactly where the angle defect is zero).
    """
    verts, topo = topology_and_verts(verts, topo)
    x, y, _ = vertex_frames(verts, topo)
    return to_vectors(x, y, edges_to_vertices(verts, topo, z))


def _directions(x, y, w, n) -> torch.Tensor:
    return to_vectors(x, y, nth_roots(w, n))


def edge_directions(verts, topo, z, n: int) -> torch.Tensor:
    """The ``n`` directions of an ``n``-direction field at edge midpoints.

    Returns
    -------
    (E, n, 3) tensor: ``nth_roots(z, n)`` drawn in the edge frames; direction ``k`` is
    direction 0 turned by ``2 pi k / n``.
    """
    verts, topo, z, n = _field_of(verts, topo, z, n)
    x, y, _ = edge_frames(verts, topo)
    return _directions(x, y, z, n)


def face_directions(verts, topo, z, n: int) -> torch.Tensor:
    """(F, n, 3) the ``n`` directions at face barycenters (root of :func:`face_values`)."""
    n = check_n(n)
    verts, topo = topology_and_verts(verts, topo)
    x, y, _ = face_frames(verts, topo)
    return _directions(x, y, face_values(verts, topo, z, n), n)


def point_directions(verts, topo, z, face_index, bary, n: int) -> torch.Tensor:
    """(P, n, 3) the ``n`` directions at points inside faces (root of :func:`interpolate`)."""
    n = check_n(n)
    verts, topo = topology_and_verts(verts, topo)
    w = interpolate(verts, topo, z, face_index, bary, n)
    x, y, _ = face_frames(verts, topo)
    idx = torch.as_tensor(face_index, device=verts.device).to(torch.int64)
    return _directions(x[idx], y[idx], w, n)


def vertex_directions(verts, topo, z, n: int) -> torch.Tensor:
    """(V, n, 3) the ``n`` directions at vertices (root of :func:`edges_to_vertices`)."""
    n = check_n(n)
    verts, topo = topology_and_verts(verts, topo)
    x, y, _ = vertex_frames(verts, topo)
    return _directions(x, y, edges_to_vertices(verts, topo, z, n), n)


# --------------------------------------------------------------------------- vertices


def _vertex_fans(topo: Topology):
    """Corners around each vertex in counter-clockwise order (cached on the topology).

    Corner ``c = 3 f + k`` sits at vertex ``faces[f, k]`` and spans the angle from its
    *first* outgoing edge ``v -> f[k+1]`` (the edge opposite corner ``k+2``) to its second
    ``v -> f[k+2]``. The next corner counter-clockwise shares that second edge. A fan
    starts at the vertex's lowest corner index (interior vertices) or at the corner with
    no predecessor (boundary vertices).

    Returns
    -------
    dict of int64 numpy arrays: ``order`` (corners sorted by vertex then fan position),
    ``vertex`` (vertex of each entry of ``order``), ``start`` (first corner per vertex,
    ``-1`` if unreferenced), ``pairs_vertex``, ``pairs_edge``, ``pairs_corner``,
    ``pairs_second`` (one row per vertex-edge incidence: the corner whose first edge it is,
    or, for the last edge of a boundary fan, whose second edge it is).
    """

    def build():
        f = topo.faces.numpy()
        fe = topo.face_edges.numpy()
        ef = topo.edge_faces.numpy()
        nf, nv = f.shape[0], topo.num_vertices
        corner_vertex = f.ravel()
        k = np.tile(np.arange(3), nf)
        face = np.repeat(np.arange(nf), 3)
        second_edge = fe[face, (k + 1) % 3]
        other = np.where(ef[second_edge, 0] == face, ef[second_edge, 1], ef[second_edge, 0])
        nxt = np.full(3 * nf, -1, dtype=np.int64)
        has = other >= 0
        g = other[has]
        kk = np.argmax(f[g] == corner_vertex[has][:, None], axis=1)
        nxt[has] = 3 * g + kk
        prev = np.full(3 * nf, -1, dtype=np.int64)
        prev[nxt[has]] = np.flatnonzero(has)

        corners = np.arange(3 * nf)
        lowest = np.full(nv, 3 * nf, dtype=np.int64)
        np.minimum.at(lowest, corner_vertex, corners)
        start = np.where(lowest < 3 * nf, lowest, -1)
        boundary_first = corners[prev < 0]
        start[corner_vertex[boundary_first]] = boundary_first

        rank = np.full(3 * nf, -1, dtype=np.int64)
        current = start[start >= 0].copy()
        step = 0
        while current.size:
            rank[current] = step
            current = nxt[current]
            current = current[(current >= 0)]
            current = current[rank[current] < 0]
            step += 1
        if (rank < 0).any():  # cannot happen on a manifold topology
            bad = list_some(np.unique(corner_vertex[rank < 0]))
            raise ValueError(f"could not order the corners around vertices [{bad}]")
        order = np.lexsort((rank, corner_vertex))
        first_edge = fe[face, (k + 2) % 3]
        last = np.flatnonzero(nxt < 0)
        pairs_corner = np.concatenate([corners, last])
        pairs_second = np.concatenate([np.zeros(3 * nf, bool), np.ones(last.size, bool)])
        pairs_edge = np.concatenate([first_edge, second_edge[last]])
        return {
            "order": order,
            "vertex": corner_vertex[order],
            "start": start,
            "pairs_vertex": corner_vertex[pairs_corner],
            "pairs_edge": pairs_edge,
            "pairs_corner": pairs_corner,
            "pairs_second": pairs_second,
        }

    return topo.cached("fields.vertex_fans", build)


def vertex_transport(verts, topo, n: int = 1) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Transport coefficients ``r_ve`` from vertices to the midpoints of their edges (6.2).

    Around vertex ``v`` the faces are unfolded in counter-clockwise order from the vertex
    frame ``X_v`` (its first outgoing edge, see :func:`vertex_frames`); ``theta`` is the
    unfolded angle of the outgoing edge ``v -> w`` and ``s_v`` the angle-defect rescaling
    factor

    .. math::  s_v = \\frac{2\\pi}{\\sum_{T \\ni v} \\alpha_v}\\ \\text{(interior)}, \\qquad
               s_v = 1\\ \\text{(boundary: no closing condition)},

    so that the rescaled angles ``s_v theta`` close up to ``2 pi``. A vector at angle
    ``phi`` from ``X_v`` is at angle ``phi - s_v theta`` from the direction ``v -> w`` at the
    midpoint, and that direction is ``+X_e`` when ``v < w`` and ``-X_e`` otherwise:

    .. math::  r_{ve} = \\pm e^{-\\imath s_v \\theta}, \\qquad z_e = r_{ve}^n z_v.

    (The thesis writes ``e^{-i s theta}`` with ``theta`` the angle of ``X_e`` itself; the
    two agree for ``v < w``; here the flip by ``pi`` is applied after rescaling, so that a
    field along the edge stays along it.)

    Returns
    -------
    vertex, edge : (P,) int64 tensors, one row per vertex-edge incidence
    r : (P,) complex tensor ``r_ve ** n``
    """
    n = check_n(n)
    verts, topo = topology_and_verts(verts, topo)
    return _vertex_transport(verts, topo, n)


def _vertex_transport(verts, topo: Topology, n: int):
    fans = _vertex_fans(topo)
    dev = verts.device
    geom = face_geometry(verts, topo)
    alpha = geom.angles.flatten()
    order = torch.from_numpy(fans["order"]).to(dev)
    fan_vertex = torch.from_numpy(fans["vertex"]).to(dev)
    a_sorted = alpha[order]
    csum = torch.cumsum(a_sorted, 0)
    total = verts.new_zeros(topo.num_vertices).index_add(0, fan_vertex, a_sorted)
    # start offset of each vertex's segment in the cumulative sum
    counts = torch.bincount(fan_vertex, minlength=topo.num_vertices)
    seg_start = torch.cumsum(counts, 0) - counts
    before = torch.cat([csum.new_zeros(1), csum])[seg_start][fan_vertex]
    theta_sorted = csum - a_sorted - before  # angle of the corner's first edge
    theta = torch.empty_like(alpha).index_put((order,), theta_sorted)

    pc = torch.from_numpy(fans["pairs_corner"]).to(dev)
    pv = torch.from_numpy(fans["pairs_vertex"]).to(dev)
    pe = torch.from_numpy(fans["pairs_edge"]).to(dev)
    second = torch.from_numpy(fans["pairs_second"]).to(dev)
    angle = theta[pc] + torch.where(second, alpha[pc], torch.zeros_like(alpha[pc]))
    boundary = topo.boundary_vertices.to(dev)
    safe_total = torch.where(total > 0, total, torch.ones_like(total))
    s = torch.where(boundary, torch.ones_like(total), 2 * math.pi / safe_total)
    low = topo.edges.to(dev)[pe, 0] == pv
    sign = torch.where(low, 1.0, -1.0).to(verts.dtype) ** n
    r = torch.polar(torch.ones_like(angle), -n * s[pv] * angle) * sign
    return pv, pe, r


def vertex_frames(verts, topo) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """3D vertex frames ``X_v, Y_v = N_v x X_v, N_v`` matching :func:`vertex_transport`.

    ``X_v`` is the first outgoing edge of ``v`` -- the edge ``v -> f[k+1]`` of the corner
    ``(f, k)`` with the lowest index ``3 f + k`` at an interior vertex, or of the first
    corner of the fan (the one after the boundary) at a boundary vertex -- projected on the
    plane orthogonal to the angle-weighted vertex normal ``N_v`` and normalised.
    Unreferenced vertices get zero rows.

    Returns
    -------
    X, Y, N : (V, 3) tensors.
    """
    verts, topo = topology_and_verts(verts, topo)
    fans = _vertex_fans(topo)
    normal = vertex_normals(verts, topo)
    start = torch.from_numpy(fans["start"]).to(verts.device)
    has = start >= 0
    faces = topo.faces.to(verts.device).flatten()
    c = start.clamp(min=0)
    nxt_corner = 3 * (c // 3) + (c % 3 + 1) % 3
    d = verts[faces[nxt_corner]] - verts
    d = d - (d * normal).sum(-1, keepdim=True) * normal
    x = _normalize(d) * has[:, None].to(verts.dtype)
    return x, torch.linalg.cross(normal, x), normal


def edges_to_vertices(verts, topo, z, n: int = 1) -> torch.Tensor:
    """Edge values to vertex values by averaging the transported values (thesis 6.2).

    .. math::  z_v = \\frac{1}{|E_v|} \\sum_{e \\ni v} \\bar r_{ve}^{\\,n} z_e

    in the vertex frame of :func:`vertex_transport` (angle-defect rescaled). Unreferenced
    vertices get 0.

    Parameters
    ----------
    z : (E,) complex tensor (representation vector for ``n > 1``)

    Returns
    -------
    (V,) complex tensor.
    """
    verts, topo, z, n = _field_of(verts, topo, z, n)
    pv, pe, r = _vertex_transport(verts, topo, n)
    acc = z.new_zeros(topo.num_vertices).index_add(0, pv, r.conj() * z[pe])
    count = torch.bincount(pv, minlength=topo.num_vertices).to(verts.dtype)
    return acc / torch.where(count > 0, count, torch.ones_like(count))


def vertices_to_edges(verts, topo, zv, n: int = 1) -> torch.Tensor:
    """Vertex values to edge values: the mean of the two transported values (thesis 6.2).

    .. math::  z_e = \\tfrac12 (r_{ie}^n z_i + r_{je}^n z_j), \\qquad e = (i, j)

    Parameters
    ----------
    zv : (V,) complex tensor in the frames of :func:`vertex_transport`

    Returns
    -------
    (E,) complex tensor.
    """
    n = check_n(n)
    verts, topo = topology_and_verts(verts, topo)
    zv = _as_complex(zv, "zv")
    if zv.shape != (topo.num_vertices,):
        raise ValueError(f"zv must have shape ({topo.num_vertices},), got {tuple(zv.shape)}")
    target = complex_dtype(verts.dtype)
    if zv.dtype != target:
        raise ValueError(f"zv has dtype {zv.dtype} but the mesh is {verts.dtype}: expected {target}")
    zv = zv.to(verts.device)
    pv, pe, r = _vertex_transport(verts, topo, n)
    out = zv.new_zeros(topo.num_edges).index_add(0, pe, r * zv[pv])
    return out / 2


# --------------------------------------------------------------------------- one-forms


def to_one_form(verts, topo, z, orthogonal: bool = False) -> torch.Tensor:
    """The DEC one-form of an edge field (thesis 6.3): ``c_e = |e| Re(z_e)``.

    By the integral property (3.2), ``c_e`` is the line integral of the field along the
    edge, oriented from the lower to the higher index. With ``orthogonal=True`` returns
    the conjugate form ``c_perp = |e| Im(z_e)`` (the flux across the edge); ``c + i c_perp
    = |e| z``.

    Returns
    -------
    (E,) real tensor.
    """
    verts, topo = topology_and_verts(verts, topo)
    z = _edge_vector(z, topo, verts)
    e = topo.edges.to(verts.device)
    length = torch.linalg.vector_norm(verts[e[:, 1]] - verts[e[:, 0]], dim=-1)
    return length * (z.imag if orthogonal else z.real)


def from_one_form(verts, topo, c, c_perp=None) -> torch.Tensor:
    """The edge field of a DEC one-form (thesis 6.3): ``z_e = (c_e + i c_perp_e) / |e|``.

    A one-form determines only the tangential (real) part of the field along each edge;
    the normal part is ``c_perp / |e|`` when the conjugate form is given and 0 otherwise
    (so ``from_one_form(to_one_form(z))`` keeps ``Re(z)`` exactly and drops ``Im(z)``).

    Parameters
    ----------
    c : (E,) real tensor
    c_perp : (E,) real tensor, optional

    Returns
    -------
    (E,) complex tensor.
    """
    verts, topo = topology_and_verts(verts, topo)
    e = topo.edges.to(verts.device)
    length = torch.linalg.vector_norm(verts[e[:, 1]] - verts[e[:, 0]], dim=-1)

    def check(x, name):
        x = torch.as_tensor(x, device=verts.device)
        if not x.is_floating_point():
            raise ValueError(f"{name} must be a real floating tensor, got {x.dtype}")
        if x.shape != (topo.num_edges,):
            raise ValueError(f"{name} must have shape ({topo.num_edges},), got {tuple(x.shape)}")
        return x.to(verts.dtype)

    c = check(c, "c")
    im = torch.zeros_like(c) if c_perp is None else check(c_perp, "c_perp")
    return torch.complex(c / length, im / length)
