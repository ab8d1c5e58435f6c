"""Integer-grid maps from cross fields (thesis chapter 4, after [BZK09] "Mixed-Integer Quadrangulation").

An *integer-grid map* is a per-corner ``(u, v)`` map of a triangle mesh, cut open into a disk,
whose transitions across the cut are ``w_g = i^{-k} w_f + t`` (``w = u + i v``, ``k`` a quarter
turn, ``t`` an *integer* translation) and whose cones (the singular vertices of the cross
field) lie at integer points. The integer iso-lines of such a map, if no triangle is flipped,
form a pure quad mesh whose irregular vertices are the cones (:mod:`torch_edgevf.quad.extract`).

Steps (:func:`integer_grid_map`):

1. face singularities become vertices (1-to-3 split at their exact location, thesis 4.1, B.2);
   the *cones* are the vertices of non-zero index;
2. a dual spanning tree combs the field into one direction ``U_f`` per face; the primal edges
   the tree does not cross, pruned of dangling branches that end at regular vertices, form
   the cut graph, which joins the cones and the homology generators (and the boundary);
3. *unknowns, with every transition eliminated.* The corners glued across uncut edges form
   the *wedges* (vertices of the cut mesh). Each vertex has one *master* wedge ``M_v``; walking
   around the vertex across its cut edges, every other wedge is ``i^r M_v + sum_e c_e t_e``
   with Gaussian-integer ``c_e``. Where the walk closes it gives a relation: at a vertex inside
   a seam, ``t_e2 = unit * t_e1`` (one translation per *arc*, a maximal seam); at a branch point
   or a cone, a *closure* ``(1 - i^r) M_v + sum c_a t_a = 0`` over the arc translations.
   The closures are solved for some of the integer unknowns (cone masters and arc
   translations) by Gaussian elimination over the Gaussian integers, choosing unit pivots
   first, so every solution is ``y = B y_ind`` with integer ``B`` where the closures allow;
4. the energy ``int |grad u - s U|^2 + |grad v - s V|^2`` (``s`` the target quads per unit
   length) is a quadratic in the free masters ``x`` and the integers ``y_ind``. ``x`` is
   eliminated by one sparse factorization (a Schur complement), leaving a small dense
   problem in ``y_ind``;
5. *greedy rounding with re-solves* [BZK09]: the cone positions first, then the arc
   translations, each time the unknown closest to an integer is fixed and the rest re-solved;
   the dependent integers follow and are checked to be integers; where the rounding puts
   close cones or corners at one point, a cone on a boundary line, or the tips of a slit (a
   hole of one triangle, mapped to a slit) less than two units apart, it is re-run with
   those held apart;
6. the free masters are solved with the integers fixed; flipped triangles, if any, are
   removed by local stiffening [BZK09] (re-solves with the distorted triangles' weights
   raised), then if needed by a few iterations of a foldover-free energy ([GKK+21] "Foldover-free maps in
   50 lines of code", :mod:`torch_edgevf.quad.untangle`), the integers staying fixed.

Not differentiable (combinatorial and integer).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import torch
from threadpoolctl import threadpool_limits

from .._validation import as_edge_field
from ..fields.param import CutGraph, comb, dual_tree, face_plane, prune_cut
from ..fields.singularities import singularities, split_singular_faces
from ..mesh.geometry import topology_and_verts
from ..mesh.topology import Topology
from .cones import boundary_axes, cancel_dipoles, combed_field, split_cones
from .rounding import Reduced, eliminate, greedy_round
from .seams import Unknowns, build_unknowns

__all__ = ["IntegerGridMap", "integer_grid_map", "transitions"]

log = logging.getLogger(__name__)

_UNITS = np.array([1, 1j, -1, -1j])
_GRID = 2.0**30


@dataclass
class IntegerGridMap:
    """Result of :func:`integer_grid_map`.

    Attributes
    ----------
    verts, faces : the mesh the map lives on: the input with singular faces split, in the
        dtype of the input vertices (float32 or float64; computed in float64)
    uv : (F, 3, 2) tensor in that dtype, ``(u, v)`` per corner (integers exact in both)
    cones : (C,) int64, the vertices of non-zero index (each at an integer ``(u, v)``)
    cone_index : (C,) tensor in that dtype, their indices (``+-1/4`` for the usual cones)
    cut_edges : (E,) bool
    matching : (E,) int64 ``k_e``: ``w_g = i^{-k} w_f + t_e`` for ``f, g = edge_faces[e]``
    translations : (E, 2) int64 ``t_e`` (zero off the cut)
    scale : the target gradient norm ``s`` (quads per unit length)
    flipped : number of triangles with negative or zero ``uv`` area, or around a vertex whose
        ``uv`` angles do not add up to ``2 pi (1 - I)``, after the fix
    flipped_before_fix : the same before the foldover-free iterations
    energy : ``int |grad u - s U|^2 + |grad v - s V|^2`` of the final map
    relaxed_energy : the same before rounding (the seamless, non-integer optimum)
    num_split : number of face singularities moved to new vertices
    num_field_cones : the field's cones, before those of index ``+1/2`` or more were split
        into ``+1/4`` cones (:func:`torch_edgevf.quad.cones.split_cones`) and close pairs of
        opposite index cancelled (``dipoles``)
    boundary_turns : (V,) int64, quarter turns of the map at each boundary vertex (0 inside):
        the number of quads there; 1 or 3 at the corners, which are at integer points
    """

    verts: torch.Tensor
    faces: torch.Tensor
    uv: torch.Tensor
    cones: torch.Tensor
    cone_index: torch.Tensor
    cut_edges: torch.Tensor
    matching: torch.Tensor
    translations: torch.Tensor
    scale: float
    flipped: int
    flipped_before_fix: int
    energy: float
    relaxed_energy: float
    num_split: int
    num_field_cones: int
    boundary_turns: torch.Tensor


# --------------------------------------------------------------------------- the map


def transitions(topo: Topology, uv: np.ndarray, matching: np.ndarray) -> np.ndarray:
    """(E, 2) translations ``t_e = w_g - i^{-k} w_f`` measured at the lower end of every
    interior edge (0 on boundary edges), as floats."""
    ef, ec = topo.edge_faces.numpy(), topo.edge_corners.numpy()
    t = np.zeros((topo.num_edges, 2))
    e = np.flatnonzero((ef >= 0).all(1))
    f, g, kf, kg = ef[e, 0], ef[e, 1], ec[e, 0], ec[e, 1]
    wf = uv[f, (kf + 1) % 3, 0] + 1j * uv[f, (kf + 1) % 3, 1]
    wg = uv[g, (kg + 2) % 3, 0] + 1j * uv[g, (kg + 2) % 3, 1]
    d = wg - _UNITS[(-matching[e]) % 4] * wf
    t[e, 0], t[e, 1] = d.real, d.imag
    return t


def _energy_system(
    verts: np.ndarray, fl: np.ndarray, wedge: np.ndarray, ncls: int, angle: np.ndarray, s: float
):
    """Least-squares rows ``A [u; v] ~ rhs`` of ``sum_f area |grad u - s U|^2 + |grad v - s V|^2``
    (normalised by the total area), on the wedge unknowns ``[u (ncls), v (ncls)]``."""
    nf = fl.shape[0]
    d0 = verts[fl[:, 2]] - verts[fl[:, 1]]
    d0 = d0 / np.linalg.norm(d0, axis=1, keepdims=True)
    P = face_plane(verts, fl, d0)
    area = 0.5 * np.abs(P[:, 1, 0] * P[:, 2, 1] - P[:, 1, 1] * P[:, 2, 0])
    e = P[:, [2, 0, 1]] - P[:, [1, 2, 0]]
    grad = np.stack([-e[..., 1], e[..., 0]], -1) / (2 * area[:, None, None])
    U = s * np.stack([np.cos(angle), np.sin(angle)], -1)
    V = np.stack([-U[:, 1], U[:, 0]], -1)
    w = np.sqrt(area / area.sum())
    rows = np.broadcast_to(np.arange(2 * nf).reshape(nf, 2, 1), (nf, 2, 3))
    cols = np.broadcast_to(wedge[:, None, :], (nf, 2, 3))
    vals = w[:, None, None] * np.transpose(grad, (0, 2, 1))
    Bm = sp.csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(2 * nf, ncls))
    A = sp.block_diag([Bm, Bm]).tocsr()
    rhs = np.concatenate([(w[:, None] * U).ravel(), (w[:, None] * V).ravel()])
    return A, rhs, area


def _distortion(uv: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(F,) ``|sigma_1 - 1| + |sigma_2 - 1|`` of each triangle's Jacobian relative to its
    target shape, with the smaller singular value negative for a flipped triangle."""
    D = np.stack([uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]], -1)
    R = np.stack([target[:, 1] - target[:, 0], target[:, 2] - target[:, 0]], -1)
    J = D @ np.linalg.inv(R)
    e, f = (J[:, 0, 0] + J[:, 1, 1]) / 2, (J[:, 0, 0] - J[:, 1, 1]) / 2
    g, h = (J[:, 1, 0] + J[:, 0, 1]) / 2, (J[:, 1, 0] - J[:, 0, 1]) / 2
    q, r = np.hypot(e, h), np.hypot(f, g)
    return np.abs(q + r - 1) + np.abs(q - r - 1)


