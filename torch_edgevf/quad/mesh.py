"""Quad meshes from cross fields: field, integer-grid map, extraction (thesis chapter 4).

:func:`quad_mesh` runs the whole pipeline of the thesis' quadrangulation chapter:

1. a cross field (``n = 4``): curvature-aligned (default) or smoothest, constrained along
   the sharp edges (dihedral angle above ``sharp_angle``) and, on open meshes, along the
   boundary (:mod:`torch_edgevf.fields.design`). The default follows the curvature where
   it is anisotropic and the smoothest field where it is near-umbilic or flat
   (:mod:`torch_edgevf.quad.field`): a sphere gets the smoothest field's 8 cones, not the
   noise of its curvature directions;
2. its integer-grid map (:mod:`torch_edgevf.quad.igm`): cones at integer points, integer
   seam translations, no flipped triangle; on open meshes every boundary edge on an integer
   iso-line, a few short ones of a jagged boundary turned across the field where that
   spares a stair of corners closer than a quad (:mod:`torch_edgevf.quad.corners`);
3. the quads of the map's integer iso-lines (:mod:`torch_edgevf.quad.extract`).

The quad mesh is pure (quads only), manifold, closed where the input is, has the input's
Euler characteristic, its vertices lie on the input surface, and its irregular vertices are
the cones: a cone of index ``I`` has valence ``4 - 4 I`` (3 for ``+1/4``, 5 for ``-1/4``).
:func:`quad_mesh_report` measures these properties and the quality of a quad mesh.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import torch

from .._dtypes import complex_dtype
from .._validation import as_edge_field, as_faces, as_verts, check_vertex_count, single_mesh
from ..mesh.geometry import dihedral_angles
from ..mesh.topology import Topology
from .extract import extract_quads
from .field import curvature_guide
from .igm import IntegerGridMap, _grid_map64, _relabelled_map64, with_dtype

__all__ = ["QuadMesh", "quad_mesh", "quad_mesh_report", "QuadMeshReport", "sharp_edges", "save_quad_mesh"]

_FIELDS = ("curvature", "smoothest")
_BOUNDARY = ("hard", "soft")
_RETRY_SCALES = (1.0, 1.1, 0.9, 1.2)
#: Scales (of the map: the inverse of the edge length) tried after the retries when the size
#: is the default one (no ``quads`` or ``edge_length``): quads of 0.7 and 0.5 times the mean
#: edge length.  Finer grids leave more room between dense cones (``plane_holes.obj``: 27
#: boundary loops and about 210 cones; its map stays folded at the default size and at 0.7,
#: and unfolds at 0.5).
_FINER_SCALES = (1 / 0.7, 2.0)


@dataclass
class QuadMesh:
    """Result of :func:`quad_mesh`.

    Attributes
    ----------
    verts : (Q_V, 3) tensor, on the input surface, in the dtype of the input vertices
    quads : (Q_F, 4) int64 tensor, counter-clockwise like the input
    cone_vertices : (C,) int64, the quad vertex at each cone of the map
    cone_index : (C,) the cones' indices (valence ``4 - 4 I``), in the dtype of ``verts``
    corner_vertices : (K,) int64, the quad vertex at each corner of the boundary (open meshes)
    corner_turns : (K,) int64, the number of quads there (1 convex, 3 or 4 concave)
    field : (E,) complex tensor, the cross field used (on the input mesh), complex64 for
        float32 vertices and complex128 for float64
    grid_map : the :class:`~torch_edgevf.quad.igm.IntegerGridMap` the quads come from
    """

    verts: torch.Tensor
    quads: torch.Tensor
    cone_vertices: torch.Tensor
    cone_index: torch.Tensor
    corner_vertices: torch.Tensor
    corner_turns: torch.Tensor
    field: torch.Tensor
    grid_map: IntegerGridMap


def sharp_edges(verts, faces, angle: float) -> torch.Tensor:
    """(K,) int64 indices of the interior edges whose dihedral angle exceeds ``angle`` (degrees)."""
    beta = dihedral_angles(verts, faces).detach()
    return torch.nonzero(beta.abs() > math.radians(angle)).flatten()


def _check_mesh(verts, faces) -> tuple[torch.Tensor, Topology]:
    verts = as_verts(verts)
    faces = as_faces(faces)
    topo = Topology(faces, num_vertices=verts.shape[0])  # raises on non-manifold input
    check_vertex_count(verts, topo.num_vertices)
    if topo.unreferenced_vertices.numel():
        raise ValueError(
            f"the mesh has {topo.unreferenced_vertices.numel()} unreferenced vertices (e.g. "
            f"{topo.unreferenced_vertices[:10].tolist()}): remove them first "
            "(torch_edgevf.mesh.topology.remove_unreferenced_vertices)"
        )
    from ..mesh.repair import find_degenerate_faces

    bad = find_degenerate_faces(verts.detach().cpu().double().numpy(), topo.faces.numpy())
    if bad.size:
        raise ValueError(
            f"the mesh has {bad.size} zero-area faces (e.g. {bad[:10].tolist()}): repair it first "
            "(torch_edgevf.mesh.repair.repair_degenerate_faces or 'edgevf repair')"
        )
    return verts, topo


def _scale(verts, topo, quads, edge_length) -> float:
    if quads is not None and edge_length is not None:
        raise ValueError("give quads or edge_length, not both")
    if quads is not None:
        if isinstance(quads, bool) or not isinstance(quads, (int, np.integer)) or quads < 1:
            raise ValueError(f"quads must be a positive integer, got {quads!r}")
        p = verts.detach().double()[topo.faces]
        area = 0.5 * torch.linalg.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]).norm(dim=1).sum()
        return math.sqrt(int(quads) / float(area))
    if edge_length is not None:
        if isinstance(edge_length, bool) or not isinstance(
            edge_length, (int, float, np.floating, np.integer)
        ):
            raise ValueError(f"edge_length must be a positive number, got {edge_length!r}")
        if not (math.isfinite(edge_length) and edge_length > 0):
            raise ValueError(f"edge_length must be a positive finite number, got {edge_length!r}")
        return 1.0 / float(edge_length)
    e = verts.detach().double()[topo.edges]
    return 1.0 / float((e[:, 1] - e[:, 0]).norm(dim=1).mean())


def _design(verts, topo, field, sharp, boundary, lam, free=None):
    """The cross field; ``free``: boundary edges left out of a hard boundary's constraint."""
    from ..fields.design import FieldDesigner

    designer = FieldDesigner(verts.detach().double(), topo, n=4)
    bnd = torch.nonzero(topo.boundary_edges).flatten()
    hard = sharp
    if boundary == "hard":
        kept = bnd if free is None else bnd[~torch.isin(bnd, free)]
        hard = torch.cat([hard, kept])
    guide = None
    if field == "curvature":  # curvature where anisotropic, smoothest elsewhere (.field)
        smooth = None
        if hard.numel():  # the smooth field that follows the constrained edges
            ones = torch.ones(hard.numel(), dtype=torch.complex128)
            smooth = designer.constrained(edges=hard, values=ones)
        guide = curvature_guide(designer, smooth)  # None: no anisotropy anywhere
    if boundary == "soft" and bnd.numel():
        w = torch.zeros(topo.num_edges, dtype=torch.complex128)
        scale = float(guide.abs().max()) if guide is not None else 1.0
        w[bnd] = 10.0 * scale / designer.mean_edge_length.item()
        guide = w if guide is None else guide + w
    if hard.numel() == 0:
        if guide is None:
            return designer.smoothest()
        z = designer.aligned(guide, lam)
        return z / designer.norm(z)
    # a cross direction along each constrained edge: the value (not only the direction, which
    # would allow the opposite sign, a cross at 45 degrees) is fixed to the typical magnitude
    # of the unconstrained design
    free = designer.smoothest() if guide is None else designer.aligned(guide, lam)
    rms = torch.sqrt((designer.mass * free.abs() ** 2).sum() / designer.mass.sum())
    values = torch.full((hard.numel(),), complex(float(rms)), dtype=torch.complex128)
    z = designer.constrained(edges=hard, values=values, guide=guide, lam=lam)
    return z / designer.norm(z)


