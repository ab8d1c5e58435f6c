"""Quad extraction from an integer-grid map (after [EBCK13] "QEx", by cell flooding).

The integer iso-lines ``u = i`` and ``v = j`` of a locally injective integer-grid map cut the
surface into quads: each is the preimage of one unit square ``[i, i+1] x [j, j+1]``. Instead
of tracing the iso-lines edge by edge, the quads are found as regions:

1. *pieces*: every triangle meets, in its own chart, the open unit squares of its ``uv``
   bounding box; a (triangle, square) pair is a piece when their interiors intersect, which
   the separating-axis test decides with the two axes and the three edge normals (exact on the
   designed coincidences: cones and boundary vertices at integer coordinates);
2. *flooding*: two pieces are one quad when the square of one, carried into the other
   triangle's chart by the transition ``w_g = i^{-k} w_f + t`` of their shared edge, is the
   other's square and the open edge crosses that square. A union-find over pieces, which
   keeps the quarter turn between each piece's chart and its quad's reference chart, gives
   the quads;
3. *corners*: a square's corner lying in the closed triangle of one of its pieces is a quad
   vertex: the mesh vertex it coincides with (a cone), a point on an edge (named in the
   chart of the edge's first face, so both sides agree) or a point inside the triangle. Each
   quad must get exactly one vertex at each of its four reference corners.

Every check that fails (a flipped or degenerate triangle, a square met on one side of an
edge but not the other, a quad with a missing or doubled corner) raises ``ValueError``: the
result is a quad mesh of the map, or nothing.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from ..mesh.topology import Topology

__all__ = ["extract_quads", "QuadExtraction"]

_CORNERS = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])


class QuadExtraction:
    """Quads of an integer-grid map.

    Attributes
    ----------
    verts : (Q_V, 3) float64 array, points on the triangle mesh
    quads : (Q_F, 4) int64 array, counter-clockwise
    vertex_face : (Q_V,) int64, a triangle containing each quad vertex
    vertex_bary : (Q_V, 3) float64, its barycentric coordinates there
    vertex_mesh_vertex : (Q_V,) int64, the mesh vertex a quad vertex coincides with, or -1
    """

    def __init__(self, verts, quads, vertex_face, vertex_bary, vertex_mesh_vertex):
        self.verts = verts
        self.quads = quads
        self.vertex_face = vertex_face
        self.vertex_bary = vertex_bary
        self.vertex_mesh_vertex = vertex_mesh_vertex


def _orient(a, b, q):
    """``(b - a) x (q - a)``, broadcast; exact in sign (zero when exactly collinear).

    Evaluated in floating point; values too small to trust are recomputed exactly with
    rational arithmetic on the floats (every float is a dyadic rational).
    """
    a, b, q = np.broadcast_arrays(a, b, q)
    o = (b[..., 0] - a[..., 0]) * (q[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (q[..., 0] - a[..., 0])
    mag = (np.abs(b) + np.abs(a)).max(-1) * (np.abs(q) + np.abs(a)).max(-1)
    doubt = np.abs(o) <= 1e-12 * np.maximum(mag, 1.0)
    if doubt.any():
        idx = np.nonzero(doubt)
        for k, (pa, pb, pq) in enumerate(zip(a[idx].tolist(), b[idx].tolist(), q[idx].tolist())):
            ax, ay = Fraction(pa[0]), Fraction(pa[1])
            exact = (Fraction(pb[0]) - ax) * (Fraction(pq[1]) - ay) - (Fraction(pb[1]) - ay) * (
                Fraction(pq[0]) - ax
            )
            o[tuple(i[k] for i in idx)] = float(exact) if exact else 0.0
    return o


def _expand_cells(lo: np.ndarray, hi: np.ndarray):
    """All integer cells ``(i, j)`` with ``lo <= (i, j) <= hi`` per row: (row, i, j) arrays."""
    nx = (hi[:, 0] - lo[:, 0] + 1).clip(min=0)
    ny = (hi[:, 1] - lo[:, 1] + 1).clip(min=0)
    count = nx * ny
    row = np.repeat(np.arange(lo.shape[0]), count)
    start = np.repeat(np.cumsum(count) - count, count)
    k = np.arange(row.size) - start
    i = lo[row, 0] + k // ny[row]
    j = lo[row, 1] + k % ny[row]
    return row, i, j


def _cell_range(pts: np.ndarray):
    """Cells whose closed square can meet the convex hull of ``pts`` (rows, k, 2)."""
    lo = np.floor(pts.min(1)).astype(np.int64)
    hi = np.floor(pts.max(1)).astype(np.int64)
    return lo, hi


def _triangle_meets_cell(tri: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Interiors of the counter-clockwise triangles ``tri`` (n, 3, 2) and the open squares meet."""
    umin, umax = tri[:, :, 0].min(1), tri[:, :, 0].max(1)
    vmin, vmax = tri[:, :, 1].min(1), tri[:, :, 1].max(1)
    ok = (umax > i) & (umin < i + 1) & (vmax > j) & (vmin < j + 1)
    q = np.stack([i, j], -1)[:, None, :] + _CORNERS[None]  # (n, 4, 2)
    for k in range(3):
        a, b = tri[:, k][:, None], tri[:, (k + 1) % 3][:, None]
        ok &= _orient(a, b, q).max(1) > 0
    return ok


