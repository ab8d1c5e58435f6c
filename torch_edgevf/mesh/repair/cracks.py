"""Zero-width cracks closed: coincident vertices merged, T-junctions split."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..._validation import list_some
from ..diagnose import _t_junctions
from .report import RepairReport


def _merge_clusters(pairs: np.ndarray, nv: int) -> np.ndarray:
    """(V,) map of each vertex to the lowest index of its cluster (pairs joined transitively)."""
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(nv, nv))
    _, labels = connected_components(graph, directed=False)
    lowest = np.full(labels.max() + 1, nv, dtype=np.int64)
    np.minimum.at(lowest, labels, np.arange(nv))
    return lowest[labels]


def _split_at_t_junctions(v, tri, origin, tol, junctions, report: RepairReport, max_rounds: int = 8):
    """Split triangles at their T-junction vertices until none is left; fill the report.

    Each round splits every triangle along one of its edges (the first with T-junction
    vertices): the triangle ``(a, b, c)`` whose edge ``a -> b`` holds the vertices
    ``w_1, ..., w_m`` (in order from ``a``) becomes the fan ``(a, w_1, c), (w_1, w_2, c),
    ..., (w_m, b, c)`` with the same winding. The other two edges are edges of the new
    triangles, so the next round (a fresh search) finds their T-junctions again.
    """
    split: list[np.ndarray] = []
    before = len(tri)
    w, t, k, _ = junctions
    for _round in range(max_rounds):
        if not len(w):
            break
        # rows are sorted by triangle, corner, position: keep the first corner of each triangle
        first_k = np.full(len(tri), 3)
        np.minimum.at(first_k, t, k)
        sel = k == first_k[t]
        w, t, k = w[sel], t[sel], k[sel]
        start = np.r_[True, t[1:] != t[:-1]]
        end = np.r_[t[1:] != t[:-1], True]
        a, b, c = tri[t, (k + 1) % 3], tri[t, (k + 2) % 3], tri[t, k]
        prev = np.where(start, a, np.r_[0, w[:-1]])
        fans = np.concatenate([np.stack([prev, w, c], 1), np.stack([w[end], b[end], c[end]], 1)])
        fan_origin = np.concatenate([origin[t], origin[t[end]]])
        split.append(origin[t[end]])
        keep = np.ones(len(tri), dtype=bool)
        keep[t] = False
        tri = np.concatenate([tri[keep], fans])
        origin = np.concatenate([origin[keep], fan_origin])
        order = np.argsort(origin, kind="stable")  # triangles in the order of their faces
        tri, origin = tri[order], origin[order]
        w, t, k, _ = _t_junctions(v, tri, tol)
    else:
        if len(w):  # not expected: each round removes the T-junctions of one edge per face
            raise ValueError(
                f"repair: T-junctions left after {max_rounds} rounds of splitting, at input faces "
                f"[{list_some(np.unique(origin[t]).tolist())}]"
            )
    report.split_faces = np.unique(np.concatenate(split)).tolist() if split else []
    report.t_junction_triangles = int(len(tri) - before)
    return np.ascontiguousarray(tri), origin
