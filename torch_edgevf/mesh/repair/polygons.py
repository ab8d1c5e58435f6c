"""Polygons triangulated in their planes (fans where convex, ear clipping otherwise)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from ..._validation import face_range_message
from .report import RepairReport


@dataclass(frozen=True)
class Polygons:
    """Polygons of several sizes, stored flat (as the file readers parse them).

    ``flat`` holds the corner indices of every polygon in turn, ``sizes`` the number of
    corners of each; ``polygons[i]`` is the index array of polygon ``i``.
    """

    flat: np.ndarray
    sizes: np.ndarray

    def __len__(self) -> int:
        return len(self.sizes)

    @property
    def offsets(self) -> np.ndarray:
        return np.cumsum(self.sizes) - self.sizes

    def __getitem__(self, i: int) -> np.ndarray:
        start = int(self.sizes[:i].sum())
        return self.flat[start : start + int(self.sizes[i])]


def triangulate(
    faces, num_vertices: int, check: bool = True, *, verts=None
) -> tuple[np.ndarray, np.ndarray, RepairReport]:
    """Triangulation of polygons after removing their repeated vertex indices.

    The first step of :func:`repair`, also used by the file readers. Triangles keep
    their faces' corners and winding; no vertex is added.

    Without positions, a polygon of ``k > 3`` corners is split into the fan of ``k - 2``
    triangles from its first corner, which is valid for convex polygons only. With
    ``verts``, each polygon is triangulated in its best-fit plane (through the mean of its
    corners, normal to its Newell normal, the vector area): a strictly convex polygon keeps
    the fan, any other one is triangulated by ear clipping, which cuts off, in turn, the
    best-shaped corner that turns as the polygon does and whose triangle with its two
    neighbours holds no other corner. Every triangle then has positive area in the plane
    (its normal agrees with the polygon's), the ``k - 2`` triangles cover the polygon once
    and its sides are sides of the triangles. A polygon without a plane (zero area:
    collinear corners) or that is not simple in its plane (sides that cross or touch,
    a side doubling back) keeps the fan and is named in ``report.fan_faces``. Polygons
    with an index outside ``[0, num_vertices)`` or a non-finite corner keep the fan
    unreported (:func:`repair` drops them), and so does a polygon that still repeats a
    vertex once its consecutive repeats are removed (pinched), without the fan's
    triangles that repeat it.

    Parameters
    ----------
    faces : (F, k) integer array or tensor, or a sequence of index sequences
    num_vertices : int
    check : raise ``ValueError`` for indices outside ``[0, num_vertices)``
    verts : (num_vertices, 3) float array or tensor, optional
        The vertex positions; without them polygons are split into fans.

    Returns
    -------
    triangles : (T, 3) int64 array
    origin : (T,) int64 array, the face of each triangle
    report : :class:`RepairReport` with ``triangulated_faces``, ``added_triangles``,
        ``fan_faces`` and ``repeated_index_faces`` filled in
    """
    v = None
    if verts is not None:
        v = verts.detach().cpu().numpy() if isinstance(verts, torch.Tensor) else np.asarray(verts)
        if v.shape != (num_vertices, 3) or not np.issubdtype(v.dtype, np.floating):
            raise ValueError(
                f"verts must be a ({num_vertices}, 3) float array, got shape {v.shape}, dtype {v.dtype}"
            )
        v = v.astype(np.float64)
    tri, origin, report, _, _ = _triangulate(faces, num_vertices, check, v, sides=False)
    return tri, origin, report


#: Tolerance of the plane tests of :func:`triangulate` relative to the squared extent of
#: a polygon: smaller doubled areas count as zero (collinear corners, straight turns).
PLANE_TOL = 1e-12


def _fan(k: int) -> np.ndarray:
    """(k - 2, 3) corners of the fan of a k-gon from its first corner."""
    j = np.arange(1, k - 1)
    return np.stack([np.zeros_like(j), j, j + 1], 1)


def _cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _plane_coordinates(p: np.ndarray):
    """Polygons (n, k, 3) in their best-fit planes: (n, k, 2) coordinates, (n,) tolerance, (n,) flat.

    The plane passes through the mean of the corners, normal to the Newell normal (the
    vector area); its axes ``(u, w)`` have ``u x w`` along the normal, so that every polygon
    has positive signed area in its coordinates. ``tol`` is :data:`PLANE_TOL` times the
    squared extent of the polygon; ``flat`` marks the polygons whose doubled area is not
    above it (no plane).
    """
    c = p - p.mean(1, keepdims=True)
    normal = np.cross(c, np.roll(c, -1, axis=1)).sum(1)  # twice the vector area
    size = np.linalg.norm(normal, axis=1)
    tol = PLANE_TOL * (c.max(1) - c.min(1)).max(1) ** 2
    flat = ~(size > tol)
    unit = np.where(flat[:, None], [0.0, 0.0, 1.0], normal / np.where(flat, 1.0, size)[:, None])
    axis = np.eye(3)[np.argmin(np.abs(unit), axis=1)]  # the axis least aligned with the normal
    u = np.cross(unit, axis)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(unit, u)
    xy = np.stack([np.einsum("nkd,nd->nk", c, u), np.einsum("nkd,nd->nk", c, w)], -1)
    return xy, tol, flat


def _turns(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cross and dot products of the sides into and out of each corner of polygons (..., k, 2)."""
    side = np.roll(xy, -1, axis=-2) - xy  # from corner i to corner i + 1
    into = np.roll(side, 1, axis=-2)
    return _cross2(into, side), (into * side).sum(-1)


def _self_intersecting(xy: np.ndarray, tol: np.ndarray) -> np.ndarray:
    """(n,) whether two sides of each polygon (n, k, 2) meet other than adjacent ones at their corner."""
    n, k, _ = xy.shape
    turn, dot = _turns(xy)
    out = ((np.abs(turn) <= tol[:, None]) & (dot < 0)).any(1)  # a side doubling back on the last
    side = np.roll(xy, -1, axis=1) - xy
    i, j = np.triu_indices(k, 2)
    keep = j - i < k - 1  # sides 0 and k - 1 are adjacent
    i, j = i[keep], j[keep]
    step = max(1, (1 << 20) // max(n, 1))
    eps = tol[:, None]
    for s in range(0, len(i), step):
        a, b = i[s : s + step], j[s : s + step]
        pa, da, pb, db = xy[:, a], side[:, a], xy[:, b], side[:, b]

        def sign(x):
            return np.where(np.abs(x) <= eps, 0, np.sign(x))

        o1, o2 = sign(_cross2(da, pb - pa)), sign(_cross2(da, pb + db - pa))
        o3, o4 = sign(_cross2(db, pa - pb)), sign(_cross2(db, pa + da - pb))
        on_line = ((o1 == 0) & (o2 == 0)) | ((o3 == 0) & (o4 == 0))
        crossing = ~on_line & (o1 * o2 <= 0) & (o3 * o4 <= 0)
        # sides along one line meet where their extents along it overlap
        t = np.where((da * da).sum(-1, keepdims=True) >= (db * db).sum(-1, keepdims=True), da, db)
        s0, s1 = (pa * t).sum(-1), ((pa + da) * t).sum(-1)
        r0, r1 = (pb * t).sum(-1), ((pb + db) * t).sum(-1)
        overlap = np.maximum(np.minimum(s0, s1), np.minimum(r0, r1)) <= (
            np.minimum(np.maximum(s0, s1), np.maximum(r0, r1)) + eps
        )
        out |= (crossing | (on_line & overlap)).any(1)
    return out


def _ear_clip(xy: np.ndarray, tol: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ear clipping of polygons (n, k, 2) of positive signed area: (n, k - 2, 3) corners, (n,) done.

    An ear is a corner that turns left by more than ``tol`` and whose closed triangle with
    its two neighbours holds no other remaining corner (so none lies on the new side);
    each step cuts off the ear of the best shape (doubled area over the sum of the squared
    sides), in all polygons at once. ``done`` is False for a polygon that is not simple
    (its turns do not add up to one counter-clockwise revolution, or two sides meet) or
    that is left without an ear; its corners are then meaningless.
    """
    n, k, _ = xy.shape
    turn, dot = _turns(xy)
    done = np.abs(np.arctan2(turn, dot).sum(1) - 2 * np.pi) <= np.pi
    done[done] = ~_self_intersecting(xy[done], tol[done])
    corner = np.arange(k)
    prv = np.broadcast_to(np.roll(corner, 1), (n, k)).copy()
    nxt = np.broadcast_to(np.roll(corner, -1), (n, k)).copy()
    alive = np.ones((n, k), dtype=bool)

    def scores(r: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Shape of the ear at corner ``b`` of polygon ``r`` (arrays), -1 where it is no ear."""
        a, c = prv[r, b], nxt[r, b]
        pa, pb, pc = xy[r, a], xy[r, b], xy[r, c]
        ab, bc, ca = pb - pa, pc - pb, pa - pc
        area = _cross2(ab, bc)
        q, eps = xy[r], -tol[r][:, None]
        inside = (
            (_cross2(ab[:, None], q - pa[:, None]) >= eps)
            & (_cross2(bc[:, None], q - pb[:, None]) >= eps)
            & (_cross2(ca[:, None], q - pc[:, None]) >= eps)
        )
        own = (corner == a[:, None]) | (corner == b[:, None]) | (corner == c[:, None])
        ear = (area > tol[r]) & ~(inside & alive[r] & ~own).any(1)
        size = (ab**2).sum(1) + (bc**2).sum(1) + (ca**2).sum(1)
        return np.where(ear, area / np.where(size > 0, size, 1.0), -1.0)

    def all_scores(rows: np.ndarray) -> np.ndarray:
        if not len(rows):
            return np.zeros((0, k))
        r, b = np.repeat(rows, k), np.tile(corner, len(rows))
        step = max(1, (1 << 20) // k)
        s = np.concatenate([scores(r[m : m + step], b[m : m + step]) for m in range(0, len(r), step)])
        return np.where(alive[rows], s.reshape(len(rows), k), -np.inf)

    out = np.zeros((n, k - 2, 3), dtype=np.int64)
    score = np.full((n, k), -np.inf)
    live = np.flatnonzero(done)
    score[live] = all_scores(live)
    for step in range(k - 3):
        b = score[live].argmax(1)
        stuck = score[live, b] < 0
        if stuck.any():  # clipping may have freed an ear away from the cut: look again
            score[live[stuck]] = all_scores(live[stuck])
            b[stuck] = score[live[stuck]].argmax(1)
            lost = score[live, b] < 0
            done[live[lost]] = False
            live, b = live[~lost], b[~lost]
        a, c = prv[live, b], nxt[live, b]
        out[live, step] = np.stack([a, b, c], 1)
        alive[live, b] = False
        score[live, b] = -np.inf
        nxt[live, a], prv[live, c] = c, a
        score[np.r_[live, live], np.r_[a, c]] = scores(np.r_[live, live], np.r_[a, c])
    b = alive[live].argmax(1)
    out[live, k - 3] = np.stack([prv[live, b], b, nxt[live, b]], 1)
    return out, done


def _split_polygons(block: np.ndarray, v: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of polygons (n, k), k > 3, as in :func:`triangulate`: (n, k - 2, 3), rows fanned.

    The second output lists the rows that have positions but kept the fan for lack of a
    plane or of a simple outline.
    """
    n, k = block.shape
    tri = block[:, _fan(k)]
    if v is None:
        return tri, np.zeros(0, np.int64)
    placed = np.asarray(((block >= 0) & (block < len(v))).all(1))
    placed[placed] = np.isfinite(v[block[placed]]).all((1, 2))
    rows = np.flatnonzero(placed)
    if not len(rows):
        return tri, np.zeros(0, np.int64)
    xy, tol, flat = _plane_coordinates(v[block[rows]])
    turn, dot = _turns(xy)
    convex = ~flat & (turn > tol[:, None]).all(1) & (np.arctan2(turn, dot).sum(1) < 3 * np.pi)
    clip = np.flatnonzero(~convex & ~flat)
    corners, done = _ear_clip(xy[clip], tol[clip])
    ok = rows[clip[done]]
    tri[ok] = block[ok][np.arange(len(ok))[:, None, None], corners[done]]
    fanned = np.union1d(rows[flat], rows[clip[~done]])
    return tri, fanned.astype(np.int64)


def _triangulate(faces, nv: int, check: bool = True, v: np.ndarray | None = None, sides: bool = True):
    """Triangles of the polygons, without repeated indices: (T, 3), origin (T,), report, polygons, sides.

    ``v``: float64 positions (nv, 3), or None for fans (see :func:`triangulate`).
    ``faces`` may be :class:`Polygons`; the sides are not computed without ``sides``.
    """
    report = RepairReport()
    if isinstance(faces, torch.Tensor):
        faces = faces.detach().cpu().numpy()
    if isinstance(faces, Polygons):
        return _triangulate_flat(faces, nv, check, v, report, sides)
    if isinstance(faces, np.ndarray):
        if faces.ndim != 2 or (faces.size and not np.issubdtype(faces.dtype, np.integer)):
            raise ValueError(
                f"faces must be an (F, k) integer array, got shape {faces.shape}, dtype {faces.dtype}"
            )
        if not len(faces):
            raise ValueError("the mesh is empty: faces has no rows")
        flat_polys = Polygons(faces.astype(np.int64).ravel(), np.full(len(faces), faces.shape[1]))
        tri, origin, report, _, sides_out = _triangulate_flat(flat_polys, nv, check, v, report, sides)
        return tri, origin, report, flat_polys, sides_out
    else:
        try:
            arrays = [np.asarray(p) for p in faces]
        except TypeError as err:
            raise ValueError(
                f"faces must be an (F, k) array or a sequence of index sequences: {err}"
            ) from err
        for i, p in enumerate(arrays):
            if p.ndim != 1 or (p.size and not np.issubdtype(p.dtype, np.integer)):
                raise ValueError(f"face {i} is not a sequence of integer vertex indices: {p!r}")
        polys: Sequence = [p.astype(np.int64) for p in arrays]
    if not polys:
        raise ValueError("the mesh is empty: faces has no rows")
    sizes = np.array([len(p) for p in polys])
    flat = np.concatenate(polys) if sizes.sum() else np.zeros(0, np.int64)
    tri, origin, report, _, sides_out = _triangulate_flat(Polygons(flat, sizes), nv, check, v, report, sides)
    return tri, origin, report, polys, sides_out


def _triangulate_flat(polys: Polygons, nv: int, check: bool, v, report: RepairReport, sides: bool):
    """:func:`_triangulate` of polygons stored flat."""
    if not len(polys):
        raise ValueError("the mesh is empty: faces has no rows")
    sizes, flat = polys.sizes, polys.flat
    offsets = polys.offsets
    bad = (flat < 0) | (flat >= nv)
    if check and bad.any():
        owner = np.repeat(np.arange(len(polys)), sizes)
        raise ValueError(face_range_message(np.unique(owner[bad]).tolist(), nv))
    tris, origins, side_list = [], [], []
    for k in np.unique(sizes):
        if k < 3:
            continue
        rows = np.flatnonzero(sizes == k)
        block = flat[offsets[rows][:, None] + np.arange(k)]
        srt = np.sort(block, axis=1)
        repeated = (srt[:, 1:] == srt[:, :-1]).any(1)
        clean, crow = block[~repeated], rows[~repeated]
        if k > 3:
            report.triangulated_faces += crow.tolist()
            split, fanned = _split_polygons(clean, v)
            tris.append(split.reshape(-1, 3))
            origins.append(np.repeat(crow, k - 2))
            report.fan_faces += crow[fanned].tolist()
        else:
            tris.append(clean)
            origins.append(crow)
        if sides:
            side_list += [clean[:, [j, (j + 1) % k]] for j in range(k)]
        for i in rows[repeated].tolist():
            report.repeated_index_faces.append(i)
            p = flat[offsets[i] : offsets[i] + k]
            keep = [p[0]] + [p[m] for m in range(1, len(p)) if p[m] != p[m - 1]]
            while len(keep) > 1 and keep[-1] == keep[0]:
                keep.pop()
            if len(keep) > 3:
                report.triangulated_faces.append(i)
            if len(keep) > 1:
                side_list.append(np.array([[keep[m], keep[(m + 1) % len(keep)]] for m in range(len(keep))]))
            if len(keep) > 3 and len(set(keep)) == len(keep):
                split, fanned = _split_polygons(np.array([keep], dtype=np.int64), v)
                tris.append(split.reshape(-1, 3))
                origins.append(np.full(len(keep) - 2, i))
                if len(fanned):
                    report.fan_faces.append(i)
                continue
            for j in range(1, len(keep) - 1):
                t = (keep[0], keep[j], keep[j + 1])
                if len(set(t)) == 3:  # a non-consecutive repeat leaves a degenerate fan triangle
                    tris.append(np.array([t], dtype=np.int64))
                    origins.append(np.array([i]))
    report.repeated_index_faces.sort()
    report.triangulated_faces.sort()
    report.fan_faces.sort()
    if tris:
        tri, origin = np.concatenate(tris), np.concatenate(origins)
        order = np.argsort(origin, kind="stable")  # triangles in the order of their faces
        tri, origin = tri[order], origin[order]
    else:
        tri, origin = np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    report.added_triangles = int(len(tri) - len(np.unique(origin)))
    sides_out = None
    if sides:
        pairs = np.concatenate(side_list).reshape(-1, 2) if side_list else np.zeros((0, 2), np.int64)
        pairs = pairs[pairs[:, 0] != pairs[:, 1]]
        sides_out = np.unique(np.sort(pairs, axis=1), axis=0).astype(np.int64)
    return np.ascontiguousarray(tri), origin.astype(np.int64), report, polys, sides_out