def _stiffen(A, rhs, P, Q, y, x, corners, target, fl, expected, iterations: int = 20):
    """Local stiffening [BZK09]: re-solve the free unknowns with the integers fixed, each
    triangle's weight multiplied by ``1 + distortion`` at every round, so that the stiffened
    triangles around a displaced cone follow it; stops when the map is locally injective."""
    import scipy.sparse.linalg as sla

    nf = fl.shape[0]
    weight = np.ones(nf)
    Qy = Q @ y
    best, best_bad = x, None
    for _ in range(iterations + 1):
        uv = corners(P @ x + Qy)
        bad = _bad_faces(uv, fl, expected)
        if best_bad is None or bad < best_bad:
            best, best_bad = x, bad
        if bad == 0:
            break
        weight *= 1 + 4 * np.minimum(_distortion(uv, target), 10.0)
        sw = np.sqrt(np.repeat(weight, 2))
        Sw = sp.diags(np.concatenate([sw, sw]))
        Aw = (Sw @ A).tocsr()
        AP = (Aw @ P).tocsc()
        x = sla.spsolve((AP.T @ AP).tocsc(), AP.T @ (Sw @ rhs - Aw @ Qy))
    return best


def _wound_vertices(uv: np.ndarray, fl: np.ndarray, expected: np.ndarray) -> np.ndarray:
    total = np.zeros(expected.shape[0])
    for k in range(3):
        e1, e2 = uv[:, (k + 1) % 3] - uv[:, k], uv[:, (k + 2) % 3] - uv[:, k]
        np.add.at(total, fl[:, k], np.arctan2(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0], (e1 * e2).sum(1)))
    return np.flatnonzero(np.abs(total - expected * math.pi / 2) > 1e-6)


