"""Differentiable mesh geometry in pure torch.

Everything here is a function of the vertex positions, so gradients flow back to them;
dtype and device follow ``verts``. The operators of :mod:`torch_edgevf.operators` depend
only on the intrinsic per-face quantities gathered in :class:`FaceGeometry` (edge lengths,
twice the area, and the corner dot products ``d_k = |e_a||e_b| cos(alpha_k)``), which can
be built from positions (:func:`face_geometry`) or from edge lengths alone
(:meth:`FaceGeometry.from_lengths`).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np
import torch

from .._validation import (
    as_faces,
    as_verts,
    check_face_range,
    check_positions_dtype,
    check_vertex_count,
    list_some,
    single_mesh,
)
from .topology import Topology

__all__ = [
    "FaceGeometry",
    "face_geometry",
    "edge_lengths",
    "face_areas",
    "corner_angles",
    "transport_coefficients",
    "dihedral_angles",
    "angle_defects",
    "face_normals",
    "vertex_normals",
    "mean_edge_length",
]

# The 9 ordered corner pairs (a, b) of a face, in row-major order; for a != b, c is the
# third corner and sigma = +1 when b follows a counter-clockwise.
PAIR_A = np.repeat(np.arange(3), 3)
PAIR_B = np.tile(np.arange(3), 3)
PAIR_C = np.where(PAIR_A == PAIR_B, PAIR_A, 3 - PAIR_A - PAIR_B)
PAIR_SIGMA = np.where(PAIR_B == (PAIR_A + 1) % 3, 1.0, np.where(PAIR_A == PAIR_B, 0.0, -1.0))
OFF_DIAGONAL = PAIR_A != PAIR_B


@dataclass
class FaceGeometry:
    """Intrinsic per-face quantities; the operators are written on these alone.

    Attributes
    ----------
    lengths : (F, 3) tensor
        ``lengths[f, k]`` is the length of the edge opposite corner ``k``.
    double_area : (F,) tensor
        ``2 A_f``.
    dots : (F, 3) tensor
        ``dots[f, k] = |e_{k+1}| |e_{k+2}| cos(alpha_k)``, the dot product of the two edge
        vectors leaving corner ``k``.
    """

    lengths: torch.Tensor
    double_area: torch.Tensor
    dots: torch.Tensor

    @property
    def area(self) -> torch.Tensor:
        return 0.5 * self.double_area

    @property
    def angles(self) -> torch.Tensor:
        """(F, 3) interior corner angles ``alpha_k`` in ``(0, pi)``."""
        return torch.atan2(self.double_area[:, None].expand_as(self.dots), self.dots)

    @property
    def cotangents(self) -> torch.Tensor:
        """(F, 3) ``cot(alpha_k) = d_k / (2A)``."""
        return self.dots / self.double_area[:, None]

    @property
    def dtype(self) -> torch.dtype:
        """The real dtype of the quantities (so a geometry can stand in for positions)."""
        return self.lengths.dtype

    @property
    def device(self) -> torch.device:
        return self.lengths.device

    @property
    def num_faces(self) -> int:
        return self.lengths.shape[0]

    @classmethod
    def from_edge_lengths(cls, lengths: torch.Tensor, topo: Topology) -> FaceGeometry:
        """Build from one length per edge of ``topo`` (in the order of ``topo.edges``).

        The intrinsic path for meshes whose positions cannot be trusted, e.g. the mollified
        lengths of :func:`torch_edgevf.mesh.repair.repair`; differentiable in ``lengths``.
        The operators, :class:`~torch_edgevf.fields.design.FieldDesigner` and
        :func:`~torch_edgevf.fields.singularities.singularities` accept the result in place
        of vertex positions.

        Parameters
        ----------
        lengths : (E,) floating tensor
        topo : :class:`Topology`
        """
        if not isinstance(topo, Topology):
            raise ValueError(f"topo must be a Topology, got {type(topo).__name__}")
        if not isinstance(lengths, torch.Tensor) or lengths.dim() != 1 or lengths.shape[0] != topo.num_edges:
            shape = tuple(lengths.shape) if isinstance(lengths, torch.Tensor) else type(lengths).__name__
            raise ValueError(f"lengths must be an (E,) tensor with E = {topo.num_edges}, got {shape}")
        if not lengths.is_floating_point():
            raise ValueError(f"lengths must have a floating dtype, got {lengths.dtype}")
        if not bool(torch.isfinite(lengths.detach()).all()):
            bad = torch.nonzero(~torch.isfinite(lengths.detach())).flatten().tolist()
            raise ValueError(f"lengths has NaN or Inf values at edges [{list_some(bad)}]")
        return cls.from_lengths(lengths[topo.face_edges.to(lengths.device)])

    @classmethod
    def from_lengths(cls, lengths: torch.Tensor) -> FaceGeometry:
        """Build from edge lengths alone (intrinsic meshes).

        The area uses Kahan's cancellation-free form of Heron's formula.

        Parameters
        ----------
        lengths : (F, 3) tensor, ``lengths[f, k]`` opposite corner ``k``.
        """
        if lengths.dim() != 2 or lengths.shape[1] != 3:
            raise ValueError(f"lengths must have shape (F, 3), got {tuple(lengths.shape)}")
        check_positions_dtype(lengths, "lengths")
        # computed on lengths divided by a power of two near the longest edge of each face
        # (exact), then scaled back: the squares and the fourth power of Heron's formula
        # neither overflow nor underflow at any scale (see _checked)
        h = _power_of_two_scale(lengths.detach().amax(dim=1))
        inv_h = 1 / h
        ls = lengths * inv_h[:, None]
        sq = ls * ls
        dots = 0.5 * (sq[:, [1, 2, 0]] + sq[:, [2, 0, 1]] - sq)
        a, b, c = torch.sort(ls, dim=1, descending=True).values.unbind(1)
        prod = (a + (b + c)) * (c - (a - b)) * (c + (a - b)) * (a + (b - c))
        bad = torch.nonzero(prod.detach() <= 0).flatten().tolist()
        if bad:
            raise ValueError(
                f"edge lengths violate the strict triangle inequality (zero-area faces) "
                f"at faces [{list_some(bad)}]"
            )
        return _checked(cls(ls, 0.5 * torch.sqrt(prod), dots), h)


def _power_of_two_scale(magnitude: torch.Tensor) -> torch.Tensor:
    """Per face, the power of two ``2^k >= magnitude`` (1 where it is 0 or not finite).

    Dividing and multiplying by it is exact, so quantities computed on coordinates or
    lengths divided by it and scaled back agree bit for bit with the direct computation
    wherever that neither overflowed nor underflowed.
    """
    m = magnitude.detach()
    ok = torch.isfinite(m) & (m > 0)
    _, k = torch.frexp(torch.where(ok, m, torch.ones_like(m)))
    info = torch.finfo(m.dtype)
    k = k.clamp(math.ceil(math.log2(info.tiny)) + 1, math.floor(math.log2(info.max)))
    return torch.exp2(k.to(m.dtype))


def _checked(scaled: FaceGeometry, h: torch.Tensor) -> FaceGeometry:
    """Scale a geometry computed on lengths divided by ``h`` back; reject what cannot be used.

    Faces whose area is zero relative to their longest edge are degenerate (tested on the
    scaled quantities, so at any scale).  A well-shaped face whose area (a square of its
    scale) is not a finite normal number of the dtype -- it overflows, or underflows to
    zero or loses precision -- cannot be represented: a ``ValueError`` names the scale.
    """
    eps = torch.finfo(scaled.double_area.dtype).eps
    lt = scaled.lengths.detach().t()
    lmax = torch.maximum(torch.maximum(lt[0], lt[1]), lt[2])
    degenerate = scaled.double_area.detach() <= 8 * eps * lmax * lmax
    if degenerate.any():
        bad = torch.nonzero(degenerate).flatten().tolist()
        raise ValueError(f"zero-area (degenerate) faces at faces [{list_some(bad)}]")
    h2 = h * h
    geom = FaceGeometry(scaled.lengths * h[:, None], scaled.double_area * h2, scaled.dots * h2[:, None])
    _check_representable(geom, lmax * h)
    return geom


def _check_representable(geom: FaceGeometry, lmax: torch.Tensor) -> None:
    info = torch.finfo(geom.double_area.dtype)
    a2 = geom.double_area.detach()
    sq = lmax * lmax
    ok = (
        torch.isfinite(a2)
        & (a2 >= info.tiny)
        & torch.isfinite(sq)
        & torch.isfinite(geom.dots.detach()).all(1)
    )
    if bool(ok.all()):
        return
    bad = torch.nonzero(~ok).flatten()
    big = bool((~torch.isfinite(sq[bad]) | ~torch.isfinite(a2[bad])).any())
    scale = float(lmax[bad].max() if big else lmax[bad].min())
    kind = "overflow" if big else "underflow"
    raise ValueError(
        f"edge lengths of about {scale:.3g} are out of the range of {geom.double_area.dtype}: "
        f"face areas (squares of the lengths, {info.tiny:.3g} to {info.max:.3g}) {kind} at faces "
        f"[{list_some(bad.tolist())}]; rescale the vertices (the connection Laplacian does not "
        f"depend on the scale s, the mass matrix is proportional to s^2)"
    )


#: The last geometry computed without autograd for each topology, with the positions it
#: was computed from: a memo of :func:`face_geometry` for repeated calls on the same
#: positions (e.g. several operators of one mesh). Held beside the topology, not on it,
#: and dropped with it.
_LAST_GEOMETRY: weakref.WeakKeyDictionary[Topology, tuple[torch.Tensor, FaceGeometry]] = (
    weakref.WeakKeyDictionary()
)


def face_geometry(verts, faces) -> FaceGeometry:
    """Per-face lengths, doubled areas and corner dot products from vertex positions.

    Computed coordinate by coordinate on ``(F,)`` vectors (structure of arrays); the
    ``(F, 3)`` attributes are transposed views of contiguous ``(3, F)`` tensors, so
    ``geom.lengths.t()`` etc. are contiguous.

    Parameters
    ----------
    verts : (V, 3) floating tensor
    faces : (F, 3) integer tensor, or a :class:`Topology`

    Raises
    ------
    ValueError
        On NaN/Inf coordinates or zero-area faces, naming them, and where the areas (squares
        of the edge lengths) are out of the range of the dtype, naming the scale.  Every
        quantity is computed on the edge vectors of a face divided by a power of two of its
        size (exact) and scaled back, so a well-shaped mesh gives finite operators at any
        scale whose areas the dtype holds (float64: about 1e-150 to 1e150, float32: 1e-18 to
        1e18).
    """
    topo = faces if isinstance(faces, Topology) else None
    faces = None if topo is not None else as_faces(faces)
    return _face_geometry(as_verts(verts), topo, faces)


def face_geometry_of(verts: torch.Tensor, topo: Topology) -> FaceGeometry:
    """:func:`face_geometry` of positions already checked at a public entry point (by
    :func:`topology_and_verts` or ``as_verts``) and their :class:`Topology`: not checked again."""
    return _face_geometry(verts, topo, None)


def _face_geometry(verts: torch.Tensor, topo: Topology | None, faces: torch.Tensor | None) -> FaceGeometry:
    # Without autograd, the last geometry of a topology is reused for equal positions
    # (compared by value, so in-place edits of any kind are seen).
    memo = topo if topo is not None and not (torch.is_grad_enabled() and verts.requires_grad) else None
    if memo is not None:
        cached = _LAST_GEOMETRY.get(memo)
        if cached is not None and _same_values(cached[0], verts):
            return cached[1]
    if topo is not None and verts.shape[0] >= topo.num_vertices:
        ends = topo.edge_ends().to(verts.device)  # indices checked when the topology was built
    else:
        rows = topo.faces if topo is not None else faces
        assert rows is not None  # a topology or the faces
        rows = rows.to(verts.device)
        check_face_range(rows, verts.shape[0])
        ft = rows.t()
        ends = torch.stack([ft.roll(1, 0), ft.roll(-1, 0)])
    coords = verts.t().contiguous()
    geom = None
    if (
        coords.device.type == "cpu"
        and ends.shape[-1] > 2 * FACE_BLOCK
        and not (torch.is_grad_enabled() and coords.requires_grad)
    ):
        try:
            geom = _geometry_by_blocks(coords, ends)
        except ValueError:
            pass  # computed again as a whole below, whose message names the faces
    if geom is None:
        geom = _geometry_of(coords, ends)
    if memo is not None:
        _LAST_GEOMETRY[memo] = (verts.detach().clone(), geom)
    return geom


#: Faces per block of the computations without autograd on the CPU: the temporaries of a
#: block stay in the cache (about half the time of whole-array operations at 10^5 faces).
FACE_BLOCK = 8192


def face_blocks(num_faces: int) -> list[slice]:
    """The slices of :data:`FACE_BLOCK` faces that cover ``num_faces`` faces."""
    return [slice(s, min(s + FACE_BLOCK, num_faces)) for s in range(0, num_faces, FACE_BLOCK)]


def _geometry_of(coords: torch.Tensor, ends: torch.Tensor) -> FaceGeometry:
    """The geometry of the faces whose edges run from ``ends[1]`` to ``ends[0]`` (``coords`` ``(3, V)``)."""
    # Structure of arrays: e[x, k] is the (F,) coordinate x of the edge opposite corner k,
    # running from corner k+1 to corner k+2; one gather of both ends of every edge.
    nf, flat = ends.shape[-1], ends.reshape(-1)
    p = torch.stack([coords[x].index_select(0, flat) for x in range(3)]).view(3, 2, 3, nf)
    e = p[:, 0] - p[:, 1]
    del p
    geom = _direct_geometry(e)
    if geom is None:
        # Some face is too large or too small for the squares and fourth powers below:
        # computed on the edge vectors divided by a power of two near the largest
        # coordinate difference of each face (exact) and scaled back by _checked.
        h = _power_of_two_scale(e.detach().abs().amax(dim=(0, 1)))
        l2, double_area, dots = _face_products(e * (1 / h))
        geom = _checked(FaceGeometry(torch.sqrt(l2).t(), double_area, dots.t()), h)
    return geom


def _geometry_by_blocks(coords: torch.Tensor, ends: torch.Tensor) -> FaceGeometry:
    """:func:`_geometry_of`, block by block of faces into whole-mesh tensors (no autograd)."""
    nf = ends.shape[-1]
    lengths = coords.new_empty(3, nf)
    double_area = coords.new_empty(nf)
    dots = coords.new_empty(3, nf)
    for block in face_blocks(nf):
        g = _geometry_of(coords, ends[..., block])
        lengths[:, block] = g.lengths.t()
        double_area[block] = g.double_area
        dots[:, block] = g.dots.t()
    return FaceGeometry(lengths.t(), double_area, dots.t())


def _face_products(e: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Squared lengths ``(3, F)``, doubled areas ``(F,)`` and corner dots ``(3, F)`` of edge vectors.

    ``e`` is ``(3, 3, F)``: coordinate ``x`` of the edge opposite corner ``k`` of every face.
    """
    sq = e * e
    l2 = sq[0] + sq[1] + sq[2]
    del sq
    cx = e[1, 0] * e[2, 1] - e[2, 0] * e[1, 1]
    cy = e[2, 0] * e[0, 1] - e[0, 0] * e[2, 1]
    cz = e[0, 0] * e[1, 1] - e[1, 0] * e[0, 1]
    double_area = torch.sqrt(cx * cx + cy * cy + cz * cz)
    # q[x, k] = e[x, k] e[x, k + 1]; the vectors leaving corner k are -e_{k+2} and e_{k+1}
    q = e * e.roll(-1, dims=1)
    dots = -(q[0] + q[1] + q[2]).roll(-1, dims=0)
    return l2, double_area, dots