def quad_mesh(
    verts,
    faces=None,
    quads: int | None = None,
    edge_length: float | None = None,
    field="curvature",
    sharp_angle: float | None = 60.0,
    boundary: str | None = None,
    lam: float = 0.0,
    fix_flips: bool = True,
    retries: int = 3,
) -> QuadMesh:
    """A pure quad mesh of the surface from a cross field (module docstring).

    Parameters
    ----------
    verts : (V, 3) tensor
    faces : (F, 3) int tensor: a manifold, consistently oriented mesh without zero-area faces
    quads : target number of quads (about ``quads`` vertices on a closed surface), or
    edge_length : target quad edge length; default: the mean edge length of the input
    field : ``"curvature"`` (the curvature-aligned cross field, thesis 3.4, softly aligned
        to the curvature directions weighted by the curvature's anisotropy
        ``|k1 - k2| / (|k1| + |k2|)``: 0 below 0.1, 1 above 0.3; where the weight is below 1
        the guide blends towards the smoothest field, and where it is 0 everywhere, as on
        a sphere, the field is the smoothest one; :mod:`torch_edgevf.quad.field`),
        ``"smoothest"`` (3.1), or an (E,) complex tensor: the representation vector of a
        cross field (``n = 4``) of this mesh, used as given
    sharp_angle : edges with a dihedral angle above this (degrees) constrain the field to
        follow them (``None``: no constraint); ignored for a given field
    boundary : required on open meshes: ``"hard"`` (the field follows the boundary edges) or
        ``"soft"`` (strongly guided along them)
    lam : ``lambda_t`` of the soft alignment to the curvature (thesis 3.4)
    fix_flips : repair flipped triangles of the map (foldover-free iterations)
    retries : on an open mesh whose map is folded, or whose field's turns along the boundary
        do not add up, the map is made again with the short boundary edges of stairs and of
        corners closer than a quad turned across the field
        (:mod:`torch_edgevf.quad.corners`), and the less folded one kept, at every scale;
        when the map stays folded, try again at up to this many other scales (x1.1,
        x0.9, x1.2: other integers); with the default size (no ``quads`` or
        ``edge_length``), then also with quads of 0.7 and 0.5 times the mean edge length (a
        warning says so when one is used); the scale used is ``grid_map.scale``. With
        ``boundary="hard"`` and a field made here (not a given tensor), when the map is
        folded at every size, the field is made again without the constraint on the
        boundary edges of the triangles that hold its singularities (cones next to the
        boundary, where the map has no room for them), and every size tried again

    Returns
    -------
    :class:`QuadMesh`

    Raises
    ------
    ValueError
        For a mesh that is not manifold or has zero-area faces, a field that is not a
        cross field of this mesh, an open mesh without ``boundary``, or when no valid quad
        mesh of the map exists (flips left), with the reason.

    Examples
    --------
    >>> q = quad_mesh(verts, faces, quads=1000)       # doctest: +SKIP
    >>> q.quads.shape                                  # doctest: +SKIP
    """
    verts, faces = single_mesh(verts, faces, "quad_mesh")
    verts, topo = _check_mesh(verts, faces)
    if boundary is not None and boundary not in _BOUNDARY:
        raise ValueError(f"boundary must be one of {_BOUNDARY} or None, got {boundary!r}")
    if not topo.is_closed:
        if boundary is None:
            raise ValueError(
                f"the mesh is open ({topo.num_boundary_edges} boundary edges): pass boundary='hard' or "
                "'soft' to align the quads with its boundary"
            )
    if sharp_angle is not None and not (isinstance(sharp_angle, (int, float)) and 0 < sharp_angle < 180):
        raise ValueError(f"sharp_angle must be in (0, 180) degrees or None, got {sharp_angle!r}")
    s = _scale(verts, topo, quads, edge_length)
    if isinstance(field, str):
        if field not in _FIELDS:
            raise ValueError(f"field must be one of {_FIELDS} or a cross field tensor, got {field!r}")
        sharp = (
            sharp_edges(verts, topo, sharp_angle)
            if sharp_angle is not None
            else torch.zeros(0, dtype=torch.int64)
        )
        z = _design(verts, topo, field, sharp, boundary, lam)
    else:
        z = _check_field(field, topo, verts)
    # a rounding that leaves the map folded somewhere is retried at slightly other scales
    # (other integers); the scale used is the map's ``scale``
    scales = _RETRY_SCALES[: max(1, retries + 1)]
    if quads is None and edge_length is None and retries > 0:
        scales += _FINER_SCALES
    v64 = verts.detach().double()
    grid, factor, tries = _try_scales(v64, topo, z, s, scales, fix_flips)
    free = None
    if grid.flipped and retries > 0 and boundary == "hard" and isinstance(field, str) and not topo.is_closed:
        free = _singular_boundary_edges(v64, topo, z)
    if free is not None and free.numel():
        # the field made again without the constraint on the boundary edges of the triangles
        # that hold its singularities: held along those edges, it turns inside the triangles
        # at the boundary, where the map has no room for its cones
        z = _design(verts, topo, field, sharp, boundary, lam, free=free)
        grid, factor, more = _try_scales(v64, topo, z, s, scales, fix_flips)
        tries += [f"{t} (the boundary edges of singular triangles free)" for t in more]
    if not grid.flipped and factor in _FINER_SCALES:
        warnings.warn(
            f"quad_mesh: the integer-grid map stayed folded at the default size ({', '.join(tries[:-1])}); "
            f"the quads are {1 / factor:.2g} times as long as the input's mean edge",
            stacklevel=2,
        )
    if grid.flipped:
        raise ValueError(
            f"the integer-grid map keeps folded triangles after repair ({', '.join(tries)}): no quad "
            "mesh (try a smaller edge length or more quads, or a smoother field)"
        )
    ex = extract_quads(grid.verts, grid.faces, grid.uv, grid.matching)
    where = {int(v): i for i, v in enumerate(ex.vertex_mesh_vertex) if v >= 0}
    cone_q = np.array([where.get(c, -1) for c in grid.cones.tolist()], dtype=np.int64)
    turns = grid.boundary_turns.numpy()
    corners = np.flatnonzero(topo_boundary_corners(grid, turns))
    corner_q = np.array([where.get(int(c), -1) for c in corners], dtype=np.int64)
    return QuadMesh(
        verts=torch.from_numpy(ex.verts).to(device=verts.device, dtype=verts.dtype),
        quads=torch.from_numpy(ex.quads).to(verts.device),
        cone_vertices=torch.from_numpy(cone_q),
        cone_index=grid.cone_index.to(verts.dtype),
        corner_vertices=torch.from_numpy(corner_q),
        corner_turns=torch.from_numpy(turns[corners]),
        field=z.to(complex_dtype(verts.dtype)),
        grid_map=with_dtype(grid, verts.dtype),
    )