def _target_shapes(verts: np.ndarray, fl: np.ndarray, angle: np.ndarray, s: float) -> np.ndarray:
    """(F, 3, 2) corners of the ideal map ``(u, v) = s (<x, U>, <x, V>)`` of every triangle."""
    d0 = verts[fl[:, 2]] - verts[fl[:, 1]]
    d0 = d0 / np.linalg.norm(d0, axis=1, keepdims=True)
    P = face_plane(verts, fl, d0)
    c, sn = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return s * np.stack([c * P[..., 0] + sn * P[..., 1], -sn * P[..., 0] + c * P[..., 1]], -1)


def _frame_angles_in_plane(verts, topo, angle):
    """``angle`` is measured in the frame of edge 0 *with its orientation sign*; the energy
    system uses the unsigned direction corner 1 -> corner 2: add ``pi`` where the sign is -1."""
    sign = topo.face_edge_signs.numpy()[:, 0]
    return angle + np.where(sign < 0, math.pi, 0.0)


def _bad_faces(uv: np.ndarray, fl: np.ndarray, quarter_turns: np.ndarray) -> int:
    """Number of triangles that keep the map from being locally injective: flipped or
    collapsed ones (``uv`` area <= 0), and those around a vertex whose ``uv`` angles do not add
    up to ``quarter_turns * pi / 2`` (a star wound the wrong number of times, possible with
    every triangle positive)."""
    a, b = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    bad = (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]) <= 0
    wound = np.zeros(quarter_turns.shape[0], dtype=bool)
    wound[_wound_vertices(uv, fl, quarter_turns)] = True
    bad |= wound[fl].any(1)
    return int(bad.sum())


