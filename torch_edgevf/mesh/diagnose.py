"""Mesh diagnosis: every problem found, with its location, instead of the first error.

:func:`diagnose` runs the checks of the library and lists every problem. Two of them
concern meshes that are valid but not what their author meant, so that nothing else
rejects them:

* coincident vertices (:func:`find_coincident_vertices`): distinct, referenced vertices
  at one position. A vertex split at one position leaves a zero-width crack that the
  topology sees as two boundary loops.
* T-junctions (:func:`find_t_junctions`): a boundary vertex lying inside a boundary edge
  of another face, typically where one side of a seam was subdivided and the other not;
  the topology sees a hole of zero width.

Both use a tolerance relative to the diagonal of the bounding box of the referenced
vertices, :data:`COINCIDENT_TOL` by default, and a k-d tree (``scipy.spatial.cKDTree``),
so that they stay near-linear in the size of the mesh.
:func:`~torch_edgevf.mesh.repair.repair` reports both, and closes the cracks when asked
(``merge_coincident=True``, ``split_t_junctions=True``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import chain

import numpy as np

from .._validation import as_faces, as_verts, check_face_range, list_some
from .geometry import face_geometry
from .topology import Topology

__all__ = [
    "COINCIDENT_TOL",
    "Diagnosis",
    "diagnose",
    "find_coincident_vertices",
    "find_t_junctions",
]

#: Default tolerance of :func:`find_coincident_vertices` and :func:`find_t_junctions`,
#: relative to the diagonal of the bounding box of the referenced vertices: positions
#: closer than ``COINCIDENT_TOL * diagonal`` count as equal. Float32 rounding of
#: coordinates of the size of the mesh stays below it; the closest distinct vertices of
#: the real test meshes are more than ten times farther apart.
COINCIDENT_TOL = 1e-6


@dataclass
class Diagnosis:
    """Topology summary (when it could be built) and the list of problems found.

    Attributes
    ----------
    summary : dict of counts from :meth:`Topology.summary`, or None
    problems : list of str, one line per problem, naming where it is
    coincident_vertices : (K, 2) int64 array of vertex pairs ``i < j`` at one position
        (see :func:`find_coincident_vertices`); empty when there are none or the check
        could not run
    t_junctions : (K, 4) int64 array of rows ``(vertex, a, b, face)``: ``vertex`` lies
        inside the boundary edge ``(a, b)``, ``a < b``, of ``face`` (see
        :func:`find_t_junctions`)
    """

    summary: dict | None = None
    problems: list[str] = field(default_factory=list)
    coincident_vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    t_junctions: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.int64))

    @property
    def ok(self) -> bool:
        return not self.problems

    def __str__(self) -> str:
        lines = []
        if self.summary:
            lines += [f"{k.replace('_', ' ')}: {v}" for k, v in self.summary.items()]
        lines += ["no problems found"] if self.ok else [f"problem: {p}" for p in self.problems]
        return "\n".join(lines)


def diagnose(verts, faces, tol: float = COINCIDENT_TOL) -> Diagnosis:
    """Run every check of the library on a mesh and collect the problems (never raises).

    The checks: the shapes and dtypes of ``verts`` and ``faces``, the topology (manifold,
    oriented, unreferenced vertices), the face geometry (zero-area faces, scale), and
    the two kinds of zero-width crack, coincident vertices and T-junctions, each listed
    with the elements involved and what :func:`~torch_edgevf.mesh.repair.repair` would
    do about it.

    Parameters
    ----------
    verts : (V, 3) float tensor or array
    faces : (F, 3) integer tensor or array
    tol : float >= 0, the tolerance of the crack checks relative to the bounding-box
        diagonal (0: bitwise-equal positions only)

    Returns
    -------
    :class:`Diagnosis`
    """
    out = Diagnosis()
    try:
        faces = as_faces(faces)
    except ValueError as exc:
        out.problems.append(str(exc))
        return out
    try:
        verts = as_verts(verts)
    except ValueError as exc:
        out.problems.append(str(exc))
        verts = None
    try:
        topo = Topology(faces, num_vertices=None if verts is None else verts.shape[0])
        out.summary = topo.summary()
        if topo.unreferenced_vertices.numel():
            n = topo.unreferenced_vertices.numel()
            out.problems.append(f"{n} unreferenced vertices (kept, with zero rows in vertex operators)")
    except ValueError as exc:
        out.problems.append(str(exc))
    if verts is not None:
        try:
            face_geometry(verts, faces)
        except ValueError as exc:
            out.problems.append(str(exc))
        try:
            out.coincident_vertices = find_coincident_vertices(verts, faces, tol)
            out.t_junctions = find_t_junctions(verts, faces, tol)
        except ValueError as exc:  # indices out of range (named above by the topology) or tol
            out.problems.append(str(exc))
        out.problems += crack_problems(out.coincident_vertices, out.t_junctions, tol)
    return out


def crack_problems(coincident, t_junctions, tol: float = COINCIDENT_TOL) -> list[str]:
    """Problem lines for coincident vertices and T-junctions (none when both are empty).

    Parameters
    ----------
    coincident : (K, 2) integer array or sequence of vertex pairs
    t_junctions : (K, 4) integer array or sequence of ``(vertex, a, b, face)``
    tol : the tolerance the pairs were found with (for the message)
    """
    out = []
    if len(coincident):
        pairs = [(int(i), int(j)) for i, j in coincident]
        out.append(
            f"{len(pairs)} pairs of coincident vertices (distinct vertices at one position, within "
            f"{tol:g} of the bounding-box diagonal: a zero-width crack unless merged) at vertex pairs "
            f"[{list_some(pairs)}]; repair(..., merge_coincident=True) merges them"
        )
    if len(t_junctions):
        rows = [f"{int(v)} in ({int(a)}, {int(b)}) of face {int(f)}" for v, a, b, f in t_junctions]
        out.append(
            f"{len(rows)} T-junctions (a boundary vertex inside a boundary edge of another face: "
            f"a zero-width crack) at [{list_some(rows)}]; repair(..., split_t_junctions=True) "
            "splits those faces at the vertices"
        )
    return out


# --------------------------------------------------------------------------- cracks


def _check_tol(tol) -> float:
    if isinstance(tol, bool) or not isinstance(tol, (int, float, np.floating)) or not (0 <= tol < 1):
        raise ValueError(f"tol must be a number in [0, 1), got {tol!r}")
    return float(tol)


def _as_arrays(verts, faces) -> tuple[np.ndarray, np.ndarray]:
    """float64 positions and int64 (F, 3) faces, checked (ValueError naming the problem)."""
    v = as_verts(verts).detach().cpu().numpy().astype(np.float64)
    f = as_faces(faces).cpu().numpy()
    check_face_range(f, len(v))
    return v, f


def _scaled(v: np.ndarray, used: np.ndarray, tol: float) -> tuple[np.ndarray, float]:
    """Positions scaled by a power of two (exact) into [-1, 1], and the absolute tolerance.

    The scaling keeps bitwise equality and every ratio of distances, and keeps the
    bounding-box diagonal finite for coordinates near the float64 limits.
    """
    pts = v[used]
    if not len(pts):
        return v, 0.0
    m = float(np.abs(pts).max())
    scale = 2.0 ** -np.ceil(np.log2(m)) if m > 0 else 1.0
    q = v * scale
    p = q[used]
    diag = float(np.linalg.norm(p.max(0) - p.min(0)))
    return q, tol * diag


def _referenced(v: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Sorted indices of the vertices used by ``tri`` with finite coordinates."""
    used = np.zeros(len(v), dtype=bool)
    used[tri.ravel()] = True
    return np.flatnonzero(used & np.isfinite(v).all(1))