def _try_scales(v64, topo, z, s, scales, fix_flips):
    """The map at the first of ``s * scales`` where it is not folded (else at the last), its
    factor, and the folds at each scale tried."""
    tries = []
    z128 = z.to(torch.complex128)
    for factor in scales:
        grid = _map_at(v64, topo, z128, s * factor, fix_flips)
        tries.append(f"{grid.flipped} at scale x{factor:.3g}")
        if not grid.flipped:
            break
    return grid, factor, tries


def _singular_boundary_edges(verts, topo: Topology, z) -> torch.Tensor:
    """The boundary edges of the triangles that hold a singularity of the cross field ``z``."""
    from ..fields.singularities import singularities

    faces = singularities(verts, topo, z, n=4).singular_faces
    edges = topo.face_edges[faces].flatten()
    return torch.unique(edges[topo.boundary_edges[edges]])


def _map_at(verts, topo: Topology, z, scale: float, fix_flips: bool) -> IntegerGridMap:
    """The integer-grid map at ``scale``; on an open mesh where it is folded, or where the
    field's turns along the boundary do not add up, the one with the short boundary edges of
    stairs and of close corners turned across the field instead
    (:mod:`torch_edgevf.quad.corners`), if that is less folded."""
    closed = topo.is_closed
    try:
        grid = _grid_map64(verts, topo, z, scale, True, fix_flips, 8, 1.0)
    except ValueError:  # the turns along the boundary do not add up (a soft field)
        if closed:
            raise
        other = _relabelled_map64(verts, topo, z, scale, fix_flips)
        if other is None:
            raise
        return other
    if grid.flipped and not closed:
        other = _relabelled_map64(verts, topo, z, scale, fix_flips)
        if other is not None and other.flipped < grid.flipped:
            return other
    return grid