def _cone_paths(fl: np.ndarray, cone: np.ndarray):
    """Pairs of cones at most two edges apart, each with a path ``(a, f1, c, f2, b)``: faces
    ``f1`` holding ``a`` and ``c`` and ``f2`` holding ``c`` and ``b`` (``c = b``, ``f2 = f1``
    for an edge)."""
    paths: dict = {}
    nv = int(fl.max()) + 1
    corner: dict = {}
    for f in range(fl.shape[0]):
        for k in range(3):
            corner.setdefault(int(fl[f, k]), []).append(f)
    nbr: dict[int, dict[int, int]] = {}  # vertex -> neighbour -> a face holding both
    for f in range(fl.shape[0]):
        for k in range(3):
            x, y = int(fl[f, k]), int(fl[f, (k + 1) % 3])
            nbr.setdefault(x, {}).setdefault(y, f)
            nbr.setdefault(y, {}).setdefault(x, f)
    del corner, nv
    for a in np.flatnonzero(cone).tolist():
        for c, f1 in nbr.get(a, {}).items():
            if cone[c] and c > a:
                paths.setdefault((a, c), (a, f1, c, f1, c))
            if cone[c]:
                continue
            for b, f2 in nbr[c].items():
                if b > a and cone[b]:
                    paths.setdefault((a, b), (a, f1, c, f2, b))
    return list(paths.values())


def _rot(q: int) -> np.ndarray:
    c = [1, 1j, -1, -1j][q % 4]
    return np.array([[c.real, -c.imag], [c.imag, c.real]])


def _separation_rows(unk: Unknowns, uv, uv_relaxed, fl, paths):
    """Constraints that keep close cones apart: for every pair at most two edges apart that
    the rounded map puts at one point, ``W_b - W_a = d`` in a chart along their path, ``d``
    the relaxed offset rounded away from 0 (at least one unit along its longer axis).

    Along the path ``a -f1- c -f2- b`` the chart of ``f2`` is carried into that of ``f1`` by the
    rigid motion fixing ``c``: ``w -> R (w - W_c(f2)) + W_c(f1)``, ``R`` the quarter turns
    between the two wedges of ``c``; ``c``'s own (real) unknowns cancel, so the constraint
    involves the integer unknowns only."""
    rows = []
    n = unk.ncls
    Qd = unk.Q.tocsr()

    def corner(f, v):
        return int(np.flatnonzero(fl[f] == v)[0])

    def q_of(w):
        return np.vstack([Qd[w].toarray(), Qd[n + w].toarray()])  # (2, ny)

    for a, f1, c, f2, b in paths:
        ka, kc1, kc2, kb = corner(f1, a), corner(f1, c), corner(f2, c), corner(f2, b)
        w_a, w_c1, w_c2, w_b = unk.wedge[f1, ka], unk.wedge[f1, kc1], unk.wedge[f2, kc2], unk.wedge[f2, kb]
        R = _rot(int(unk.rho[w_c1] - unk.rho[w_c2]))

        def offset(m, R=R, f1=f1, f2=f2, ka=ka, kc1=kc1, kc2=kc2, kb=kb):
            return R @ (m[f2, kb] - m[f2, kc2]) + m[f1, kc1] - m[f1, ka]

        if np.abs(offset(uv)).max() > 0.5:
            continue
        delta = offset(uv_relaxed)
        d = np.rint(delta)
        if not d.any():
            j = int(np.argmax(np.abs(delta)))
            d[j] = 1.0 if delta[j] >= 0 else -1.0
        form = R @ (q_of(w_b) - q_of(w_c2)) + q_of(w_c1) - q_of(w_a)
        rows.append(np.column_stack([form, -d]))
    return np.vstack(rows) if rows else np.zeros((0, unk.K.shape[1]))


