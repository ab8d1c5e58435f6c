"""Singularities of edge-based n-direction fields: detection, exact location, remeshing.

Thesis section 4.1 and appendix B.2.

Detection
---------
The surface is partitioned into *face regions* (the medial triangle of each face, whose
corners are the three edge midpoints) and *vertex regions* (around each vertex, the union
of the corner triangles cut off by the medial triangles; see thesis figure 4.1 a). The
index of a region is the turning number of the field along its boundary.

Along the mid-segment from ``q_a`` to ``q_b`` inside a face, the Crouzeix-Raviart hat of
the third edge vanishes, so the interpolated representation vector is the linear blend of
``z_a`` and ``z_b`` and it rotates, relative to the (flat) transport, by

.. math::  \\omega_{ab} = \\arg\\left(\\frac{z_b}{z_a\\, r_{ab}^n}\\right) \\in [-\\pi, \\pi].

With ``omega[f, c]`` the rotation along the mid-segment next to corner ``c``, traversed in
the face's counter-clockwise direction ``q_{c+1} -> q_{c+2}``:

.. math::
    I_f = \\frac{1}{2\\pi n} \\sum_{c} \\omega_{fc}, \\qquad
    I_v = \\frac{1}{2\\pi n} \\Big( n\\,\\Omega_v - \\sum_{(f, c) : f_c = v} \\omega_{fc} \\Big)

in turns of the direction field (a cross-field singularity is ``+-1/4``), with
``Omega_v`` the angle defect. The minus sign is the one derivation detail to watch (the
thesis writes ``+ sum omega_jk``): a loop turning counter-clockwise around ``v`` runs
along each mid-segment next to ``v`` in the direction *opposite* to the face's loop
(``q_{c+2} -> q_{c+1}``). Each segment is thus counted once with each sign, the
``omega``'s cancel in the sum, and by the discrete Gauss-Bonnet theorem

.. math::  \\sum_f I_f + \\sum_v I_v = \\chi

*exactly*, on every closed mesh, for every field: the same floating point ``omega`` is used
on both sides of a segment, and every region's sum is an integer multiple of ``2 pi``
(face transport has no holonomy, ``r_01 r_12 r_20 = 1``; a vertex loop's holonomy is
``e^{i n Omega_v}``) up to rounding errors of order ``1e-12``, so each index is rounded to
the nearest multiple of ``1/n`` and the counts are integers. Indices beyond ``+-1/n``
(a vertex region can hold several singularities) are kept, not clipped.

*Zero edge values.* ``arg 0`` is defined as ``0``: a zero value is treated as a vanishing
vector along its edge frame (``z = +eps``). Any convention that assigns one direction per
edge keeps every identity above, so the counts stay integral and sum to ``chi``; zeros
only decide in which neighbouring region a singularity sitting on an edge midpoint is
counted. An antipodal pair ``omega = +-pi`` (the linear blend passes through zero on the
segment) is likewise resolved by ``torch.angle``, identically for both regions.

*Boundary convention.* A boundary vertex's region is a half disk whose boundary runs
along the interior mid-segments (counter-clockwise) and back along the two boundary half
edges through the vertex, where the boundary turns by ``Omega_v = pi - sum alpha``. The
field's rotation along the boundary part is not defined by the representation (the
Crouzeix-Raviart field is not continuous at vertices), so it is taken to be the rotation
that matches the boundary's turning as closely as possible: with ``boundary="round"``
(the default) a boundary vertex gets the same formula as an interior vertex, rounded to
the nearest ``1/n``. A field at a constant angle to the boundary (tangent or normal, such
as the source ``p`` or the vortex ``J p`` on a disk) then gets index 0 at boundary
vertices and ``sum = chi``. In general

.. math::  \\sum_f I_f + \\sum_v I_v = \\chi + B,

where ``B`` (:attr:`Singularities.boundary_turning`) measures how much the field winds
relative to the boundary: the fractional parts dropped at the boundary vertices (for
``z -> conj(p)`` on a disk, ``B = -2`` and the interior index is ``-1``). With
``boundary="exclude"`` the boundary vertices get index 0 and ``B`` takes their whole
turning.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from .._validation import as_edge_field, check_n
from ..mesh.geometry import (
    FaceGeometry,
    angle_defects_of,
    face_geometry,
    face_geometry_of,
    face_normals,
    pair_transport,
    topology_and_verts,
)
from ..mesh.topology import Topology
from ..operators.kernels import intrinsic_topology

__all__ = [
    "Singularities",
    "singularities",
    "face_rotations",
    "locate_singularities",
    "SingularityLocation",
    "split_faces",
    "split_singular_faces",
    "SplitResult",
    "face_frame_angles",
]

_BOUNDARY = ("round", "exclude")


@dataclass
class Singularities:
    """Indices of an n-direction field, per face region and per vertex region.

    Attributes
    ----------
    face_index : (F,) float tensor
        Index of each face region, in turns of the direction field (multiples of ``1/n``).
    vertex_index : (V,) float tensor
        Index of each vertex region (0 for unreferenced vertices).
    face_winding, vertex_winding : int64 tensors
        The same as integers: ``n * index``.
    n : int
    euler_characteristic : int
    boundary_turning : float
        ``B`` in ``total = chi + B`` (0 on closed meshes; see the module docstring).
    max_rounding_error : float
        Largest distance of a region's turning number (times ``n``) to the integer it was
        rounded to, excluding boundary vertices; ``~1e-12`` in float64, a health check.
    """

    face_index: torch.Tensor
    vertex_index: torch.Tensor
    face_winding: torch.Tensor
    vertex_winding: torch.Tensor
    n: int
    euler_characteristic: int
    boundary_turning: float = 0.0
    max_rounding_error: float = 0.0
    _extra: dict = field(default_factory=dict, repr=False)

    @property
    def total(self) -> float:
        """Sum of all indices; equals the Euler characteristic on closed meshes."""
        return (int(self.face_winding.sum()) + int(self.vertex_winding.sum())) / self.n

    @property
    def singular_faces(self) -> torch.Tensor:
        """(K,) int64 indices of the faces with a non-zero index."""
        return torch.nonzero(self.face_winding).flatten()

    @property
    def singular_vertices(self) -> torch.Tensor:
        """(K,) int64 indices of the vertices with a non-zero index."""
        return torch.nonzero(self.vertex_winding).flatten()

    @property
    def singular_face_index(self) -> torch.Tensor:
        """(K,) the indices of :attr:`singular_faces`."""
        return self.face_index[self.singular_faces]

    @property
    def singular_vertex_index(self) -> torch.Tensor:
        """(K,) the indices of :attr:`singular_vertices`."""
        return self.vertex_index[self.singular_vertices]

    @property
    def num_singularities(self) -> int:
        """Number of singular regions (faces and vertices)."""
        return int((self.face_winding != 0).sum()) + int((self.vertex_winding != 0).sum())

    def as_list(self) -> list[tuple[str, int, float]]:
        """``[("face" | "vertex", element index, index), ...]`` for every singular region."""
        out = [("face", int(i), float(self.face_index[i])) for i in self.singular_faces]
        out += [("vertex", int(i), float(self.vertex_index[i])) for i in self.singular_vertices]
        return out

    def counts(self) -> dict[float, int]:
        """Number of singular regions per index value, e.g. ``{0.25: 8}``."""
        vals = torch.cat([self.singular_face_index, self.singular_vertex_index]).tolist()
        out: dict[float, int] = {}
        for v in vals:
            out[v] = out.get(v, 0) + 1
        return dict(sorted(out.items()))

    def __repr__(self) -> str:
        return (
            f"Singularities(n={self.n}, faces={self.singular_faces.numel()}, "
            f"vertices={self.singular_vertices.numel()}, counts={self.counts()}, total={self.total}, "
            f"chi={self.euler_characteristic}, boundary_turning={self.boundary_turning:.3g})"
        )


def _unit(z: torch.Tensor) -> torch.Tensor:
    """``z / |z|`` with ``arg 0 := 0`` (a zero is a vanishing vector along the edge frame)."""
    a = z.abs()
    return torch.where(a > 0, z / torch.where(a > 0, a, torch.ones_like(a)), torch.ones_like(z))


def _geometry(verts, topo):
    """Detached positions (or a :class:`FaceGeometry` in their place), topology and face geometry."""
    if isinstance(verts, FaceGeometry):
        topo = intrinsic_topology(verts, topo)
        geom = FaceGeometry(verts.lengths.detach(), verts.double_area.detach(), verts.dots.detach())
        return geom, topo, geom
    verts, topo = topology_and_verts(verts, topo)
    verts = verts.detach()
    return verts, topo, face_geometry_of(verts, topo)


def face_rotations(verts, topo, z, n: int = 1) -> torch.Tensor:
    """Rotation of the field along the three mid-segments of every face (thesis 4.1).

    .. math::  \\omega_{fc} = \\arg\\left(\\frac{z_{c+2}}{z_{c+1} r_{c+1, c+2}^n}\\right)

    (indices of the edges opposite the corners), the angle from which the field turns,
    relative to the flat transport, along the mid-segment next to corner ``c``, traversed
    counter-clockwise for the face (from the midpoint of edge ``(c+2, c)`` to that of edge
    ``(c, c+1)``). Not differentiable in a useful sense (piecewise constant counts).

    Returns
    -------
    (F, 3) real tensor in ``[-pi, pi]``.
    """
    verts, topo, geom = _geometry(verts, topo)
    n = check_n(n)
    z = as_edge_field(z, topo, verts).detach()
    if z.dim() != 1:
        raise ValueError(f"z must have shape (E,), got {tuple(z.shape)}")
    signs = topo.face_edge_signs.to(device=verts.device, dtype=verts.dtype)
    r = pair_transport(geom, signs, n).reshape(-1, 3, 3)
    u = _unit(z)[topo.face_edges.to(verts.device)]  # (F, 3)
    a = torch.tensor([1, 2, 0], device=verts.device)
    b = torch.tensor([2, 0, 1], device=verts.device)
    rab = r[:, a, b]  # (F, 3): r_{c+1, c+2}
    return torch.angle(u[:, b] * (u[:, a] * rab).conj())


def singularities(verts, faces, z, n: int = 1, boundary: str = "round") -> Singularities:
    """Detect the singularities of the n-direction field ``z`` (thesis 4.1).

    Parameters
    ----------
    verts : (V, 3) tensor, or a :class:`~torch_edgevf.mesh.geometry.FaceGeometry` in
        their place (intrinsic, e.g. a repaired mesh's mollified lengths)
    faces : (F, 3) int tensor or :class:`Topology`
    z : (E,) complex tensor, the representation vector (``n``-th angle power) per edge
    n : int, the symmetry (1 vector field, 2 line field, 4 cross field)
    boundary : ``"round"`` (default) or ``"exclude"``: index of boundary vertices, see the
        module docstring.

    Returns
    -------
    :class:`Singularities` with ``face_index`` (F,) and ``vertex_index`` (V,) in turns of
    the direction field.

    .. math::
        I_f = \\frac{1}{2\\pi n}\\sum_c \\omega_{fc}, \\qquad
        I_v = \\frac{1}{2\\pi n}\\Big(n\\Omega_v - \\sum_{f_c = v}\\omega_{fc}\\Big)

    Examples
    --------
    >>> s = singularities(verts, faces, z, n=4)
    >>> s.total == topo.euler_characteristic   # closed mesh
    """
    if boundary not in _BOUNDARY:
        raise ValueError(f"boundary must be one of {_BOUNDARY}, got {boundary!r}")
    verts, topo, geom = _geometry(verts, faces)
    n = check_n(n)
    with torch.no_grad():
        omega = face_rotations(verts, topo, z, n).to(torch.float64)
        dev = omega.device
        fl = topo.faces.to(dev)
        two_pi = 2 * math.pi
        face_turn = omega.sum(1) / two_pi
        defect = angle_defects_of(geom, topo).to(torch.float64)
        vsum = torch.zeros(topo.num_vertices, dtype=torch.float64, device=dev).index_add(
            0, fl.flatten(), omega.flatten()
        )
        vert_turn = (n * defect - vsum) / two_pi
        face_k = torch.round(face_turn).to(torch.int64)
        vert_k = torch.round(vert_turn).to(torch.int64)
        bnd = topo.boundary_vertices.to(dev)
        if boundary == "exclude":
            vert_k = torch.where(bnd, torch.zeros_like(vert_k), vert_k)
        interior_err = (vert_turn - vert_k)[~bnd].abs()
        err = max(
            float((face_turn - face_k).abs().max()) if face_k.numel() else 0.0,
            float(interior_err.max()) if interior_err.numel() else 0.0,
        )
        b_turn = float((vert_k - vert_turn)[bnd].sum()) / n if bool(bnd.any()) else 0.0
        dtype = verts.dtype
        return Singularities(
            face_index=face_k.to(dtype) / n,
            vertex_index=vert_k.to(dtype) / n,
            face_winding=face_k,
            vertex_winding=vert_k,
            n=n,
            euler_characteristic=topo.euler_characteristic,
            boundary_turning=b_turn,
            max_rounding_error=err,
        )


# --------------------------------------------------------------------------- location


@dataclass
class SingularityLocation:
    """Zeros of the interpolated representation vector inside faces (thesis 4.1, B.2).

    Attributes
    ----------
    faces : (K,) int64, the face of each singularity
    barycentric : (K, 3) coordinates ``(1 - a - b, a, b)`` w.r.t. the face's corners
    points : (K, 3) positions ``v_0 + a (v_1 - v_0) + b (v_2 - v_0)``
    inside : (K,) bool, all barycentric coordinates >= 0 (always true, up to rounding,
        for a face with a non-zero index: the zero lies in its medial triangle)
    """

    faces: torch.Tensor
    barycentric: torch.Tensor
    points: torch.Tensor
    inside: torch.Tensor


def locate_singularities(verts, faces, z, n: int = 1, which=None) -> SingularityLocation:
    """Exact location of the zero of the field inside faces (thesis 4.1 and B.2).

    Inside a face with corners ``v_1, v_2, v_3`` (edges ``q_i`` opposite them), the
    interpolated representation vector in the frame of edge 1 is
    ``sum_i z_i r_{i1}^n phi_i(a, b)`` with ``phi_1 = 2a + 2b - 1``, ``phi_2 = 1 - 2a``,
    ``phi_3 = 1 - 2b``; it vanishes where

    .. math::
        \\begin{pmatrix} \\operatorname{Re}(z_1 - z_{21}) & \\operatorname{Re}(z_1 - z_{31}) \\\\
        \\operatorname{Im}(z_1 - z_{21}) & \\operatorname{Im}(z_1 - z_{31}) \\end{pmatrix}
        \\binom{a}{b} = \\frac12 \\binom{\\operatorname{Re}(z_1 - z_{21} - z_{31})}
        {\\operatorname{Im}(z_1 - z_{21} - z_{31})}, \\quad z_{ij} = z_i r_{ij}^n.

    Differentiable with respect to ``verts`` and ``z``.

    Parameters
    ----------
    which : (K,) int tensor of face indices, or None for the singular faces of
        :func:`singularities`.
    """
    verts, topo = topology_and_verts(verts, faces)
    n = check_n(n)
    z = as_edge_field(z, topo, verts)
    if z.dim() != 1:
        raise ValueError(f"z must have shape (E,), got {tuple(z.shape)}")
    if which is None:
        which = singularities(verts, topo, z, n).singular_faces
    which = torch.as_tensor(which, dtype=torch.int64, device=verts.device).flatten()
    if which.numel() and (int(which.min()) < 0 or int(which.max()) >= topo.num_faces):
        raise ValueError(f"face indices in `which` must lie in [0, {topo.num_faces})")
    geom = face_geometry(verts, topo)
    signs = topo.face_edge_signs.to(device=verts.device, dtype=verts.dtype)
    r = pair_transport(geom, signs, n).reshape(-1, 3, 3)[which]
    zf = z[topo.face_edges.to(verts.device)[which]]
    z1 = zf[:, 0]
    z21 = zf[:, 1] * r[:, 1, 0]
    z31 = zf[:, 2] * r[:, 2, 0]
    c1, c2 = z1 - z21, z1 - z31
    rhs = 0.5 * (z1 - z21 - z31)
    det = c1.real * c2.imag - c2.real * c1.imag
    safe = torch.where(det != 0, det, torch.ones_like(det))
    a = (rhs.real * c2.imag - c2.real * rhs.imag) / safe
    b = (c1.real * rhs.imag - rhs.real * c1.imag) / safe
    third = torch.full_like(a, 1.0 / 3.0)
    a = torch.where(det != 0, a, third)
    b = torch.where(det != 0, b, third)
    bary = torch.stack([1 - a - b, a, b], dim=1)
    p = verts[topo.faces.to(verts.device)[which]]
    points = p[:, 0] + a[:, None] * (p[:, 1] - p[:, 0]) + b[:, None] * (p[:, 2] - p[:, 0])
    inside = (bary.detach() >= -1e-12).all(dim=1)
    return SingularityLocation(which, bary, points, inside)


# --------------------------------------------------------------------------- splitting


def face_frame_angles(verts, topo) -> torch.Tensor:
    """(F, 3) angle of each edge frame in a face-local planar coordinate system.

    The reference direction is the frame of the edge opposite corner 0 (angle 0), angles
    counter-clockwise around the face normal. The frame of edge ``a`` is
    ``e^{i theta_a}`` in that system, so a value ``z_a`` of an n-field in the frame of edge
    ``a`` reads ``z_a e^{i n theta_a}`` in the face-local one, and
    ``r_ab = e^{i (theta_a - theta_b)}``.
    """
    verts, topo = topology_and_verts(verts, topo)
    fl = topo.faces.to(verts.device)
    p = verts[fl]
    vec = p[:, [2, 0, 1]] - p[:, [1, 2, 0]]  # edge opposite corner k, from k+1 to k+2
    d = vec * topo.face_edge_signs.to(device=verts.device, dtype=verts.dtype)[..., None]
    d = d / torch.linalg.vector_norm(d, dim=-1, keepdim=True)
    nrm = face_normals(verts, topo)
    d0 = d[:, 0]
    y0 = torch.linalg.cross(nrm, d0)
    return torch.atan2((d * y0[:, None]).sum(-1), (d * d0[:, None]).sum(-1))


@dataclass
class SplitResult:
    """A mesh after 1-to-3 splits, with the field carried over.

    Attributes
    ----------
    verts : (V + K, 3) tensor, the new vertices appended in the order of ``split_faces``
    faces : (F + 2K, 3) int64 tensor; split face ``f`` is replaced by ``(v0, v1, s)`` in
        place and ``(v1, v2, s)``, ``(v2, v0, s)`` are appended
    z : (E + 3K,) complex tensor, in the new mesh's edge order
    new_vertices : (K,) int64 indices of the inserted vertices
    split_faces : (K,) int64 original indices of the split faces
    edge_map : (E,) int64, the new index of every old edge (its value is unchanged)
    """

    verts: torch.Tensor
    faces: torch.Tensor
    z: torch.Tensor
    new_vertices: torch.Tensor
    split_faces: torch.Tensor
    edge_map: torch.Tensor


def split_faces(verts, faces, z, which, barycentric, n: int = 1) -> SplitResult:
    """Insert one vertex inside each face of ``which`` (1-to-3 split) and carry the field.

    Old edges keep their values. A new edge from corner ``v_k`` to the new vertex ``s``
    (frame ``v_k -> s``, as ``s`` has the highest index) gets the value of the
    Crouzeix-Raviart interpolated field of the old face at its midpoint, expressed in its
    frame. The field in each sub-face is then exactly the old field (an affine field is
    determined by its values at three midpoints), so detection and location are unchanged.

    Parameters
    ----------
    which : (K,) distinct face indices
    barycentric : (K, 3) positive barycentric coordinates of the new vertices
    """
    verts, topo = topology_and_verts(verts, faces)
    n = check_n(n)
    z = as_edge_field(z, topo, verts)
    dev = verts.device
    which = torch.as_tensor(which, dtype=torch.int64, device=dev).flatten()
    bary = torch.as_tensor(barycentric, dtype=verts.dtype, device=dev).reshape(-1, 3)
    if bary.shape[0] != which.shape[0]:
        raise ValueError(f"barycentric has {bary.shape[0]} rows for {which.shape[0]} faces")
    if torch.unique(which).numel() != which.numel():
        raise ValueError("split_faces: `which` has repeated faces")
    if bool((bary.detach() <= 0).any()):
        bad = which[(bary.detach() <= 0).any(1)].tolist()
        raise ValueError(f"barycentric coordinates must be > 0 (strictly inside) at faces {bad[:10]}")
    k = which.numel()
    nv = topo.num_vertices
    fl = topo.faces.to(dev)
    fw = fl[which]
    p = verts[fw]
    s_pos = (bary[:, :, None] * p).sum(1)
    new_v = torch.arange(nv, nv + k, device=dev)
    new_verts = torch.cat([verts, s_pos])
    new_faces = fl.clone()
    new_faces[which] = torch.stack([fw[:, 0], fw[:, 1], new_v], 1)
    new_faces = torch.cat(
        [new_faces, torch.stack([fw[:, 1], fw[:, 2], new_v], 1), torch.stack([fw[:, 2], fw[:, 0], new_v], 1)]
    )
    new_topo = Topology(new_faces, num_vertices=nv + k)

    # face-local values w_a = z_a e^{i n theta_a}; field at barycentric l: sum (1 - 2 l_a) w_a
    theta = face_frame_angles(verts, topo)[which]
    zf = z[topo.face_edges.to(dev)[which]]
    w = zf * torch.polar(torch.ones_like(theta), n * theta)
    nrm = face_normals(verts, topo)[which]
    p0 = p[:, 2] - p[:, 1]  # edge 0 runs from corner 1 to corner 2; its frame adds the sign
    d0 = p0 * topo.face_edge_signs.to(device=dev, dtype=verts.dtype)[which, 0:1]
    d0 = d0 / torch.linalg.vector_norm(d0, dim=-1, keepdim=True)
    y0 = torch.linalg.cross(nrm, d0)
    eye = torch.eye(3, dtype=verts.dtype, device=dev)
    vals = []
    for c in range(3):
        lam = 0.5 * (eye[c][None, :] + bary)  # midpoint of (v_c, s)
        psi = ((1 - 2 * lam) * w).sum(1)
        d = s_pos - p[:, c]
        th = torch.atan2((d * y0).sum(-1), (d * d0).sum(-1))
        vals.append(psi * torch.polar(torch.ones_like(th), -n * th))

    # edge lookup by key
    keys_new = new_topo.edges[:, 0] * (nv + k) + new_topo.edges[:, 1]
    keys_old = topo.edges[:, 0] * (nv + k) + topo.edges[:, 1]
    edge_map = torch.searchsorted(keys_new, keys_old)
    spoke_keys = torch.cat([fw[:, c].cpu() * (nv + k) + new_v.cpu() for c in range(3)])
    spoke_idx = torch.searchsorted(keys_new, spoke_keys).to(dev)
    z_new = z.new_zeros(new_topo.num_edges)
    z_new = z_new.index_put((edge_map.to(dev),), z)
    z_new = z_new.index_put((spoke_idx,), torch.cat(vals))
    return SplitResult(new_verts, new_faces, z_new, new_v, which, edge_map.to(dev))


def split_singular_faces(verts, faces, z, n: int = 1, min_barycentric: float = 1e-3) -> SplitResult:
    """Make every face singularity a vertex: locate it (B.2) and split its face 1-to-3.

    A location closer than ``min_barycentric`` to the face's boundary is pulled inside
    (barycentric coordinates clamped and renormalised), so no sliver face is created; the
    new vertex then carries the singularity only up to that tolerance (the detection, which
    only needs the field's winding, still finds it there).

    Returns
    -------
    :class:`SplitResult`
    """
    verts, topo = topology_and_verts(verts, faces)
    loc = locate_singularities(verts, topo, z, n)
    bary = loc.barycentric.detach().clamp_min(min_barycentric)
    bary = bary / bary.sum(1, keepdim=True)
    return split_faces(verts, topo, z, loc.faces, bary, n)