def topo_boundary_corners(grid: IntegerGridMap, turns: np.ndarray) -> np.ndarray:
    """(V,) bool: the boundary vertices of the map's mesh with other than 2 quarter turns."""
    bnd = np.zeros(turns.shape[0], dtype=bool)
    e = Topology(grid.faces, grid.verts.shape[0])
    bnd[e.boundary_vertices.numpy()] = True
    return bnd & (turns != 2)


def _check_field(field, topo: Topology, verts) -> torch.Tensor:
    if not isinstance(field, torch.Tensor):
        raise ValueError(
            f"field must be one of {_FIELDS} or a (E,) complex tensor, got {type(field).__name__}"
        )
    if field.dim() != 1:
        raise ValueError(
            f"field must be one cross field of shape (E,) = ({topo.num_edges},), got {tuple(field.shape)}"
        )
    if not field.is_complex():
        raise ValueError(
            "field must be complex: the representation vector (4th power) of a cross field, "
            f"got {field.dtype}"
        )
    z = as_edge_field(field.detach(), topo, verts.detach(), "field")
    if not bool((z != 0).any()):
        raise ValueError("field is zero everywhere: it has no directions")
    return z


# --------------------------------------------------------------------------- measures


@dataclass
class QuadMeshReport:
    """Properties of a quad mesh (:func:`quad_mesh_report`).

    Attributes
    ----------
    num_vertices, num_quads, num_edges : counts
    euler_characteristic : ``V - E + F``
    manifold : every edge has one or two quads, oriented consistently, and every vertex's
        quads form one fan
    closed : every edge has two quads
    valence : (Q_V,) int64 number of quads at each vertex
    irregular : (K,) int64 vertices of valence != 4 inside, != 2 on the boundary
    angle_deviation : mean ``|corner angle - 90 deg|`` in degrees
    """

    num_vertices: int
    num_quads: int
    num_edges: int
    euler_characteristic: int
    manifold: bool
    closed: bool
    valence: np.ndarray
    irregular: np.ndarray
    angle_deviation: float


