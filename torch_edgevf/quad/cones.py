"""The cones of a combed cross field, and how to move them (see :mod:`torch_edgevf.quad.igm`).

A cross field combed into one direction ``angle[f]`` per face (:func:`~torch_edgevf.fields.param.comb`)
turns across every interior edge, relative to the transport by unfolding, by
``r_e + k_e pi/2``: ``r_e`` is the rotation of the field, the quarter turns ``k_e`` (the
*matching*) only relabel the cross. Around a vertex ``v`` (counter-clockwise, ``Omega_v`` the
angle defect)

.. math::  I_v = \\frac{1}{2\\pi}\\Big(\\Omega_v + \\sum_{e \\ni v} \\pm r_e\\Big)

is the index of the field (a multiple of 1/4), and an integer-grid map built on the comb
has corner angles adding up to ``2 pi (1 - I_v)`` at ``v``: the quad mesh has valence
``4 - 4 I_v`` there. A cone of index ``+1/2`` or more (valence 2, 1 or 0) has no proper quad
mesh; :func:`split_cones` replaces it by cones of index ``+1/4`` around it, changing the
rotations ``r`` the least (in the least-squares sense) inside a disk around the cone, as
trivial connections do [CDS10], so the indices elsewhere and the holonomy of every loop
outside the disk stay as they were.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csg

from ..fields.singularities import face_frame_angles
from ..mesh.geometry import angle_defects
from ..mesh.topology import Topology

__all__ = ["CombedField", "combed_field", "split_cones", "cancel_dipoles", "BoundaryAxes", "boundary_axes"]

_QUARTER = math.pi / 2


@dataclass
class CombedField:
    """One direction per face and the field's turning across edges.

    Attributes
    ----------
    angle : (F,) the direction ``U_f`` in the frame of :func:`face_frame_angles`
    rotation : (E,) ``r_e``, the rotation from slot 0 to slot 1 relative to the transport
        (0 on boundary edges)
    matching : (E,) int64 ``k_e`` in {0..3}: ``U_g = T(U_f) e^{i (r_e + k_e pi/2)}``
    index : (V,) int64, ``4 I_v`` (quarter turns)
    """

    angle: np.ndarray
    rotation: np.ndarray
    matching: np.ndarray
    index: np.ndarray


def _transported(topo: Topology, theta: np.ndarray, angle: np.ndarray):
    """``psi_e``: ``angle`` of the slot-0 face carried into the slot-1 face, per interior edge."""
    ef, ec = topo.edge_faces.numpy(), topo.edge_corners.numpy()
    e = np.flatnonzero((ef >= 0).all(1))
    f, g = ef[e, 0], ef[e, 1]
    return e, f, g, angle[f] - theta[f, ec[e, 0]] + theta[g, ec[e, 1]]


def _indices(verts, topo: Topology, rotation: np.ndarray, defects=None) -> np.ndarray:
    edges = topo.edges.numpy()
    turn = (angle_defects(verts, topo).numpy() if defects is None else defects).copy()
    np.add.at(turn, edges[:, 1], rotation)  # the loop around the upper end crosses slot 0 -> 1
    np.add.at(turn, edges[:, 0], -rotation)
    return np.rint(turn / _QUARTER).astype(np.int64)


def combed_field(verts, topo: Topology, angle: np.ndarray) -> CombedField:
    """Rotations, matchings and indices of the combed directions ``angle`` (module docstring),
    with ``r_e`` the principal rotation in ``(-pi/4, pi/4]``."""
    theta = face_frame_angles(verts, topo).numpy()
    e, _, g, psi = _transported(topo, theta, angle)
    d = angle[g] - psi
    k = np.rint(d / _QUARTER)
    rotation = np.zeros(topo.num_edges)
    rotation[e] = d - _QUARTER * k
    matching = np.zeros(topo.num_edges, dtype=np.int64)
    matching[e] = np.mod(k.astype(np.int64), 4)
    return CombedField(angle, rotation, matching, _indices(verts, topo, rotation))


def _with_rotation(verts, topo: Topology, field: CombedField, rotation: np.ndarray, tree) -> CombedField:
    """The comb whose rotations are ``rotation``: angles integrated from the roots of the dual
    spanning ``tree = (parent, parent_edge, order)`` (so its edges keep matching 0), matchings
    from the remaining turns."""
    theta = face_frame_angles(verts, topo).numpy()
    ef, ec = topo.edge_faces.numpy(), topo.edge_corners.numpy()
    parent, parent_edge, order = tree
    angle = field.angle.copy()
    for g in order.tolist():
        f = parent[g]
        if f < 0:
            continue
        ed = parent_edge[g]
        if ef[ed, 0] == f:  # f slot 0, g slot 1
            angle[g] = angle[f] - theta[f, ec[ed, 0]] + theta[g, ec[ed, 1]] + rotation[ed]
        else:
            angle[g] = angle[f] - theta[f, ec[ed, 1]] + theta[g, ec[ed, 0]] - rotation[ed]
    # the root of a tree may lie where the rotations changed: its angle, kept, would turn
    # the field everywhere else by the change there. Turn each component back so that the
    # faces whose rotations did not change keep their directions (the changes add up to
    # quarter turns around them, so one turn per component does it).
    same = (rotation == field.rotation)[topo.face_edges.numpy()].all(1)
    comp = topo.components.numpy()[topo.faces.numpy()[:, 0]]
    spin = np.exp(4j * (angle - field.angle))
    for c in np.unique(comp[same]).tolist():
        turn = np.angle(spin[same & (comp == c)].sum()) / 4
        if abs(turn) > 1e-9:
            angle[comp == c] -= turn
    e, _, g, psi = _transported(topo, theta, angle)
    k = (angle[g] - psi - rotation[e]) / _QUARTER
    if np.abs(k - np.rint(k)).max(initial=0) > 1e-6:
        raise RuntimeError("combing along the tree left a non-quarter turn")
    matching = np.zeros(topo.num_edges, dtype=np.int64)
    matching[e] = np.mod(np.rint(k).astype(np.int64), 4)
    return CombedField(angle, rotation, matching, _indices(verts, topo, rotation))


def _rings(topo: Topology, v: int, depth: int) -> np.ndarray:
    """(V,) ring distance from ``v`` (edges), -1 beyond ``depth``."""
    edges = topo.edges.numpy()
    nv = topo.num_vertices
    g = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(nv, nv))
    dist = csg.dijkstra(g, directed=False, unweighted=True, indices=v, limit=depth + 0.5)
    return np.where(np.isfinite(dist), dist, -1).astype(np.int64)


def _spread(verts: np.ndarray, v: int, candidates: np.ndarray, m: int) -> np.ndarray:
    """``m`` of ``candidates`` evenly spread by angle around ``v`` (in its tangent plane)."""
    d = verts[candidates] - verts[v]
    n = np.linalg.svd(d - d.mean(0), full_matrices=False)[2][-1]
    x = d[0] - (d[0] @ n) * n
    x /= np.linalg.norm(x)
    y = np.cross(n, x)
    phi = np.mod(np.arctan2(d @ y, d @ x), 2 * math.pi)
    picks: list[int] = []
    for j in range(m):
        want = 2 * math.pi * j / m
        gap = np.abs(np.angle(np.exp(1j * (phi - want))))
        gap[picks] = np.inf
        picks.append(int(np.argmin(gap)))
    return candidates[picks]


def _retarget(topo: Topology, defects, rotation: np.ndarray, inside: np.ndarray, new: np.ndarray) -> None:
    """Change ``rotation`` (in place) on the edges touching the vertices ``inside`` by the
    least-squares change that gives every vertex touching them the index ``new``."""
    edges = topo.edges.numpy()
    free = np.flatnonzero(inside[edges[:, 0]] | inside[edges[:, 1]])
    touched = np.zeros(topo.num_vertices, dtype=bool)
    touched[edges[free].ravel()] = True
    rows = np.flatnonzero(touched)
    row_of = np.full(topo.num_vertices, -1, dtype=np.int64)
    row_of[rows] = np.arange(rows.size)
    C = np.zeros((rows.size, free.size))
    C[row_of[edges[free, 1]], np.arange(free.size)] += 1
    C[row_of[edges[free, 0]], np.arange(free.size)] -= 1
    turn = defects.copy()
    np.add.at(turn, edges[:, 1], rotation)
    np.add.at(turn, edges[:, 0], -rotation)
    want = _QUARTER * new[rows] - turn[rows]
    rotation[free] += np.linalg.lstsq(C, want, rcond=None)[0]


def split_cones(
    verts, topo: Topology, field: CombedField, tree, max_index: int = 1, depth: int = 2
) -> CombedField:
    """Replace every interior cone of index above ``max_index / 4`` by ``4 I`` cones of index
    ``+1/4`` on a ring of ``depth`` (or more) edges around it (module docstring).

    The rotations change only on the edges within that ring, by the least-squares change that
    gives the new indices; the other indices do not change. A cone whose rings reach the
    boundary is left as it is. ``tree`` is the dual spanning tree the new comb is integrated
    along (its edges keep matching 0).
    """
    v_np = verts.numpy() if hasattr(verts, "numpy") else np.asarray(verts)
    bnd = topo.boundary_vertices.numpy()
    high = np.flatnonzero((field.index > max_index) & ~bnd)
    if high.size == 0:
        return field
    defects = angle_defects(verts, topo).numpy()
    rotation = field.rotation.copy()
    target = field.index.copy()
    for v in high.tolist():
        m = int(target[v])
        chosen = None
        for dd in range(depth, depth + 4):
            ring = _rings(topo, v, dd + 1)
            if np.any(bnd[ring >= 0]):
                break
            candidates = np.flatnonzero((ring == dd) & (target == 0))
            if candidates.size >= 2 * m:
                chosen = dd
                break
        if chosen is None:
            continue
        new = target.copy()
        new[v] = 0
        new[_spread(v_np, v, candidates, m)] += 1
        _retarget(topo, defects, rotation, (ring >= 0) & (ring <= chosen), new)
        target = new
    out = _with_rotation(verts, topo, field, rotation, tree)
    if not np.array_equal(out.index, target):
        raise RuntimeError("moving the cones changed other indices")
    return out


def cancel_dipoles(verts, topo: Topology, field: CombedField, tree, distance: float) -> CombedField:
    """Remove pairs of interior cones of opposite index (``+1/4``, ``-1/4``) closer than
    ``distance`` along the edges, closest pair first.

    A quad mesh with edges of length ``distance`` cannot resolve such a pair: the two cones
    would sit at neighbouring grid points or at one. Their indices are set to 0 by the
    least-squares change of the rotations on the edges around the shortest path between them
    (as :func:`split_cones`); other indices and the holonomy of loops around that
    neighbourhood do not change. Pairs whose neighbourhood reaches the boundary stay.
    """
    bnd = topo.boundary_vertices.numpy()
    edges = topo.edges.numpy()
    v_np = verts.numpy() if hasattr(verts, "numpy") else np.asarray(verts)
    length = np.linalg.norm(v_np[edges[:, 1]] - v_np[edges[:, 0]], axis=1)
    nv = topo.num_vertices
    graph = sp.coo_matrix((length, (edges[:, 0], edges[:, 1])), shape=(nv, nv)).tocsr()
    adjacency = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(nv, nv)).tocsr()
    adjacency = adjacency + adjacency.T
    defects = angle_defects(verts, topo).numpy()
    rotation = field.rotation.copy()
    target = field.index.copy()
    changed = False
    excluded = bnd.copy()
    while True:
        pos = np.flatnonzero((target == 1) & ~excluded)
        neg = np.flatnonzero((target == -1) & ~excluded)
        if pos.size == 0 or neg.size == 0:
            break
        dist, pred = csg.dijkstra(
            graph, directed=False, indices=pos, limit=distance, return_predecessors=True
        )
        d = dist[:, neg]
        best = np.unravel_index(np.argmin(d), d.shape)
        if not np.isfinite(d[best]):
            break
        i, j = best
        a, b = int(pos[i]), int(neg[j])
        path = [b]
        while path[-1] != a:
            path.append(int(pred[i, path[-1]]))
        inside = np.zeros(nv, dtype=bool)
        inside[path] = True
        inside |= (adjacency @ inside.astype(float)) > 0
        if np.any(bnd[(adjacency @ inside.astype(float)) > 0]):
            excluded[a] = True  # leave this cone out of the search
            continue
        new = target.copy()
        new[a] = new[b] = 0
        _retarget(topo, defects, rotation, inside, new)
        target = new
        changed = True
    if not changed:
        return field
    out = _with_rotation(verts, topo, field, rotation, tree)
    if not np.array_equal(out.index, target):
        raise RuntimeError("cancelling the cones changed other indices")
    return out


@dataclass
class BoundaryAxes:
    """How the boundary of an open mesh sits in the charts of a combed cross field.

    Attributes
    ----------
    faces, corner_a, corner_b : (B,) every boundary edge as the corners ``a -> b`` of its face
        (the face on its left)
    axis : (B,) the chart coordinate constant along the edge: 1 (``v``) if it runs along ``u``
        in its face's chart, 0 (``u``) if along ``v``
    turns : (V,) int64, at every boundary vertex the number of quarter turns of the map's
        corners there (the quads at the vertex: 2 on a straight boundary, 1 at a convex
        corner, 3 at a concave one); 0 inside
    """

    faces: np.ndarray
    corner_a: np.ndarray
    corner_b: np.ndarray
    axis: np.ndarray
    turns: np.ndarray
    relabelled: bool = False


def boundary_axes(verts, topo: Topology, field: CombedField, scale: float | None = None) -> BoundaryAxes:
    """Label every boundary edge by the chart axis it follows, and count the quarter turns
    at every boundary vertex (:class:`BoundaryAxes`).

    An edge's label is its direction relative to the face's ``U``, rounded to quarter turns.
    At a boundary vertex the labels of its two boundary edges, carried into one chart across
    the matchings of the fan between them, fix the turns modulo 4; of those values the one
    nearest the sum of the corner angles less the field's rotation across the fan is taken.
    """
    theta = face_frame_angles(verts, topo).numpy()
    fl = topo.faces.numpy()
    fe = topo.face_edges.numpy()
    ef = topo.edge_faces.numpy()
    bnd_e = np.flatnonzero(topo.boundary_edges.numpy())
    f = np.where(ef[bnd_e, 0] >= 0, ef[bnd_e, 0], ef[bnd_e, 1])
    k = np.argmax(fe[f] == bnd_e[:, None], axis=1)
    ka, kb = (k + 1) % 3, (k + 2) % 3
    a, b = fl[f, ka], fl[f, kb]
    phi = theta[f, k] + np.where(a < b, 0.0, math.pi)
    r = (phi - field.angle[f]) / _QUARTER
    rho = r - np.rint(r)  # the edge's angle to the nearest axis, in quarter turns
    label = np.mod(np.rint(r).astype(np.int64), 4)
    nearest = np.zeros(bnd_e.size, dtype=np.int64)  # turns at each edge's start, unclamped
    fan = np.zeros(bnd_e.size, dtype=np.int64)  # triangles at each edge's start
    axis = 1 - label % 2  # the coordinate constant along the edge
    # quarter turns at the boundary vertices
    from ..mesh.geometry import corner_angles

    alpha = corner_angles(verts, topo).numpy()
    out_of = {int(x): i for i, x in enumerate(a)}  # vertex -> its outgoing boundary edge
    in_of = {int(x): i for i, x in enumerate(b)}
    edges_faces = ef
    turns = np.zeros(topo.num_vertices, dtype=np.int64)
    for v, i_out in out_of.items():
        i_in = in_of[v]
        face, corner = int(f[i_out]), int(ka[i_out])
        shift, rot, angle_sum = 0, 0.0, 0.0
        while True:
            angle_sum += alpha[face, corner]
            fan[i_out] += 1
            if face == f[i_in] and corner == kb[i_in]:
                break
            e = int(fe[face, (corner + 1) % 3])  # the edge (v, next vertex of the fan)
            g = int(edges_faces[e, 1] if edges_faces[e, 0] == face else edges_faces[e, 0])
            if edges_faces[e, 0] == face:
                shift -= int(field.matching[e])
                rot += field.rotation[e]
            else:
                shift += int(field.matching[e])
                rot -= field.rotation[e]
            face = g
            corner = int(np.flatnonzero(fl[face] == v)[0])
        m = int((label[i_in] + 2 - (label[i_out] + shift)) % 4)
        estimate = (angle_sum - rot) / _QUARTER
        options = [m + 4 * j for j in range(3) if m + 4 * j >= 1]
        turns[v] = min(options, key=lambda n: abs(n - estimate))
        nearest[i_out] = min((m + 4 * j for j in range(-1, 3)), key=lambda n: abs(n - estimate))
    relabelled = False
    if scale is not None:
        from .corners import boundary_loops, relabel_loops

        v_np = verts.numpy() if hasattr(verts, "numpy") else np.asarray(verts)
        length = np.linalg.norm(v_np[b] - v_np[a], axis=1) * scale
        delta, n = relabel_loops(boundary_loops(a, b), nearest, length, rho, fan)
        changed = np.flatnonzero(delta != 0)
        label[changed] = (label[changed] + delta[changed]) % 4
        axis = 1 - label % 2
        turns[a] = np.where(n >= 1, n, turns[a])  # a loop left with 0 turns: as before
        relabelled = bool(changed.size)
    return BoundaryAxes(f, ka, kb, axis, turns, relabelled)