def _coincident_pairs(v: np.ndarray, tri: np.ndarray, tol: float) -> np.ndarray:
    """(K, 2) pairs ``i < j`` of referenced finite vertices closer than ``tol`` times the diagonal."""
    from scipy.spatial import cKDTree

    used = _referenced(v, tri)
    if len(used) < 2:
        return np.zeros((0, 2), np.int64)
    q, r = _scaled(v, used, tol)
    if r == 0:  # bitwise-equal positions (-0.0 == 0.0)
        _, inverse, counts = np.unique(q[used] + 0.0, axis=0, return_inverse=True, return_counts=True)
        inverse = inverse.reshape(-1)
        rep = counts[inverse] > 1
        if not rep.any():
            return np.zeros((0, 2), np.int64)
        idx, grp = used[rep], inverse[rep]
        order = np.lexsort((idx, grp))
        idx, grp = idx[order], grp[order]
        pairs = []
        for g in np.unique(grp):
            members = idx[grp == g].tolist()
            pairs += [(a, b) for k, a in enumerate(members) for b in members[k + 1 :]]
        out = np.array(pairs, dtype=np.int64).reshape(-1, 2)
    else:
        local = cKDTree(q[used]).query_pairs(r, output_type="ndarray")
        out = np.sort(used[local].reshape(-1, 2), axis=1).astype(np.int64)
    if not len(out):
        return np.zeros((0, 2), np.int64)
    return out[np.lexsort((out[:, 1], out[:, 0]))]