def _direct_range(dtype: torch.dtype) -> tuple[float, float]:
    """Squared edge lengths for which the direct products can neither overflow nor underflow.

    Areas are bounded below by the degeneracy test (``2A > 8 eps l_max^2``); their squares
    must stay normal numbers, and the sums of squared cross products finite.
    """
    info = torch.finfo(dtype)
    return 8 * math.sqrt(info.tiny) / (8 * info.eps), math.sqrt(info.max) / 8


def _direct_geometry(e: torch.Tensor) -> FaceGeometry | None:
    """The geometry computed on the edge vectors as they are, or ``None`` where their scale
    does not allow it (then computed face by face on scaled vectors, to the same bits
    wherever the direct computation neither overflows nor underflows)."""
    l2, double_area, dots = _face_products(e)
    lo, hi = _direct_range(l2.dtype)
    smallest, largest = (float(x) for x in l2.detach().aminmax())
    if not (lo <= smallest and largest <= hi):
        return None
    eps = torch.finfo(l2.dtype).eps
    lmax2 = l2.detach().amax(dim=0)
    degenerate = double_area.detach() <= 8 * eps * lmax2
    if degenerate.any():
        bad = torch.nonzero(degenerate).flatten().tolist()
        raise ValueError(f"zero-area (degenerate) faces at faces [{list_some(bad)}]")
    return FaceGeometry(torch.sqrt(l2).t(), double_area, dots.t())