def _boundary_rows(unk: Unknowns, uv, uv_relaxed, fl, cone, on_line):
    """Constraints that keep cones off the boundary lines: for every cone ``a`` and boundary
    vertex ``c`` of one triangle, ``c`` inside a straight stretch of the boundary
    (``on_line``: its coordinate across the boundary, the only one of its wedge with no free
    unknown, is an integer unknown), that the rounded map puts on ``c``'s line (a collapsed
    triangle), ``W_a - W_c = d`` in that coordinate of the triangle's chart, ``d`` the
    relaxed offset rounded away from 0 (at least one unit).  The constraint involves the
    integer unknowns only."""
    rows = []
    n = unk.ncls
    Pd, Qd = unk.P.tocsr(), unk.Q.tocsr()
    has_free = np.diff(Pd.indptr) > 0
    has_free[has_free] = np.add.reduceat(np.abs(Pd.data), Pd.indptr[:-1][has_free]) > 0
    done = set()
    for f in np.flatnonzero(cone[fl].any(1) & on_line[fl].any(1)).tolist():
        for ka in range(3):
            a = int(fl[f, ka])
            if not cone[a]:
                continue
            for kc in range(3):
                c = int(fl[f, kc])
                if not on_line[c] or (a, c) in done:
                    continue
                w_a, w_c = unk.wedge[f, ka], unk.wedge[f, kc]
                free = [bool(has_free[j * n + w_c]) for j in (0, 1)]
                if free[0] == free[1]:
                    continue
                j = free.index(False)
                if abs(uv[f, ka, j] - uv[f, kc, j]) > 0.5:
                    continue
                delta = uv_relaxed[f, ka, j] - uv_relaxed[f, kc, j]
                if abs(delta) < 1e-9:
                    continue
                done.add((a, c))
                d = float(np.sign(delta)) * max(1.0, float(np.rint(abs(delta))))
                form = Qd[j * n + w_a].toarray() - Qd[j * n + w_c].toarray()
                rows.append(np.column_stack([form, [[-d]]]))
    return np.vstack(rows) if rows else np.zeros((0, unk.K.shape[1]))


def _slits(boundary, turns: np.ndarray, fl: np.ndarray):
    """The holes of one triangle mapped to a slit: a boundary loop of three edges with 4, 4
    and 2 quarter turns. Per slit, its two sides from one tip to the other as paths ``(a,
    f1, c, f2, b)`` (:func:`_cone_paths`), the edge between the tips first, and the chart
    coordinate of its face along the slit."""
    from .corners import boundary_loops

    bf, ka, kb, axis = boundary
    a, b = fl[bf, ka], fl[bf, kb]
    out = []
    for loop in boundary_loops(a, b):
        if loop.size != 3 or sorted(turns[a[loop]].tolist()) != [2, 4, 4]:
            continue
        k = next(k for k in range(3) if turns[b[loop[k]]] == 2)
        i, m, o = (int(loop[(k + q) % 3]) for q in range(3))  # tip -> middle -> tip -> tip
        direct = (int(a[o]), int(bf[o]), int(b[o]), int(bf[o]), int(b[o]))
        other = (int(b[m]), int(bf[m]), int(a[m]), int(bf[i]), int(a[i]))
        out.append((direct, other, 1 - int(axis[o])))
    return out


def _path_form(unk: Unknowns, fl, path):
    """``W_b - W_a`` along ``path = (a, f1, c, f2, b)`` in the chart of ``f1`` (the rigid
    motion of :func:`_separation_rows` across ``c``): a function of a per-corner map, the
    (2, ny) integer form, and the wedge of ``a`` in ``f1``."""
    a, f1, c, f2, b = path
    n = unk.ncls
    Qd = unk.Q.tocsr()
    ka, kc1, kc2, kb = (int(np.flatnonzero(fl[f] == v)[0]) for f, v in ((f1, a), (f1, c), (f2, c), (f2, b)))
    w_a, w_c1, w_c2, w_b = unk.wedge[f1, ka], unk.wedge[f1, kc1], unk.wedge[f2, kc2], unk.wedge[f2, kb]
    R = _rot(int(unk.rho[w_c1] - unk.rho[w_c2]))

    def offset(m):
        return R @ (m[f2, kb] - m[f2, kc2]) + m[f1, kc1] - m[f1, ka]

    def q_of(w):
        return np.vstack([Qd[w].toarray(), Qd[n + w].toarray()])

    return offset, R @ (q_of(w_b) - q_of(w_c2)) + q_of(w_c1) - q_of(w_a), w_a