def _t_junctions(v: np.ndarray, tri: np.ndarray, tol: float):
    """T-junctions of the triangles ``tri``: arrays (vertex, triangle, corner, s), sorted.

    A boundary half-edge (an edge of exactly one triangle) of triangle ``t`` opposite
    corner ``k`` runs from ``tri[t, k+1]`` to ``tri[t, k+2]``; ``vertex`` is a boundary
    vertex, not of ``t``, within ``tol`` times the diagonal of the segment and farther
    than that from both ends; ``s`` in (0, 1) is its parameter along the half-edge.
    Candidates come from a k-d tree of the boundary vertices, queried with balls around
    pieces of each edge no longer than the median boundary edge (so that a long edge
    does not gather every vertex).
    """
    from scipy.spatial import cKDTree

    empty = (np.zeros(0, np.int64),) * 3 + (np.zeros(0),)
    nv = len(v)
    if len(tri) == 0:
        return empty
    src, dst = tri[:, [1, 2, 0]].ravel(), tri[:, [2, 0, 1]].ravel()
    keys = np.minimum(src, dst) * nv + np.maximum(src, dst)
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    half = np.flatnonzero(counts[inverse.reshape(-1)] == 1)
    a, b = src[half], dst[half]
    finite = np.isfinite(v).all(1)
    keep = finite[a] & finite[b]
    half, a, b = half[keep], a[keep], b[keep]
    if not len(half):
        return empty
    used = _referenced(v, tri)
    q, r = _scaled(v, used, tol)
    bverts = np.unique(np.concatenate([a, b]))
    # one tree point per distinct position (a soup repeats each position at every corner)
    where, slot = np.unique(q[bverts] + 0.0, axis=0, return_inverse=True)
    slot = slot.reshape(-1)
    A, B = q[a], q[b]
    d = B - A
    length = np.linalg.norm(d, axis=1)
    long = length > 2 * r  # shorter edges have no inside farther than r from both ends
    half, a, b, A, B, d, length = (x[long] for x in (half, a, b, A, B, d, length))
    if not len(half):
        return empty
    piece = max(float(np.median(length)), float(length.sum()) / (4 * len(length)))
    pieces = np.maximum(np.ceil(length / piece), 1).astype(np.int64)
    edge_of = np.repeat(np.arange(len(half)), pieces)
    start = np.cumsum(pieces) - pieces
    rank = np.arange(len(edge_of)) - start[edge_of]
    centre = A[edge_of] + ((rank + 0.5) / pieces[edge_of])[:, None] * d[edge_of]
    radius = 0.5 * length[edge_of] / pieces[edge_of] + r
    radius = radius * (1 + 1e-12) + 1e-300  # no candidate lost to rounding of the ball
    found = cKDTree(where).query_ball_point(centre, radius, return_sorted=False)
    sizes = np.fromiter((len(x) for x in found), dtype=np.int64, count=len(found))
    total = int(sizes.sum())
    if not total:
        return empty
    ce = np.repeat(edge_of, sizes)
    cp = np.fromiter(chain.from_iterable(found), dtype=np.int64, count=total)
    # the geometric test per distinct position, then every vertex at the positions that pass
    P = where[cp]
    rel = P - A[ce]
    s = np.einsum("ij,ij->i", rel, d[ce]) / length[ce] ** 2
    dist = np.linalg.norm(rel - s[:, None] * d[ce], axis=1)
    inside = (dist <= r) & (np.linalg.norm(rel, axis=1) > r) & (np.linalg.norm(P - B[ce], axis=1) > r)
    inside &= (s > 0) & (s < 1)
    ce, cp, s = ce[inside], cp[inside], s[inside]
    if not len(ce):
        return empty
    by_slot = np.argsort(slot, kind="stable")
    first = np.searchsorted(slot[by_slot], np.arange(len(where)))
    count = np.bincount(slot, minlength=len(where))
    ce, s = np.repeat(ce, count[cp]), np.repeat(s, count[cp])
    offset = np.arange(len(ce)) - np.repeat(np.cumsum(count[cp]) - count[cp], count[cp])
    cv = bverts[by_slot[np.repeat(first[cp], count[cp]) + offset]]
    _, once = np.unique(ce * nv + cv, return_index=True)  # an edge of several pieces finds a vertex again
    ce, cv, s = ce[once], cv[once], s[once]
    t, k = half[ce] // 3, half[ce] % 3
    mine = (tri[t] == cv[:, None]).any(1)  # a corner of the face itself (a degenerate face)
    cv, t, k, s = cv[~mine], t[~mine], k[~mine], s[~mine]
    order = np.lexsort((s, k, t))
    return cv[order], t[order], k[order], s[order]