def _same_values(a: torch.Tensor, b: torch.Tensor) -> bool:
    return a.dtype == b.dtype and a.device == b.device and a.shape == b.shape and torch.equal(a, b.detach())


def topology_and_verts(verts, topo, caller: str = "this function") -> tuple[torch.Tensor, Topology]:
    """Checked positions ``(V, 3)`` and the :class:`Topology` of ``topo`` (faces or a
    topology) for their vertex count; ``caller`` names the function in the error of a batch."""
    verts, topo = single_mesh(verts, topo, caller)
    if not isinstance(topo, Topology):
        topo = Topology(topo, num_vertices=None if not hasattr(verts, "shape") else verts.shape[0])
    verts = as_verts(verts)
    check_vertex_count(verts, topo.num_vertices)
    return verts, topo


def edge_lengths(verts, topo) -> torch.Tensor:
    """(E,) edge lengths ``|v_j - v_i|`` in the order of ``topo.edges``."""
    return edge_lengths_of(*topology_and_verts(verts, topo))


def edge_lengths_of(verts: torch.Tensor, topo: Topology) -> torch.Tensor:
    """:func:`edge_lengths` of positions already checked and their :class:`Topology`."""
    e = topo.edges.to(verts.device)
    return torch.linalg.vector_norm(verts[e[:, 1]] - verts[e[:, 0]], dim=-1)