def _slit_rows(unk: Unknowns, uv, uv_relaxed, fl, slits):
    """Constraints that open the slits (:func:`_slits`) to two units: a slit of one unit
    would join its two tips by two quad edges. For every slit that the rounded map makes
    shorter than two units on either side, ``W_b - W_a = D`` along both sides, ``D`` two
    units along the slit with the sign of the relaxed map's offset along the tips' edge, in
    the chart of the tip ``a`` on that side (both sides leave ``a`` along one ray: it has 4
    quarter turns). Integer unknowns only: the tips are corners."""
    rows = []
    for direct, other, j in slits:
        off1, form1, w1 = _path_form(unk, fl, direct)
        off2, form2, w2 = _path_form(unk, fl, other)
        if abs(off1(uv)[j]) >= 2 and np.abs(off2(uv)).max() >= 2:
            continue
        d1 = np.zeros(2)
        d1[j] = 2.0 if off1(uv_relaxed)[j] >= 0 else -2.0
        d2 = _rot(int(unk.rho[w2] - unk.rho[w1])) @ d1
        rows.append(np.column_stack([form1, -d1]))
        rows.append(np.column_stack([form2, -d2]))
    return np.vstack(rows) if rows else np.zeros((0, unk.K.shape[1]))


def _round_map(unk: Unknowns, A, rhs, extra_rows):
    """Eliminate, reduce and round; the integers ``y`` (exact) and the relaxed ones."""
    K = np.vstack([unk.K, extra_rows]) if extra_rows.size else unk.K
    B, b0, ind = eliminate(K, prefer=unk.kind == 1, never=unk.pinned)
    red = Reduced(A, rhs, unk.P, unk.Q, B, b0)
    kind = unk.kind[ind]
    phases = [np.flatnonzero(kind == 0), np.flatnonzero(kind == 1)]
    y_ind, steps = greedy_round(red.S, red.g, phases)
    y = red.y(y_ind)
    err = float(np.abs(y - np.rint(y)).max(initial=0))
    y_relaxed = red.y(red.relaxed())
    return red, np.rint(y), y_relaxed, err, steps, ind.size


def integer_grid_map(
    verts,
    faces,
    z,
    scale: float | None = None,
    split: bool = True,
    fix_flips: bool = True,
    separate_cones: int = 8,
    dipoles: float = 1.0,
) -> IntegerGridMap:
    """Integer-grid map guided by the cross field ``z`` (module docstring).

    Parameters
    ----------
    verts : (V, 3) tensor
    faces : (F, 3) int tensor or :class:`Topology`
    z : (E,) complex tensor, the representation vector of a cross field (``n = 4``)
    scale : target gradient norm ``s``: about ``1/s`` per quad side, ``s^2 area`` quads;
        default ``1 / (2 h)`` (``h`` the mean edge length)
    split : move face singularities to new vertices first (thesis 4.1, B.2); without it a
        face singularity raises ``ValueError``
    fix_flips : run the foldover-free iterations when the rounded map flips triangles
    separate_cones : at most this many rounds of re-rounding with close cones that the
        rounding put at one point held one unit apart, and cones that it put on the line of
        a neighbouring straight stretch of a hard boundary held one unit off it, and the
        tips of a slit (a hole of one triangle with 4, 4 and 2 quarter turns) held two
        units apart on both sides (one unit would join them by two quad edges)
    dipoles : pairs of cones of opposite index closer than this many target quad edges
        (``dipoles / s``) are removed (:func:`torch_edgevf.quad.cones.cancel_dipoles`): the
        quad mesh cannot resolve them; 0 keeps every cone of the field

    Returns
    -------
    :class:`IntegerGridMap`
    """
    like = verts if isinstance(verts, torch.Tensor) else torch.as_tensor(np.asarray(verts))
    dtype = like.dtype if like.dtype in (torch.float32, torch.float64) else torch.float64
    return with_dtype(_grid_map64(verts, faces, z, scale, split, fix_flips, separate_cones, dipoles), dtype)


def _grid_map64(verts, faces, z, scale, split, fix_flips, separate_cones, dipoles) -> IntegerGridMap:
    """The map in float64 (what the quad extraction needs: exact integers, snapped free values)."""
    with threadpool_limits(limits=1):  # small dense problems: threads only contend
        grid = _integer_grid_map(verts, faces, z, scale, split, fix_flips, separate_cones, dipoles)
    assert grid is not None  # only a relabelled map can be None
    return grid


def _relabelled_map64(verts, faces, z, scale, fix_flips) -> IntegerGridMap | None:
    """:func:`_grid_map64` (default options) with the short boundary edges of stairs and of
    corners closer than a quad turned across the field (:mod:`torch_edgevf.quad.corners`);
    ``None`` when no edge is turned (the map would be the one without it)."""
    with threadpool_limits(limits=1):
        return _integer_grid_map(verts, faces, z, scale, True, fix_flips, 8, 1.0, relabel=True)