def quad_mesh_report(verts, quads) -> QuadMeshReport:
    """Counts, manifoldness, valences and corner angles of a quad mesh (or any polygon mesh
    given as an (F, 4) array: quads only)."""
    v = np.asarray(torch.as_tensor(verts).detach().cpu(), dtype=np.float64)
    q = np.asarray(torch.as_tensor(quads).detach().cpu(), dtype=np.int64)
    if q.ndim != 2 or q.shape[1] != 4:
        raise ValueError(f"quads must have shape (Q, 4), got {q.shape}")
    directed = np.stack([q, np.roll(q, -1, 1)], -1).reshape(-1, 2)
    und = np.sort(directed, 1)
    uniq, inv, count = np.unique(und, axis=0, return_inverse=True, return_counts=True)
    _, dcount = np.unique(directed, axis=0, return_counts=True)
    manifold = bool(count.max(initial=0) <= 2 and dcount.max(initial=0) <= 1)
    closed = bool(np.all(count == 2))
    nv = int(q.max(initial=-1)) + 1
    valence = np.bincount(q.ravel(), minlength=nv)
    boundary_v = np.zeros(nv, dtype=bool)
    boundary_v[uniq[count == 1].ravel()] = True
    if manifold:  # one fan per vertex: corners around a vertex linked through shared edges
        manifold = _single_fans(q, nv)
    irregular = np.flatnonzero(np.where(boundary_v, valence != 2, valence != 4))
    p = v[q]
    a = p - np.roll(p, 1, 1)
    b = np.roll(p, -1, 1) - p
    cosang = (-(a * b).sum(-1)) / np.maximum(np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1), 1e-300)
    ang = np.degrees(np.arccos(np.clip(cosang, -1, 1)))
    return QuadMeshReport(
        num_vertices=nv,
        num_quads=q.shape[0],
        num_edges=uniq.shape[0],
        euler_characteristic=nv - uniq.shape[0] + q.shape[0],
        manifold=manifold,
        closed=closed,
        valence=valence,
        irregular=irregular,
        angle_deviation=float(np.abs(ang - 90).mean()) if q.size else 0.0,
    )