def mean_edge_length(verts, topo) -> torch.Tensor:
    """Scalar mean edge length ``h``."""
    return edge_lengths(verts, topo).mean()


def face_areas(verts, faces) -> torch.Tensor:
    """(F,) triangle areas."""
    return face_geometry(verts, faces).area


def corner_angles(verts, faces) -> torch.Tensor:
    """(F, 3) interior angles, ``[f, k]`` at corner ``k``."""
    return face_geometry(verts, faces).angles


def face_normals(verts, faces) -> torch.Tensor:
    """(F, 3) unit normals, oriented by the counter-clockwise order of the faces."""
    faces = faces.faces if isinstance(faces, Topology) else as_faces(faces)
    verts = as_verts(verts)
    face_geometry(verts, faces)  # validates (zero-area faces have no normal)
    p = verts[faces.to(verts.device)]
    a, b = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    # divided by a power of two of each face's size first: the cross product is a square
    inv_h = 1 / _power_of_two_scale(torch.maximum(a.detach().abs().amax(1), b.detach().abs().amax(1)))
    n = torch.linalg.cross(a * inv_h[:, None], b * inv_h[:, None])
    return n / torch.linalg.vector_norm(n, dim=-1, keepdim=True)


def vertex_normals(verts, topo) -> torch.Tensor:
    """(V, 3) angle-weighted unit vertex normals (zero rows at unreferenced vertices)."""
    verts, topo = topology_and_verts(verts, topo)
    geom = face_geometry(verts, topo)
    nf = face_normals(verts, topo)
    faces = topo.faces.to(verts.device)
    acc = verts.new_zeros(verts.shape).index_add(
        0, faces.flatten(), (geom.angles[:, :, None] * nf[:, None, :]).reshape(-1, 3)
    )
    norm = torch.linalg.vector_norm(acc, dim=-1, keepdim=True)
    return acc / torch.where(norm > 0, norm, torch.ones_like(norm))