def _segment_crosses_cell(a: np.ndarray, b: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """The open segments ``a b`` (n, 2) pass through the open squares."""
    ok = (np.maximum(a[:, 0], b[:, 0]) > i) & (np.minimum(a[:, 0], b[:, 0]) < i + 1)
    ok &= (np.maximum(a[:, 1], b[:, 1]) > j) & (np.minimum(a[:, 1], b[:, 1]) < j + 1)
    q = np.stack([i, j], -1)[:, None, :] + _CORNERS[None]
    o = _orient(a[:, None], b[:, None], q)
    return ok & (o.max(1) > 0) & (o.min(1) < 0)


def _transform_cells(i, j, q, t):
    """Unit squares with min corner ``(i, j)`` under ``w -> i^q w + t``: their min corners."""
    c = np.stack([i + 1j * j, (i + 1) + 1j * (j + 1)], 1) * (1j**q)[:, None] + t[:, None]
    re = np.rint(c.real).astype(np.int64)
    im = np.rint(c.imag).astype(np.int64)
    return re.min(1), im.min(1)


def extract_quads(verts, faces, uv, matching, topo: Topology | None = None) -> QuadExtraction:
    """The quad mesh of the integer-grid map ``uv`` (module docstring).

    Parameters
    ----------
    verts : (V, 3) array or tensor
    faces : (F, 3) int array or tensor
    uv : (F, 3, 2) per-corner ``(u, v)``; transitions across every interior edge
        ``w_g = i^{-k_e} w_f + t_e`` with integer ``t_e``; no flipped or degenerate triangle
    matching : (E,) int, ``k_e`` (in the edge order of ``Topology(faces)``)

    Returns
    -------
    :class:`QuadExtraction`

    Raises
    ------
    ValueError
        When ``uv`` is not a valid integer-grid map (see the module docstring).
    """
    verts = np.asarray(verts, dtype=np.float64)
    fl = np.asarray(faces, dtype=np.int64)
    uv = np.asarray(uv, dtype=np.float64)
    topo = Topology(fl, verts.shape[0]) if topo is None else topo
    matching = np.asarray(matching, dtype=np.int64)
    area2 = _orient(uv[:, 0], uv[:, 1], uv[:, 2])
    if np.any(area2 <= 0):
        bad = np.flatnonzero(area2 <= 0)
        raise ValueError(
            f"the map flips or collapses {bad.size} triangles (e.g. faces {bad[:10].tolist()}): "
            "no quad mesh can be extracted"
        )

    # 1. pieces
    lo, hi = _cell_range(uv)
    row, ci, cj = _expand_cells(lo, hi)
    meets = _triangle_meets_cell(uv[row], ci, cj)
    pf, pi, pj = row[meets], ci[meets], cj[meets]
    npc = pf.size
    off = np.array([pi.min(initial=0), pj.min(initial=0)])
    span = np.array([pi.max(initial=0), pj.max(initial=0)]) - off + 1

    def key_of(f, i, j):
        return (f * span[0] + (i - off[0])) * span[1] + (j - off[1])

    pkey = key_of(pf, pi, pj)
    order = np.argsort(pkey)
    pkey_sorted = pkey[order]

    def lookup(f, i, j):
        inside = (i >= off[0]) & (i < off[0] + span[0]) & (j >= off[1]) & (j < off[1] + span[1])
        k = np.where(inside, key_of(f, i, j), -1)
        pos = np.minimum(np.searchsorted(pkey_sorted, k), max(npc - 1, 0))
        found = inside & (pkey_sorted[pos] == k) if npc else np.zeros(k.shape, bool)
        return np.where(found, order[pos], -1)

    # 2. flooding across interior edges
    ef, ec = topo.edge_faces.numpy(), topo.edge_corners.numpy()
    e = np.flatnonzero((ef >= 0).all(1))
    f, g, kf, kg = ef[e, 0], ef[e, 1], ec[e, 0], ec[e, 1]
    a, b = uv[f, (kf + 1) % 3], uv[f, (kf + 2) % 3]
    q = (-matching[e]) % 4
    ag = uv[g, (kg + 2) % 3]  # the same vertex as a, in g's chart
    t = (ag[:, 0] + 1j * ag[:, 1]) - (1j**q) * (a[:, 0] + 1j * a[:, 1])
    if np.abs(t - (np.rint(t.real) + 1j * np.rint(t.imag))).max(initial=0) > 1e-6:
        raise ValueError("the map's transitions are not integer translations: not an integer-grid map")
    t = np.rint(t.real) + 1j * np.rint(t.imag)
    seg = np.stack([a, b], 1)
    slo, shi = _cell_range(seg)
    srow, si, sj = _expand_cells(slo, shi)
    cross = _segment_crosses_cell(a[srow], b[srow], si, sj)
    srow, si, sj = srow[cross], si[cross], sj[cross]
    gi, gj = _transform_cells(si, sj, q[srow], t[srow])
    p1 = lookup(f[srow], si, sj)
    p2 = lookup(g[srow], gi, gj)
    if np.any(p1 < 0) or np.any(p2 < 0):
        bad = e[srow[(p1 < 0) | (p2 < 0)]]
        raise ValueError(
            f"the integer grid does not continue across edges {np.unique(bad)[:10].tolist()}: "
            "the map is not locally injective there"
        )
    qq = q[srow]
    label, rot = _flood(npc, p1, p2, qq)
    ncomp = int(label.max()) + 1 if npc else 0
    if np.any((rot[p2] - rot[p1] - qq) % 4 != 0):
        raise ValueError("the quarter turns of the map do not close around a quad: not an integer-grid map")

    # 3. corners: every square corner in the closed triangle of one of the square's pieces
    fe = topo.face_edges.numpy()
    rows_n, rows_c, rows_o = [], [], []
    tri = uv[pf]
    for c in range(4):
        qp = np.stack([pi + _CORNERS[c, 0], pj + _CORNERS[c, 1]], -1).astype(np.float64)
        o = np.stack([_orient(tri[:, k], tri[:, (k + 1) % 3], qp) for k in range(3)], 1)  # (n, 3)
        idx = np.flatnonzero((o >= 0).all(1))
        rows_n.append(idx)
        rows_c.append(np.full(idx.size, c))
        rows_o.append(o[idx])
    n_ = np.concatenate(rows_n)
    c_ = np.concatenate(rows_c)
    o_ = np.concatenate(rows_o)
    face = pf[n_]
    px, py = pi[n_] + _CORNERS[c_, 0], pj[n_] + _CORNERS[c_, 1]
    t3 = uv[face]
    same = (t3[:, :, 0] == px[:, None]) & (t3[:, :, 1] == py[:, None])  # at a mesh vertex
    on_edge = (o_ == 0) & ~same.any(1)[:, None]
    bary = o_[:, [1, 2, 0]] / area2[face][:, None]  # corner k: twice the area opposite it
    kind = np.where(same.any(1), 0, np.where(on_edge.any(1), 1, 2))
    # canonical keys (kind, element, x, y): a vertex; an edge and the point in the chart of
    # the edge's slot-0 face; a face and the point
    key = np.zeros((n_.size, 4), dtype=np.int64)
    key[:, 0] = kind
    at = np.argmax(same, 1)
    v_rows = kind == 0
    key[v_rows, 1] = fl[face[v_rows], at[v_rows]]
    bary[v_rows] = np.eye(3)[at[v_rows]]
    e_rows = np.flatnonzero(kind == 1)
    k_on = np.argmax(on_edge[e_rows], 1)  # on the edge (k, k+1), opposite corner k+2
    edge = fe[face[e_rows], (k_on + 2) % 3]
    ex_, ey_ = _slot0_chart(edge, face[e_rows], px[e_rows], py[e_rows], ef, ec, uv, matching)
    key[e_rows, 1], key[e_rows, 2], key[e_rows, 3] = edge, ex_, ey_
    f_rows = kind == 2
    key[f_rows, 1], key[f_rows, 2], key[f_rows, 3] = face[f_rows], px[f_rows], py[f_rows]
    _, first, kid = np.unique(key, axis=0, return_index=True, return_inverse=True)
    kid = kid.ravel()
    quad = label[n_]
    ref = (c_ - rot[n_]) % 4
    corner_of = np.full((ncomp, 4), -1, dtype=np.int64)
    corner_of[quad, ref] = kid
    clash = np.zeros(ncomp, dtype=bool)
    clash[quad[corner_of[quad, ref] != kid]] = True
    vertex_of = np.where(kind[first] == 0, key[first, 1], -1)
    fface, fbary = face[first], bary[first]
    broken = clash | (corner_of < 0).any(1)
    if broken.any():
        where = np.unique(pf[np.isin(label, np.flatnonzero(broken))])
        raise ValueError(
            f"{int(broken.sum())} quads of the map have a missing or doubled corner (in faces "
            f"{where[:10].tolist()}): the map is not locally injective there, or a cone is not at "
            "an integer point"
        )
    if np.any(np.sort(corner_of, 1)[:, 1:] == np.sort(corner_of, 1)[:, :-1]):
        raise ValueError("a quad of the map has two equal corners (a degenerate quad)")
    pts = (fbary[:, :, None] * verts[fl[fface]]).sum(1)
    return QuadExtraction(pts, corner_of, fface, fbary, vertex_of)


def _flood(n: int, p1: np.ndarray, p2: np.ndarray, q: np.ndarray):
    """Components of the graph of pieces, and each piece's quarter turn ``rot`` relative to
    its component's first piece, for links ``chart(p2) = i^q chart(p1) + t``."""
    src = np.concatenate([p1, p2])
    dst = np.concatenate([p2, p1])
    turn = np.concatenate([q, -q]) % 4
    order = np.argsort(src, kind="stable")
    src, dst, turn = src[order], dst[order], turn[order]
    start = np.searchsorted(src, np.arange(n + 1))
    dst_l, turn_l, start_l = dst.tolist(), turn.tolist(), start.tolist()
    label = [-1] * n
    rot = [0] * n
    comp = 0
    for root in range(n):
        if label[root] >= 0:
            continue
        label[root] = comp
        stack = [root]
        while stack:
            a = stack.pop()
            for k in range(start_l[a], start_l[a + 1]):
                b = dst_l[k]
                if label[b] < 0:
                    label[b] = comp
                    rot[b] = (rot[a] + turn_l[k]) % 4
                    stack.append(b)
        comp += 1
    return np.array(label, dtype=np.int64), np.array(rot, dtype=np.int64)


def _slot0_chart(edge, face, px, py, ef, ec, uv, matching):
    """Integer points ``(px, py)`` of ``face``'s chart on ``edge``, in the chart of the
    edge's slot-0 face (so that both faces name them alike)."""
    x, y = px.astype(np.int64).copy(), py.astype(np.int64).copy()
    f0, f1 = ef[edge, 0], ef[edge, 1]
    other = (face != f0) & (f1 >= 0)
    if not other.any():
        return x, y
    e, g, h = edge[other], f0[other], f1[other]
    # w_g = i^q w_f + t  =>  w_f = i^{-q} (w_g - t), q = -k
    q = (-matching[e]) % 4
    a = uv[g, (ec[e, 0] + 1) % 3]
    ag = uv[h, (ec[e, 1] + 2) % 3]
    t = (ag[:, 0] + 1j * ag[:, 1]) - (1j**q) * (a[:, 0] + 1j * a[:, 1])
    w = ((px[other] + 1j * py[other]) - t) * (1j ** (-q))
    x[other], y[other] = np.rint(w.real).astype(np.int64), np.rint(w.imag).astype(np.int64)
    return x, y
