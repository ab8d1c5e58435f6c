"""The cut mesh of an integer-grid map and its unknowns (see :mod:`torch_edgevf.quad.igm`).

The corners glued across interior uncut edges form the *wedges* (vertices of the cut mesh).
Every vertex has one *master* wedge; walking around the vertex across its cut edges, every
other wedge is ``i^r M_v + sum_e c_e t_e`` (``t_e`` the translation of cut edge ``e``,
Gaussian-integer ``c_e``). Where a walk closes it gives a relation: inside a seam,
``t_e2 = unit * t_e1`` (merged: one translation per *arc*); at a branch point or a cone a
*closure* ``(i^a - i^b) M_v + sum_a c_a t_a = 0`` kept as a linear constraint.

:func:`build_unknowns` writes the wedge values as ``W = P x + Q y`` (real, rows
``[u (wedges); v (wedges)]``) with ``x`` the free real coordinates of the masters and ``y``
the integer ones (both coordinates of the cones and pinned vertices, and the real and
imaginary parts of the arc translations), and the closures as ``K [y; 1] = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csg

from ..mesh.topology import Topology

__all__ = ["Unknowns", "build_unknowns", "wedges"]

_UNITS = np.array([1, 1j, -1, -1j])


def wedges(topo: Topology, cut: np.ndarray) -> tuple[np.ndarray, int]:
    """(F, 3) wedge id of every corner: corners glued across interior uncut edges."""
    fl = topo.faces.numpy()
    nf = fl.shape[0]
    ef, ec = topo.edge_faces.numpy(), topo.edge_corners.numpy()
    interior = (ef >= 0).all(1)
    glue = np.flatnonzero(interior & ~cut)
    f0, f1, k0, k1 = ef[glue, 0], ef[glue, 1], ec[glue, 0], ec[glue, 1]
    # in slot 0 the edge runs lo -> hi from corner k0+1 to k0+2; in slot 1 from k1+2 to k1+1
    a = np.concatenate([3 * f0 + (k0 + 1) % 3, 3 * f0 + (k0 + 2) % 3])
    b = np.concatenate([3 * f1 + (k1 + 2) % 3, 3 * f1 + (k1 + 1) % 3])
    n, lab = csg.connected_components(sp.coo_matrix((np.ones(a.size), (a, b)), shape=(3 * nf, 3 * nf)))
    return lab.reshape(nf, 3), int(n)


def _crossings(topo: Topology, cut: np.ndarray, wedge: np.ndarray):
    """Both ends of every cut edge: wedge ``A`` (slot-0 face), ``B`` (slot-1 face), the edge.

    ``W_B = i^{-k_e} W_A + t_e`` at both ends.
    """
    ef, ec = topo.edge_faces.numpy(), topo.edge_corners.numpy()
    ce = np.flatnonzero(cut)
    f, g, kf, kg = ef[ce, 0], ef[ce, 1], ec[ce, 0], ec[ce, 1]
    a = np.concatenate([wedge[f, (kf + 1) % 3], wedge[f, (kf + 2) % 3]])
    b = np.concatenate([wedge[g, (kg + 2) % 3], wedge[g, (kg + 1) % 3]])
    return a, b, np.concatenate([ce, ce])


def _is_unit(c: complex) -> int:
    """The exponent ``q`` with ``c = i^q``, or -1."""
    for q in range(4):
        if abs(c - _UNITS[q]) < 1e-9:
            return q
    return -1


class _UnitUnionFind:
    """Union-find over cut edges with ``t_e = i^{m_e} t_root``."""

    def __init__(self, n: int):
        self.parent = list(range(n))
        self.mult = [0] * n

    def find(self, e: int) -> tuple[int, int]:
        path = []
        while self.parent[e] != e:
            path.append(e)
            e = self.parent[e]
        root, acc = e, 0
        for x in reversed(path):  # compress: mult relative to the root
            acc = (acc + self.mult[x]) % 4
            self.mult[x] = acc
            self.parent[x] = root
        return root, (self.mult[path[0]] if path else 0)

    def union(self, e1: int, e2: int, q: int) -> bool:
        """Record ``t_e2 = i^q t_e1``; False if it contradicts what is known (then no merge)."""
        r1, m1 = self.find(e1)
        r2, m2 = self.find(e2)
        if r1 == r2:
            return (m2 - m1 - q) % 4 == 0
        # t_r2 = i^{-m2} t_e2 = i^{q + m1 - m2} t_r1
        self.parent[r2] = r1
        self.mult[r2] = (q + m1 - m2) % 4
        return True


def _walks(ncls, wedge_vertex, cross_a, cross_b, cross_e, matching):
    """Express every wedge through its vertex's master; collect the closures.

    Returns ``master`` (V,) wedge id (-1 for unused vertices), ``rho`` (ncls,) quarter turns,
    ``tau`` list of dicts ``{edge: Gaussian-integer coefficient}`` (None for masters), and
    ``closures`` as ``(vertex, c_M, {edge: coefficient})``: ``c_M M_v + sum c t_e = 0``.
    """
    nv = int(wedge_vertex.max()) + 1 if ncls else 0
    master = np.full(nv, -1, dtype=np.int64)
    order = np.argsort(wedge_vertex, kind="stable")
    first = np.ones(ncls, dtype=bool)
    first[1:] = wedge_vertex[order[1:]] != wedge_vertex[order[:-1]]
    master[wedge_vertex[order[first]]] = order[first]
    rho = np.zeros(ncls, dtype=np.int64)
    tau: list = [None] * ncls
    adj: dict[int, list[int]] = {}
    for c in range(cross_a.size):
        adj.setdefault(int(cross_a[c]), []).append(c)
        if cross_b[c] != cross_a[c]:
            adj.setdefault(int(cross_b[c]), []).append(c)
    q_of = (-matching[cross_e]) % 4
    closures = []
    used = np.zeros(cross_a.size, dtype=bool)
    starts = {int(master[wedge_vertex[w]]) for w in adj}
    for m in sorted(starts):
        tau[m] = {}
        stack = [m]
        seen = {m}
        while stack:
            w = stack.pop()
            for c in adj[w]:
                if used[c]:
                    continue
                a, b, e, q = int(cross_a[c]), int(cross_b[c]), int(cross_e[c]), int(q_of[c])
                other = b if a == w else a
                if other in seen:
                    used[c] = True
                    # W_B - i^q W_A - t_e = 0
                    cm = _UNITS[rho[b] % 4] - _UNITS[(q + rho[a]) % 4]
                    rel = dict(tau[b])
                    for x, cx in tau[a].items():
                        rel[x] = rel.get(x, 0) - _UNITS[q] * cx
                    rel[e] = rel.get(e, 0) - 1
                    closures.append(
                        (int(wedge_vertex[m]), cm, {x: v for x, v in rel.items() if abs(v) > 1e-9})
                    )
                    continue
                used[c] = True
                if a == w:  # W_B = i^q W_A + t_e
                    rho[b] = (rho[a] + q) % 4
                    nt = {x: _UNITS[q] * cx for x, cx in tau[a].items()}
                    nt[e] = nt.get(e, 0) + 1
                    tau[b] = nt
                else:  # W_A = i^{-q} (W_B - t_e)
                    rho[a] = (rho[b] - q) % 4
                    nt = {x: _UNITS[-q % 4] * cx for x, cx in tau[b].items()}
                    nt[e] = nt.get(e, 0) - _UNITS[-q % 4]
                    tau[a] = nt
                seen.add(other)
                stack.append(other)
    return master, rho, tau, closures


@dataclass
class Unknowns:
    """The wedge values of a cut mesh as ``W = P x + Q y`` and the closures ``K [y; 1] = 0``.

    Attributes
    ----------
    wedge : (F, 3) wedge of every corner; ``ncls`` wedges
    wedge_vertex : (ncls,) vertex of every wedge
    P : (2 ncls, nx) sparse; Q : (2 ncls, ny) sparse
    K : (r, ny + 1) float, integer entries; the last column multiplies the constant 1
    kind : (ny,) int, 0 for an integer coordinate of a vertex, 1 for an arc translation
    pinned : (ny,) bool, fixed to 0 (one vertex per component: the translation gauge)
    vertex_y : (V, 2) int, the ``y`` column of each master coordinate (-1: a free one, in ``x``)
    num_arcs : int
    rho : (ncls,) int, quarter turns of every wedge's chart relative to its vertex's master
    vertex_x : (V, 2) int, the ``x`` column of each free master coordinate (-1: an integer one)
    """

    wedge: np.ndarray
    ncls: int
    wedge_vertex: np.ndarray
    P: sp.csr_matrix
    Q: sp.csr_matrix
    K: np.ndarray
    kind: np.ndarray
    pinned: np.ndarray
    vertex_y: np.ndarray
    num_arcs: int
    rho: np.ndarray
    vertex_x: np.ndarray


def _rot(q: int) -> np.ndarray:
    c = _UNITS[q % 4]
    return np.array([[c.real, -c.imag], [c.imag, c.real]])


def build_unknowns(
    topo: Topology,
    cut: np.ndarray,
    matching: np.ndarray,
    integer_vertex: np.ndarray,
    pinned_vertices,
    boundary=None,
) -> Unknowns:
    """The unknowns of the map on the mesh cut along ``cut`` (module docstring).

    ``integer_vertex`` (V,) bool marks the vertices at integer points (cones, boundary
    corners); one vertex of ``pinned_vertices`` per component is fixed at the origin and must
    be in ``integer_vertex``. ``boundary``, optional ``(faces, corners_a, corners_b, axis)``:
    the boundary edges, each from corner ``a`` to corner ``b`` of its face, to lie on an
    iso-line: coordinate ``axis`` (0 ``u``, 1 ``v``) of the face's chart constant and
    integer. Their vertices get that coordinate of their master as an integer unknown, and
    each edge a constraint row.
    """
    wedge, ncls = wedges(topo, cut)
    fl = topo.faces.numpy()
    nv = topo.num_vertices
    wedge_vertex = np.zeros(ncls, dtype=np.int64)
    wedge_vertex[wedge.ravel()] = fl.ravel()
    ca, cb, ce = _crossings(topo, cut, wedge)
    master, rho, tau, closures = _walks(ncls, wedge_vertex, ca, cb, ce, matching)

    cut_ids = np.flatnonzero(cut)
    local = np.full(topo.num_edges, -1, dtype=np.int64)
    local[cut_ids] = np.arange(cut_ids.size)
    uf = _UnitUnionFind(cut_ids.size)
    rows = []
    for v, cm, rel in closures:
        if abs(cm) < 1e-9 and len(rel) == 2:
            (e1, c1), (e2, c2) = rel.items()
            if _is_unit(c1) >= 0 and _is_unit(c2) >= 0:
                if uf.union(int(local[e1]), int(local[e2]), _is_unit(-c1 / c2)):
                    continue
        rows.append((v, cm, rel))
    found = [uf.find(i) for i in range(cut_ids.size)]
    roots = np.array([r for r, _ in found], dtype=np.int64)
    mults = np.array([m for _, m in found], dtype=np.int64)
    _, arc_of = np.unique(roots, return_inverse=True)
    n_arcs = int(arc_of.max()) + 1 if cut_ids.size else 0

    # which master coordinates are integer unknowns
    int_coord = np.zeros((nv, 2), dtype=bool)
    int_coord[integer_vertex] = True
    if boundary is not None:
        bf, bka, bkb, baxis = boundary
        for k in (bka, bkb):
            w = wedge[bf, k]
            int_coord[fl[bf, k], np.where(rho[w] % 2 == 0, baxis, 1 - baxis)] = True
    n_int = int(int_coord.sum())
    vertex_y = np.full((nv, 2), -1, dtype=np.int64)
    vertex_y[int_coord] = np.arange(n_int)
    ny = n_int + 2 * n_arcs
    kind = np.concatenate([np.zeros(n_int, dtype=np.int64), np.ones(2 * n_arcs, dtype=np.int64)])
    pinned = np.zeros(ny, dtype=bool)
    for v in pinned_vertices:
        if not integer_vertex[v]:
            raise ValueError(f"pinned vertex {v} must be an integer vertex")
        pinned[vertex_y[v]] = True
    free_coord = (master >= 0)[:, None] & ~int_coord
    vertex_x = np.full((nv, 2), -1, dtype=np.int64)
    vertex_x[free_coord] = np.arange(int(free_coord.sum()))
    nx = int(free_coord.sum())
    arc0 = n_int

    def arc_terms(rel):
        out: dict[int, complex] = {}
        for e, c in rel.items():
            i = int(local[e])
            j = int(arc_of[i])
            out[j] = out.get(j, 0) + c * _UNITS[mults[i]]
        return out

    # master part: W_w = R(rho_w) M_v, column j of R times coordinate j of the master
    w_all = np.arange(ncls)
    v_all = wedge_vertex
    cos = np.rint(np.cos(rho * np.pi / 2))
    sin = np.rint(np.sin(rho * np.pi / 2))
    pr: list[np.ndarray] = []
    pc: list[np.ndarray] = []
    pv: list[np.ndarray] = []
    qr: list[np.ndarray] = []
    qc: list[np.ndarray] = []
    qv: list[np.ndarray] = []
    for j, (top, bottom) in enumerate(((cos, sin), (-sin, cos))):
        is_int = int_coord[v_all, j]
        for mask, rr, cc, vv, cols in (
            (is_int, qr, qc, qv, vertex_y[v_all, j]),
            (~is_int, pr, pc, pv, vertex_x[v_all, j]),
        ):
            w = w_all[mask]
            rr += [w, ncls + w]
            cc += [cols[mask], cols[mask]]
            vv += [top[mask], bottom[mask]]
    for w in np.flatnonzero([bool(t) for t in tau]).tolist():
        for a, c in arc_terms(tau[w]).items():
            col = arc0 + 2 * a
            qr.append(np.array([w, w, ncls + w, ncls + w]))
            qc.append(np.array([col, col + 1, col, col + 1]))
            qv.append(np.array([c.real, -c.imag, c.imag, c.real]))
    P = sp.csr_matrix((np.concatenate(pv), (np.concatenate(pr), np.concatenate(pc))), shape=(2 * ncls, nx))
    Q = sp.csr_matrix((np.concatenate(qv), (np.concatenate(qr), np.concatenate(qc))), shape=(2 * ncls, ny))

    K = np.zeros((2 * len(rows), ny + 1))
    for r, (v, cm, rel) in enumerate(rows):
        if abs(cm) > 1e-9:
            if not integer_vertex[v]:
                raise RuntimeError(f"vertex {v} has holonomy but no integer unknown")
            M = np.array([[cm.real, -cm.imag], [cm.imag, cm.real]])
            K[2 * r : 2 * r + 2, vertex_y[v]] += M
        for a, c in arc_terms(rel).items():
            col = arc0 + 2 * a
            K[2 * r : 2 * r + 2, col : col + 2] += np.array([[c.real, -c.imag], [c.imag, c.real]])
    if boundary is not None and len(bf):
        # coordinate ``axis`` of both ends equal, in the chart of the edge's face
        wa, wb = wedge[bf, bka], wedge[bf, bkb]
        rows_a = Q[baxis * ncls + wa].toarray()
        rows_b = Q[baxis * ncls + wb].toarray()
        K = np.vstack([K, np.column_stack([rows_a - rows_b, np.zeros(len(bf))])])
    K = np.rint(K)
    return Unknowns(wedge, ncls, wedge_vertex, P, Q, K, kind, pinned, vertex_y, n_arcs, rho, vertex_x)