def transport_coefficients(verts, topo, n: int = 1, geom: FaceGeometry | None = None) -> torch.Tensor:
    """Transport coefficients between the edge frames of each face (thesis 2.3).

    .. math::  r_{ab} = -\\delta_a \\delta_b e^{\\imath \\sigma_{ab} \\alpha_c}, \\quad r_{aa} = 1,

    where ``c`` is the third corner and ``sigma_ab = +1`` when ``b`` follows ``a``
    counter-clockwise (``-1`` otherwise), so that ``r_ba = conj(r_ab)``. ``r_ab`` converts a
    coefficient in the frame of the edge opposite corner ``a`` into the frame of the edge
    opposite corner ``b``.

    Returns
    -------
    (F, 3, 3) complex tensor ``r[f, a, b] ** n``.
    """
    verts, topo = topology_and_verts(verts, topo)
    geom = face_geometry(verts, topo) if geom is None else geom
    return pair_transport(geom, topo.face_edge_signs.to(verts.device), n).reshape(-1, 3, 3)


_PAIR_INDEX = {name: torch.as_tensor(arr) for name, arr in (("a", PAIR_A), ("b", PAIR_B), ("c", PAIR_C))}


def pair_columns(x: torch.Tensor, which: str) -> torch.Tensor:
    """``x[:, PAIR_<which>]`` for an ``(F, 3)`` tensor, as a fast ``index_select``."""
    return x.index_select(1, _PAIR_INDEX[which].to(x.device))