def _single_fans(q: np.ndarray, nv: int) -> bool:
    """Every vertex's corners are connected through the edges they share."""
    import scipy.sparse as sp
    import scipy.sparse.csgraph as csg

    nq = q.shape[0]
    corner = np.arange(4 * nq).reshape(nq, 4)
    # corner (f, k) at vertex q[f, k] touches edges (q[f,k-1], q[f,k]) and (q[f,k], q[f,k+1])
    keys: dict = {}
    links: list = []
    for side, nb in ((0, np.roll(q, 1, 1)), (1, np.roll(q, -1, 1))):
        del side
        lo, hi = np.minimum(q, nb), np.maximum(q, nb)
        for c, a, b, vtx in zip(corner.ravel(), lo.ravel(), hi.ravel(), q.ravel()):
            k = (int(vtx), int(a), int(b))
            if k in keys:
                links.append((keys[k], c))
            else:
                keys[k] = c
    links_a = np.array(links, dtype=np.int64).reshape(-1, 2)
    g = sp.coo_matrix((np.ones(len(links_a)), (links_a[:, 0], links_a[:, 1])), shape=(4 * nq, 4 * nq))
    _, lab = csg.connected_components(g, directed=False)
    per_vertex = np.unique(np.stack([q.ravel(), lab], 1), axis=0)[:, 0]
    return bool(np.all(np.bincount(per_vertex, minlength=nv)[np.unique(q)] == 1))


def save_quad_mesh(path, verts, quads) -> None:
    """Write a quad mesh to an OBJ, OFF or PLY (text) file, chosen by the extension;
    positions with ``%.17g`` (float64 round trip). The library's loader triangulates quads."""
    from pathlib import Path

    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    v = np.asarray(torch.as_tensor(verts).detach().cpu(), dtype=np.float64)
    q = np.asarray(torch.as_tensor(quads).detach().cpu(), dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or q.ndim != 2 or q.shape[1] != 4:
        raise ValueError(f"cannot save quad mesh {path}: expected (V, 3) verts and (Q, 4) quads")
    if q.size and (q.min() < 0 or q.max() >= len(v)):
        raise ValueError(f"cannot save quad mesh {path}: quad indices must lie in [0, {len(v)})")
    vert_lines = "".join(f"{a:.17g} {b:.17g} {c:.17g}\n" for a, b, c in v)
    if fmt == "obj":
        text = "".join("v " + line for line in vert_lines.splitlines(keepends=True))
        text += "".join(f"f {a + 1} {b + 1} {c + 1} {d + 1}\n" for a, b, c, d in q)
    elif fmt == "off":
        text = f"OFF\n{len(v)} {len(q)} 0\n" + vert_lines
        text += "".join(f"4 {a} {b} {c} {d}\n" for a, b, c, d in q)
    elif fmt == "ply":
        text = (
            f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty double x\nproperty double y\n"
            f"property double z\nelement face {len(q)}\nproperty list uchar int vertex_indices\nend_header\n"
        )
        text += vert_lines + "".join(f"4 {a} {b} {c} {d}\n" for a, b, c, d in q)
    else:
        raise ValueError(
            f"cannot save quad mesh {path}: unsupported extension {path.suffix!r}, expected obj, off or ply"
        )
    path.write_text(text)
