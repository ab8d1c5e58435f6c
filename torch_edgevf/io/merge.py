"""Vertices at identical positions merged where the merge joins a surface (a crack of zero width).

A file may store one point of the surface as several vertices: STL always does, other
tools split vertices at texture seams, and a surface may be cut along a seam. Merging
every pair of vertices at identical positions would also fuse surfaces that only touch
(at a vertex or along an edge) into non-manifold edges and bowtie vertices. Here a merge
is made only where it closes a crack:

1. boundary edges (one face) are grouped by the positions of their ends; a group of
   exactly two edges at the same pair of positions, from different faces, is a crack, and
   its two edges are joined: the vertices at equal positions merged (each vertex of a
   group of three or more edges at one pair of positions is left apart, since which
   edges belong together is ambiguous);
2. the joins are checked together: a join is undone when the merged mesh would have a
   face with a repeated vertex, two faces on the same three vertices, or an edge of more
   than two faces at a vertex it merged; this repeats until no join is undone.

Each merged vertex has its faces in one fan through the manifold edge that joined it, so
no merge makes a bowtie vertex. Vertices at a position that another vertex also takes,
and that no join merged, are left apart and listed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components


@dataclass
class MergeResult:
    """What :func:`join_cracks` merged.

    ``merged_to`` maps every vertex to the lowest index of the vertices merged with it
    (itself when not merged); ``joined_edges`` counts the pairs of boundary edges joined;
    ``left_apart`` lists the referenced vertices at a position shared with another
    referenced vertex that were not merged with it; ``ambiguous_edges`` counts the boundary
    edges in groups of three or more at one pair of positions, ``undone_joins`` the joins
    undone by the checks.
    """

    merged_to: np.ndarray
    joined_edges: int = 0
    left_apart: list[int] = field(default_factory=list)
    ambiguous_edges: int = 0
    undone_joins: int = 0

    @property
    def merged_vertices(self) -> int:
        return int((self.merged_to != np.arange(len(self.merged_to))).sum())


def face_keys(faces: np.ndarray, nv: int) -> np.ndarray:
    """One key per face, equal for faces on the same three vertices (in any order).

    An int64 for ``nv < 2**21`` (the common case: no sort along the rows), else a row of
    the sorted indices viewed as bytes.
    """
    a, b, c = np.ascontiguousarray(faces.T)  # contiguous columns: the reductions run faster
    if nv < 2**21:
        lo = np.minimum(np.minimum(a, b), c)
        hi = np.maximum(np.maximum(a, b), c)
        return (lo * nv + (a + b + c - lo - hi)) * nv + hi
    return np.ascontiguousarray(np.sort(faces, axis=1)).view(np.dtype((np.void, 24))).reshape(-1)


def has_repeats(keys: np.ndarray) -> bool:
    """Whether two entries of a 1-D integer array are equal (one sort, no argsort)."""
    s = np.sort(keys)
    return bool(len(s) > 1 and (s[1:] == s[:-1]).any())


def run_sizes(keys: np.ndarray) -> np.ndarray:
    """For each entry of a 1-D array, how many entries equal it."""
    order = np.argsort(keys)
    s = keys[order]
    start = np.flatnonzero(np.r_[True, s[1:] != s[:-1]])
    size = np.diff(np.r_[start, len(s)])
    out = np.empty(len(keys), dtype=np.int64)
    out[order] = np.repeat(size, size)
    return out


def position_classes(
    verts: np.ndarray, used: np.ndarray | None = None, finite: bool = False
) -> np.ndarray | None:
    """(V,) int64, the lowest index of the vertices at each vertex's position, or None if all differ.

    Positions are compared bitwise (``-0.0`` equals ``0.0``); vertices with NaN or Inf
    coordinates and those not ``used`` are in classes of their own (``finite``: all
    coordinates are known to be finite). The rows are hashed and sorted once; equal hashes
    are then checked coordinate by coordinate.
    """
    nv = len(verts)
    candidates = np.ones(nv, dtype=bool) if finite else np.isfinite(verts.sum(1))
    if used is not None:
        candidates &= used
    idx = None if candidates.all() else np.flatnonzero(candidates)
    if idx is not None and len(idx) < 2:
        return None
    # the bits of each coordinate, -0.0 as 0.0 (one column at a time: row gathers are slow)
    cols = [np.ascontiguousarray(verts[:, c] if idx is None else verts[idx, c]) + 0.0 for c in range(3)]
    bits = [c.view(np.uint64) for c in cols]
    with np.errstate(over="ignore"):
        h = (
            bits[0] * np.uint64(0x9E3779B97F4A7C15)
            ^ bits[1] * np.uint64(0xC2B2AE3D27D4EB4F)
            ^ bits[2] * np.uint64(0x165667B19E3779F9)
        )
    s = np.sort(h)
    repeat = s[1:] == s[:-1]
    if not repeat.any():
        return None
    values = s[1:][repeat]
    if len(values) <= 64:  # a few repeated hashes: sort only their vertices
        sub = np.flatnonzero(np.isin(h, values))
        h, bits, idx = h[sub], [col[sub] for col in bits], (sub if idx is None else idx[sub])
    order = np.argsort(h)
    hs = h[order]
    start = np.r_[True, hs[1:] != hs[:-1]]
    run = np.cumsum(start) - 1
    leader = order[start][run]  # per sorted entry, the first entry of its run
    same = np.ones(len(order), dtype=bool)
    for col in bits:
        same &= col[order] == col[leader]
    if not same.all():  # a hash collision: compare the rows themselves
        rows = np.stack([col[order] for col in bits], 1)
        _, run = np.unique(rows, axis=0, return_inverse=True)
        run = run.reshape(-1)
    members = order if idx is None else idx[order]
    lowest = np.full(run.max() + 1, nv, dtype=np.int64)
    np.minimum.at(lowest, run, members)
    out = np.arange(nv, dtype=np.int64)
    out[members] = lowest[run]
    if (out == np.arange(nv)).all():
        return None
    return out


def join_cracks(
    verts: np.ndarray, faces: np.ndarray, used: np.ndarray | None = None, finite: bool = False
) -> MergeResult:
    """Merge vertices at identical positions where two boundary edges join into a manifold edge.

    ``faces`` are valid triangles (indices in range, no repeated index, no duplicates);
    ``used`` marks the vertices that ``faces`` use, if known; ``finite``: every coordinate
    is known to be finite. See the module docstring for the rule.
    """
    nv = len(verts)
    if used is None:
        used = np.zeros(nv, dtype=bool)
        used[faces] = True
    pos = position_classes(verts, used, finite)
    identity = np.arange(nv, dtype=np.int64)
    if pos is None:
        return MergeResult(identity)
    shared = (np.bincount(pos, minlength=nv) > 1)[pos]  # another vertex takes its position
    # every face with an edge at a shared vertex has that vertex: the faces without one
    # take no part (their edges keep their face counts)
    faces = faces[shared[faces].any(1)]
    # boundary half-edges (a -> b of exactly one face) with an end at a shared position
    half = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    a, b = half[:, 0], half[:, 1]
    # per half-edge, the faces of its edge; an edge of two faces has ends used twice or more
    uses = np.bincount(faces.ravel(), minlength=nv)
    faces_of_edge = np.ones(len(half), dtype=np.int64)
    multi = np.flatnonzero((uses[a] > 1) & (uses[b] > 1))
    faces_of_edge[multi] = run_sizes(np.minimum(a[multi], b[multi]) * nv + np.maximum(a[multi], b[multi]))
    pa, pb = pos[a], pos[b]
    cand = np.flatnonzero((faces_of_edge == 1) & (shared[a] | shared[b]) & (pa != pb))
    pkey = np.minimum(pa, pb)[cand] * nv + np.maximum(pa, pb)[cand]
    order = np.argsort(pkey)
    cand, pkey = cand[order], pkey[order]
    start = np.r_[True, pkey[1:] != pkey[:-1]]
    size = np.diff(np.r_[np.flatnonzero(start), len(pkey)])
    size = np.repeat(size, size)
    ambiguous = int((size > 2).sum())
    first = np.flatnonzero(start & (size == 2))
    h1, h2 = cand[first], cand[first + 1]
    h1, h2 = h1[h1 // 3 != h2 // 3], h2[h1 // 3 != h2 // 3]
    if not len(h1):  # surfaces that only touch: nothing to join
        left = np.flatnonzero(used & shared)
        return MergeResult(identity, left_apart=left.tolist(), ambiguous_edges=ambiguous)
    # the join's vertex pairs: ends at equal positions
    same_dir = pa[h1] == pa[h2]
    u = np.concatenate([a[h1], b[h1]])
    w = np.concatenate([np.where(same_dir, a[h2], b[h2]), np.where(same_dir, b[h2], a[h2])])
    joins = np.arange(len(h1))
    undone = 0
    while True:
        merged_to = _components(np.concatenate([joins, joins + len(h1)]), u, w, nv)
        bad = _violations(faces, merged_to, faces_of_edge)
        if not len(bad):
            break
        # undo the joins with a vertex in a class at fault
        at_fault = np.zeros(nv, dtype=bool)
        at_fault[bad] = True
        drop = at_fault[merged_to[u[joins]]] | at_fault[merged_to[u[joins + len(h1)]]]
        undone += int(drop.sum())
        joins = joins[~drop]
    class_size = np.bincount(merged_to[used], minlength=nv)[merged_to]
    position_size = np.bincount(pos[used], minlength=nv)[pos]
    left = np.flatnonzero(used & (class_size < position_size))
    return MergeResult(
        merged_to=merged_to,
        joined_edges=len(joins),
        left_apart=left.tolist(),
        ambiguous_edges=ambiguous,
        undone_joins=undone,
    )


def _components(rows: np.ndarray, u: np.ndarray, w: np.ndarray, nv: int) -> np.ndarray:
    """The lowest index of each vertex's class, the classes joined by the pairs ``(u, w)[rows]``."""
    out = np.arange(nv, dtype=np.int64)
    if not len(rows):
        return out
    ends = np.concatenate([u[rows], w[rows]])
    touched = np.flatnonzero(np.bincount(ends, minlength=nv))
    n = len(touched)
    lookup = np.empty(nv, dtype=np.int64)
    lookup[touched] = np.arange(n)
    local = lookup[ends].reshape(2, -1)
    graph = sp.coo_matrix((np.ones(len(rows)), (local[0], local[1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    lowest = np.full(labels.max() + 1, nv, dtype=np.int64)
    np.minimum.at(lowest, labels, touched)
    out[touched] = lowest[labels]
    return out


def _violations(faces: np.ndarray, merged_to: np.ndarray, faces_of_edge: np.ndarray) -> np.ndarray:
    """Merged vertices (class representatives) at a collapsed face, a duplicate face or an edge
    that the merge gave more than two faces (``faces_of_edge``: the face count of each
    half-edge's edge before merging)."""
    nv = len(merged_to)
    merged = np.zeros(nv, dtype=bool)
    merged[merged_to[merged_to != np.arange(nv)]] = True  # representatives of classes of several
    f = merged_to[faces]
    touched = np.flatnonzero(merged[f].any(1))
    if not len(touched):
        return np.zeros(0, dtype=np.int64)
    ft = f[touched]
    collapsed = (ft[:, 0] == ft[:, 1]) | (ft[:, 1] == ft[:, 2]) | (ft[:, 2] == ft[:, 0])
    bad = [ft[collapsed].ravel()]
    # a face with a merged vertex that another face repeats has that vertex too
    keys = face_keys(ft, nv)
    if keys.dtype.kind == "V":
        _, tinv, tcount = np.unique(keys, return_inverse=True, return_counts=True)
        bad.append(ft[tcount[tinv.reshape(-1)] > 1].ravel())
    else:
        bad.append(ft[run_sizes(keys) > 1].ravel())
    half = f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    lo, hi = np.minimum(half[:, 0], half[:, 1]), np.maximum(half[:, 0], half[:, 1])
    at_merged = merged[lo] | merged[hi]
    merged_count = run_sizes(lo[at_merged] * nv + hi[at_merged])
    over = (merged_count > 2) & (merged_count > faces_of_edge[at_merged])
    bad.append(np.concatenate([lo[at_merged][over], hi[at_merged][over]]))
    out = np.unique(np.concatenate(bad))
    return out[merged[out]]