def int_power(u: torch.Tensor, n: int) -> torch.Tensor:
    """``u ** n`` for an integer ``n >= 0`` by repeated squaring (differentiable)."""
    result, base = None, u
    while n:
        if n & 1:
            result = base if result is None else result * base
        n >>= 1
        if n:
            base = base * base
    return torch.ones_like(u) if result is None else result


def pair_transport(geom: FaceGeometry, signs: torch.Tensor, n: int = 1) -> torch.Tensor:
    """(F, 9) ``r_ab ** n`` for the 9 ordered corner pairs (row-major ``3a + b``).

    Computed without trigonometry: ``e^{i sigma alpha_c} = (d_c + i sigma 2A) / (l_a l_b)``.
    """
    dev, dtype = geom.lengths.device, geom.lengths.dtype
    off = torch.as_tensor(OFF_DIAGONAL, device=dev)
    sigma = torch.as_tensor(PAIR_SIGMA, dtype=dtype, device=dev)
    denom = torch.where(off, pair_columns(geom.lengths, "a") * pair_columns(geom.lengths, "b"), 1.0)
    re = torch.where(off, pair_columns(geom.dots, "c") / denom, 1.0)
    im = sigma * geom.double_area[:, None] / denom
    s = signs.to(dtype)
    sign = torch.where(off, -pair_columns(s, "a") * pair_columns(s, "b"), 1.0) ** n
    return int_power(torch.complex(re, im), n) * sign


def dihedral_angles(verts, topo) -> torch.Tensor:
    """(E,) signed dihedral angles, positive on convex edges, 0 on boundary edges.

    For ``e = (i, j)`` with left face ``f_L`` (where the edge runs ``i -> j``), right face
    ``f_R`` and unit edge vector ``t``,

    .. math::  \\beta_e = \\operatorname{atan2}(t \\cdot (n_L \\times n_R), n_L \\cdot n_R).
    """
    verts, topo = topology_and_verts(verts, topo)
    nf = face_normals(verts, topo)
    ef = topo.edge_faces.to(verts.device)
    interior = (ef >= 0).all(dim=1)
    e = topo.edges.to(verts.device)[interior]
    t = verts[e[:, 1]] - verts[e[:, 0]]
    t = t / torch.linalg.vector_norm(t, dim=-1, keepdim=True)
    nl, nr = nf[ef[interior, 0]], nf[ef[interior, 1]]
    beta = torch.atan2((t * torch.linalg.cross(nl, nr)).sum(-1), (nl * nr).sum(-1))
    out = verts.new_zeros(topo.num_edges)
    return out.index_put((torch.nonzero(interior).flatten(),), beta)


def angle_defects(verts, topo) -> torch.Tensor:
    """(V,) angle defects: ``2 pi - sum(alpha)`` inside, ``pi - sum(alpha)`` on the boundary.

    Unreferenced vertices get 0. On a closed mesh the sum is ``2 pi chi`` (Gauss-Bonnet).
    """
    verts, topo = topology_and_verts(verts, topo)
    return angle_defects_of(face_geometry_of(verts, topo), topo)


def angle_defects_of(geom: FaceGeometry, topo: Topology) -> torch.Tensor:
    """:func:`angle_defects` from the face geometry of a mesh (intrinsic: its angles only)."""
    faces = topo.faces.to(geom.device)
    total = geom.lengths.new_zeros(topo.num_vertices).index_add(0, faces.flatten(), geom.angles.flatten())
    full = torch.where(
        topo.boundary_vertices.to(geom.device),
        torch.full_like(total, math.pi),
        torch.full_like(total, 2 * math.pi),
    )
    defect = full - total
    if topo.unreferenced_vertices.numel():
        defect = defect.index_fill(0, topo.unreferenced_vertices.to(geom.device), 0.0)
    return defect
