"""Non-manifold edges cut, each sheet oriented, and one vertex per fan."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components

from ..._validation import list_some
from .report import RepairReport


def _edge_groups(tri: np.ndarray, nv: int):
    """Half-edges (3 f + k, opposite corner k) grouped by undirected edge."""
    src, dst = tri[:, [1, 2, 0]].ravel(), tri[:, [2, 0, 1]].ravel()
    keys = np.minimum(src, dst) * nv + np.maximum(src, dst)
    uniq, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    order = np.argsort(inverse, kind="stable")
    start = np.cumsum(counts) - counts
    return src, dst, uniq, counts, order, start


def _orient(tri: np.ndarray, origin: np.ndarray, nv: int, report: RepairReport):
    """Cut non-manifold edges (report them) and orient each sheet by flipping its minority."""
    nt = len(tri)
    src, dst, uniq, counts, order, start = _edge_groups(tri, nv)
    many = counts > 2
    report.non_manifold_edges = [(int(k // nv), int(k % nv)) for k in uniq[many]]
    two = np.flatnonzero(counts == 2)
    h1, h2 = order[start[two]], order[start[two] + 1]
    f1, f2 = h1 // 3, h2 // 3
    same = src[h1] == src[h2]  # both faces run the edge the same way: one must flip
    # a virtual root joined to every face makes one breadth-first search orient all sheets
    graph = sp.coo_matrix((np.ones(len(two)), (f1, f2)), shape=(nt, nt)).tocsr()
    ncomp, labels = connected_components(graph, directed=False)
    roots = np.unique(labels, return_index=True)[1]
    rows = np.concatenate([f1, f2, np.full(len(roots), nt)])
    cols = np.concatenate([f2, f1, roots])
    full = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(nt + 1, nt + 1)).tocsr()
    bfs, pred = breadth_first_order(full, nt, directed=True, return_predecessors=True)
    # parity of each face relative to its predecessor, then along the tree by pointer doubling
    pair_keys = np.concatenate([f1 * (nt + 1) + f2, f2 * (nt + 1) + f1])
    pair_same = np.concatenate([same, same])
    srt = np.argsort(pair_keys)
    pair_keys, pair_same = pair_keys[srt], pair_same[srt]
    p = pred[:nt].astype(np.int64)
    tree = p < nt
    step = np.zeros(nt, dtype=bool)
    q = np.searchsorted(pair_keys, np.arange(nt)[tree] * (nt + 1) + p[tree])
    step[tree] = pair_same[q]
    parity, jump = step.copy(), np.where(tree, p, -1)
    while (jump >= 0).any():
        live = jump >= 0
        parity[live] ^= parity[jump[live]]
        nxt = np.full(nt, -1)
        nxt[live] = jump[jump[live]]
        jump = nxt
    conflict = (parity[f1] ^ parity[f2]) != same
    if conflict.any():
        comp = np.unique(labels[f1[conflict]])
        faces_bad = np.flatnonzero(np.isin(labels, comp))
        edges_bad = [(int(k // nv), int(k % nv)) for k in uniq[two[conflict]]]
        raise ValueError(
            f"repair: {len(comp)} sheet(s) cannot be oriented (non-orientable, like a Moebius strip): "
            f"input faces [{list_some(np.unique(origin[faces_bad]).tolist())}], "
            f"where the orientation conflicts across edges [{list_some(edges_bad)}]"
        )
    size = np.bincount(labels, minlength=ncomp)
    odd = np.bincount(labels, weights=parity, minlength=ncomp)
    flip = parity ^ (2 * odd > size)[labels]
    tri = tri.copy()
    tri[flip] = tri[flip][:, [0, 2, 1]]
    report.flipped_faces = np.unique(origin[flip]).tolist()
    del bfs
    return tri, flip


def _split_vertices(tri: np.ndarray, nv: int, report: RepairReport):
    """One vertex per fan: corners joined across manifold (two-face) edges; returns faces and origins."""
    nt = len(tri)
    src, dst, uniq, counts, order, start = _edge_groups(tri, nv)
    two = np.flatnonzero(counts == 2)
    h1, h2 = order[start[two]], order[start[two] + 1]
    f1, f2 = h1 // 3, h2 // 3
    k1, k2 = h1 % 3, h2 % 3
    # in face f the half-edge opposite corner k runs from corner k+1 to corner k+2; after
    # orientation the other face runs it backwards, from its corner k'+2 to k'+1
    a1, b1 = 3 * f1 + (k1 + 1) % 3, 3 * f1 + (k1 + 2) % 3
    a2, b2 = 3 * f2 + (k2 + 2) % 3, 3 * f2 + (k2 + 1) % 3
    corner_vertex = tri.ravel()
    ok = (corner_vertex[a1] == corner_vertex[a2]) & (corner_vertex[b1] == corner_vertex[b2])
    rows = np.concatenate([a1[ok], b1[ok]])
    cols = np.concatenate([a2[ok], b2[ok]])
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(3 * nt, 3 * nt))
    _, labels = connected_components(graph, directed=False)
    first = np.full(labels.max() + 1, 3 * nt, dtype=np.int64)
    np.minimum.at(first, labels, np.arange(3 * nt))
    group_vertex = corner_vertex[first]
    order_groups = np.lexsort((first, group_vertex))
    new_index = np.empty_like(order_groups)
    new_index[order_groups] = np.arange(len(order_groups))
    faces = new_index[labels].reshape(nt, 3)
    vertex_origin = group_vertex[order_groups]
    copies = np.bincount(vertex_origin, minlength=nv)
    split = np.flatnonzero(copies > 1)
    report.split_vertices = {int(i): int(copies[i]) for i in split}
    on_cut = np.zeros(nv, dtype=bool)
    for a, b in report.non_manifold_edges:
        on_cut[a] = on_cut[b] = True
    report.non_manifold_vertices = [int(i) for i in split if not on_cut[i]]
    return faces.astype(np.int64), vertex_origin.astype(np.int64)