def find_coincident_vertices(verts, faces, tol: float = COINCIDENT_TOL) -> np.ndarray:
    """Pairs of distinct, referenced vertices at one position.

    Vertices ``i < j`` that some face uses are coincident when

    .. math::  \\lVert p_i - p_j \\rVert \\le \\text{tol}\\; \\lVert \\max_k p_k - \\min_k p_k \\rVert,

    the right-hand side being ``tol`` times the bounding-box diagonal of the referenced
    vertices (``tol = 0``: bitwise-equal coordinates only). A cluster of ``m`` vertices
    at one place gives its ``m (m - 1) / 2`` pairs. Pairs joined by an edge (zero-length
    edges) are included. Found with ``scipy.spatial.cKDTree.query_pairs``.

    Parameters
    ----------
    verts : (V, 3) float tensor or array (finite)
    faces : (F, 3) integer tensor or array
    tol : float in [0, 1), default :data:`COINCIDENT_TOL`

    Returns
    -------
    (K, 2) int64 array of ``(i, j)``, ``i < j``, in lexicographic order

    Raises
    ------
    ValueError
        Wrong shapes or dtypes, NaN coordinates, indices out of range, or a bad ``tol``.
    """
    tol = _check_tol(tol)
    v, f = _as_arrays(verts, faces)
    return _coincident_pairs(v, f, tol)


def find_t_junctions(verts, faces, tol: float = COINCIDENT_TOL) -> np.ndarray:
    """T-junctions: boundary vertices lying inside a boundary edge of another face.

    A boundary edge is an edge of exactly one face. The boundary vertex ``w`` (an end of
    a boundary edge) is a T-junction of the boundary edge ``(a, b)`` of face ``f`` when
    ``w`` is not a corner of ``f`` and, with ``r = tol`` times the bounding-box diagonal
    of the referenced vertices,

    .. math::  \\operatorname{dist}(p_w, [p_a, p_b]) \\le r, \\qquad
               \\lVert p_w - p_a \\rVert > r, \\qquad \\lVert p_w - p_b \\rVert > r,

    with its projection strictly inside the segment. Such a vertex is where one side of a
    crack was subdivided and the other not; splitting ``f`` at ``w`` closes the crack
    (:func:`~torch_edgevf.mesh.repair.repair` with ``split_t_junctions=True``). A vertex
    within ``r`` of an end is a coincident vertex instead (:func:`find_coincident_vertices`).

    Parameters
    ----------
    verts, faces, tol : as for :func:`find_coincident_vertices`

    Returns
    -------
    (K, 4) int64 array of rows ``(vertex, a, b, face)``, ``a < b``, ordered by face, then
    edge, then distance from ``a``; ``ValueError`` as :func:`find_coincident_vertices`
    """
    tol = _check_tol(tol)
    v, f = _as_arrays(verts, faces)
    w, t, k, s = _t_junctions(v, f, tol)
    a, b = f[t, (k + 1) % 3], f[t, (k + 2) % 3]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    from_lo = np.where(a < b, s, 1 - s)
    order = np.lexsort((from_lo, hi, lo, t))
    rows = np.stack([w, lo, hi, t], axis=1).astype(np.int64).reshape(-1, 4)
    return rows[order]