def with_dtype(grid: IntegerGridMap, dtype: torch.dtype) -> IntegerGridMap:
    """The map with its real tensors (vertices, ``uv``, cone indices) in ``dtype``."""
    return dataclasses.replace(
        grid,
        verts=grid.verts.to(dtype),
        uv=grid.uv.to(dtype),
        cone_index=grid.cone_index.to(dtype),
    )


def _integer_grid_map(
    verts, faces, z, scale, split, fix_flips, separate_cones, dipoles, relabel=False
) -> IntegerGridMap | None:
    verts, topo = topology_and_verts(verts, faces)
    z = as_edge_field(z, topo, verts)
    if z.dim() != 1:
        raise ValueError(f"z must have shape (E,), got {tuple(z.shape)}")
    verts = verts.detach().to(torch.float64).cpu()
    z = z.detach().to(torch.complex128).cpu()
    num_split = 0
    sing = singularities(verts, topo, z, n=4)
    if sing.singular_faces.numel():
        if not split:
            raise ValueError(
                f"the field has {sing.singular_faces.numel()} face singularities; pass split=True "
                "to move them to vertices"
            )
        out = split_singular_faces(verts, topo, z, n=4)
        num_split = int(out.new_vertices.numel())
        verts, z = out.verts, out.z
        topo = Topology(out.faces, verts.shape[0])
    h = float(torch.linalg.vector_norm(verts[topo.edges[:, 1]] - verts[topo.edges[:, 0]], dim=-1).mean())
    s = 1.0 / (2 * h) if scale is None else float(scale)
    if not (math.isfinite(s) and s > 0):
        raise ValueError(f"scale must be a positive finite number, got {scale!r}")

    # cut and comb; cones of index +1/2 and more (no proper quad mesh) split into +1/4 ones
    parent, parent_edge, order, tree = dual_tree(topo)
    cmb = comb(verts, topo, z, CutGraph(parent, parent_edge, order, tree, np.zeros(topo.num_edges, bool)))
    field = combed_field(verts, topo, cmb.angle)
    num_field_cones = int((field.index != 0).sum())
    field = split_cones(verts, topo, field, (parent, parent_edge, order))
    if dipoles > 0:
        field = cancel_dipoles(verts, topo, field, (parent, parent_edge, order), dipoles / s)
    wind = field.index
    bnd_v = topo.boundary_vertices.numpy()
    cone = (wind != 0) & ~bnd_v
    interior = ~topo.boundary_edges.numpy()
    cut = prune_cut(topo, interior & ~tree, cone)
    if np.any(field.matching[interior & ~cut] != 0):  # cannot happen: the comb follows the tree
        raise RuntimeError("an uncut edge has a non-zero matching")
    turns = np.zeros(topo.num_vertices, dtype=np.int64)
    boundary = None
    if bnd_v.any():
        axes = boundary_axes(verts, topo, field, s if relabel else None)
        if relabel and not axes.relabelled:
            return None
        turns = axes.turns
        boundary = (axes.faces, axes.corner_a, axes.corner_b, axes.axis)
    elif relabel:
        return None
    corner = bnd_v & (turns != 2)
    total = (wind[cone].sum() + (2 - turns[bnd_v]).sum()) / 4
    if total != topo.euler_characteristic and boundary is not None:
        # the turns at the boundary are right modulo 4; a field that crosses the boundary
        # (soft alignment on a jagged boundary) can leave them a whole turn off
        raise ValueError(
            f"the field's cones and its turning along the boundary add up to {total:g}, not the "
            f"Euler characteristic {topo.euler_characteristic}: the field is too far from the "
            "boundary's directions (align it to the boundary: boundary='hard')"
        )
    if total != topo.euler_characteristic:  # cannot happen: both count the turning of the field
        raise RuntimeError(f"the cones and boundary corners add up to {total}, not chi")
    comp = topo.components.numpy()
    pinned = []
    integer_vertex = cone | corner
    for c in range(topo.num_components):
        vs = np.flatnonzero((comp == c) & integer_vertex)
        if vs.size == 0:
            vs = np.flatnonzero((comp == c) & bnd_v)
        v0 = int(vs[0]) if vs.size else int(np.flatnonzero(comp == c)[0])
        pinned.append(v0)
        integer_vertex[v0] = True
    unk = build_unknowns(topo, cut, field.matching, integer_vertex, pinned, boundary)
    fl = topo.faces.numpy()
    angle = _frame_angles_in_plane(verts, topo, field.angle)
    A, rhs, area = _energy_system(verts.numpy(), fl, unk.wedge, unk.ncls, angle, s)

    def corners(W):
        return np.stack([W[: unk.ncls][unk.wedge], W[unk.ncls :][unk.wedge]], -1)

    slits = _slits(boundary, turns, fl) if boundary is not None else []
    tips = {frozenset((p[0], p[4])) for p, _, _ in slits}
    # the tips of a slit are held two units apart by their own constraint
    paths = [p for p in _cone_paths(fl, cone | corner) if frozenset((p[0], p[4])) not in tips]
    extra = np.zeros((0, unk.K.shape[1]))
    for attempt in range(separate_cones + 1):
        red, y, y_relaxed, err, steps, n_ind = _round_map(unk, A, rhs, extra)
        uv = corners(red.wedges(y))
        uv_relaxed = corners(red.wedges(y_relaxed))
        pairs = _separation_rows(unk, uv, uv_relaxed, fl, paths)  # two rows per pair
        off_line = (
            _boundary_rows(unk, uv, uv_relaxed, fl, cone, bnd_v & ~corner)
            if boundary is not None
            else pairs[:0]
        )
        new = np.vstack([pairs, off_line, _slit_rows(unk, uv, uv_relaxed, fl, slits)])
        log.info(
            "igm: %d cones, %d arcs, %d closures, %d separation rows, %d independent integers, "
            "%d rounding steps, dependent integers off by %.2g; %d cone pairs collapsed, %d cones "
            "on boundary lines",
            int(cone.sum()),
            unk.num_arcs,
            unk.K.shape[0] // 2,
            extra.shape[0],
            n_ind,
            steps,
            err,
            pairs.shape[0] // 2,
            off_line.shape[0],
        )
        if err > 1e-6:
            raise ValueError(
                f"integer rounding failed: the cone and seam constraints leave a dependent unknown "
                f"{err:.3g} away from an integer (a parity conflict of the cones)"
            )
        if new.size == 0 or attempt == separate_cones:
            break
        extra = np.vstack([extra, new])
    relaxed_energy = red.energy(red.wedges(y_relaxed))
    xs = red.x(y)
    W = red.wedges(y, xs)
    uv = corners(W)
    expected = np.where(bnd_v, turns, 4 - wind)  # quarter turns of the map at each vertex
    flips0 = _bad_faces(uv, fl, expected)
    if flips0 and fix_flips:
        from .untangle import untangle

        target = _target_shapes(verts.numpy(), fl, angle, s)
        xs = _stiffen(A, rhs, unk.P, unk.Q, y, xs, corners, target, fl, expected)
        uv = corners(red.wedges(y, xs))
        left = _bad_faces(uv, fl, expected)
        log.info("stiffening: %d of %d bad triangles left", left, flips0)
        if left:
            xs = untangle(unk.P, unk.Q, y, xs, unk.wedge, unk.ncls, target)
    # snap the free coordinates to multiples of 2^-30: the wedge values, sums of them and
    # integers, are then exact, and the charts on both sides of every edge agree exactly
    xs = np.round(xs * _GRID) / _GRID
    W = red.wedges(y, xs)
    uv = corners(W)
    flips = _bad_faces(uv, fl, expected)
    energy = red.energy(W)
    trans = transitions(topo, uv, field.matching)
    cones_idx = np.flatnonzero(cone)
    return IntegerGridMap(
        verts=verts,
        faces=topo.faces,
        uv=torch.from_numpy(uv),
        cones=torch.from_numpy(cones_idx),
        cone_index=torch.from_numpy(wind[cones_idx] / 4.0),
        cut_edges=torch.from_numpy(cut),
        matching=torch.from_numpy(field.matching),
        translations=torch.from_numpy(np.rint(trans).astype(np.int64)),
        scale=s,
        flipped=flips,
        flipped_before_fix=flips0,
        energy=energy * area.sum(),
        relaxed_energy=relaxed_energy * area.sum(),
        num_split=num_split,
        num_field_cones=num_field_cones,
        boundary_turns=torch.from_numpy(turns),
    )
