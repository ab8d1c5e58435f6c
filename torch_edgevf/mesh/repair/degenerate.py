"""Zero-area faces of closed manifold meshes removed by edge collapse (extrinsic; see :func:`repair`)."""

from __future__ import annotations

import numpy as np
import torch

from ..topology import Topology


def scaled_edges(p: np.ndarray) -> np.ndarray:
    """The edge vectors ``(F, 3, 3)`` of the triangles ``p`` ``(F, 3, 3)`` (edge ``k``
    opposite corner ``k``), each triangle's scaled by a power of two near its largest
    component: exact, and their products neither overflow nor underflow at any scale."""
    e = p[:, [2, 0, 1]] - p[:, [1, 2, 0]]
    _, exponent = np.frexp(np.abs(e).max(axis=(1, 2)))
    return np.ldexp(e, -exponent[:, None, None])


def find_degenerate_faces(verts, faces) -> np.ndarray:
    """Indices of the faces that the operators reject as zero-area (same criterion, float64,
    at any scale)."""
    v = np.asarray(verts, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    e = scaled_edges(v[f])
    lmax = np.linalg.norm(e, axis=2).max(1)
    double_area = np.linalg.norm(np.cross(e[:, 0], e[:, 1]), axis=1)
    return np.nonzero(double_area <= 8 * np.finfo(np.float64).eps * lmax * lmax)[0]


def repair_degenerate_faces(verts, faces) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int]]:
    """Repair zero-area faces of a closed manifold mesh by collapsing one of their short edges.

    Procedure, for each zero-area face in turn: its edges, shortest first, are tried as
    an edge collapse ``u -> w``, both directions for each edge. A collapse moves no
    vertex: ``u`` is removed, every face using ``u`` uses ``w`` instead, and the
    two faces sharing the edge ``uw`` (the degenerate face and its neighbour) are
    deleted. A collapse is accepted only if the link condition holds (``u`` and ``w``
    share exactly two neighbours), no face becomes degenerate and the result is still a
    valid :class:`~torch_edgevf.mesh.topology.Topology` (manifold, oriented); otherwise the
    next edge is tried, and ``ValueError`` is raised when none works. The Euler
    characteristic is unchanged (one vertex, three edges and two faces fewer).

    Returns
    -------
    verts : (V', 3) array, the kept vertices (a copy)
    faces : (F', 3) int64 array, reindexed
    kept : (V',) int64 array, original index of each kept vertex (to carry per-vertex data)
    repaired : list of the original indices of the repaired faces
    """
    v = np.asarray(verts)
    f = np.array(faces, dtype=np.int64)
    orig_face = np.arange(len(f))
    kept = np.arange(len(v))
    repaired = []
    while True:
        bad = find_degenerate_faces(v, f)
        if len(bad) == 0:
            break
        t = int(bad[0])
        original = int(orig_face[t])
        p = v[f[t]].astype(np.float64)
        lengths = np.linalg.norm(p[[2, 0, 1]] - p[[1, 2, 0]], axis=1)  # opposite each corner
        done = False
        for k in np.argsort(lengths):  # edge opposite corner k: (f[t, k+1], f[t, k+2])
            e0, e1 = int(f[t, (k + 1) % 3]), int(f[t, (k + 2) % 3])
            for u, w in ((e0, e1), (e1, e0)):
                g = _collapse(v, f, u, w)
                if g is not None:
                    f = g[0]
                    orig_face = orig_face[g[1]]
                    done = True
                    break
            if done:
                break
        if not done:
            raise ValueError(f"cannot repair the zero-area face {original}: no valid edge collapse")
        repaired.append(original)
    used = np.unique(f)
    remap = np.full(len(v), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return np.array(v[used]), remap[f], kept[used], repaired


def _collapse(v: np.ndarray, f: np.ndarray, u: int, w: int):
    """Faces after collapsing vertex ``u`` into ``w`` (positions unchanged), or None if invalid."""

    def neighbours(x):
        rows = f[(f == x).any(1)]
        return set(rows.ravel().tolist()) - {x}

    if len(neighbours(u) & neighbours(w)) != 2:
        return None
    keep = ~((f == u).any(1) & (f == w).any(1))
    g = np.where(f == u, w, f)[keep]
    if len(find_degenerate_faces(v, g)):
        return None
    try:
        Topology(torch.from_numpy(g), num_vertices=len(v))
    except ValueError:
        return None
    return g, np.nonzero(keep)[0]
