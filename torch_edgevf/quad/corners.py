"""Corners of a boundary loop: which chart axis each boundary edge follows (see
:func:`torch_edgevf.quad.cones.boundary_axes`).

Each boundary edge of an open mesh is mapped onto an integer iso-line of the integer-grid
map; its *label* says which axis it follows. The label nearest the cross field, edge by
edge, follows every zig-zag of a jagged boundary: a short edge at 60 degrees to its
neighbours becomes a stair, a concave and a convex corner one short edge apart, and a vertex
where the boundary turns back a notch of 4 quarter turns. A stair much shorter than a quad
must be stretched to a quad in the map, and the rounding may put its corners at one integer
point (a folded map).

:func:`relabel_loops` changes the labels of a few edges of a loop by a quarter turn (the map
turns such an edge across the field), so that

* every vertex has 1 to 4 quarter turns, fewer than twice its triangles (each triangle's
  angle is below two quarter turns: the tip of an ear, a vertex of one triangle, has 1), and
* corners (vertices of other than 2 quarter turns) lie about a quad apart along the loop,

at a low cost (local descent over runs of up to 4 edges, from the nearest labels):
``4 sum_e l_e^2 ((rho_e - delta_e)^2 - rho_e^2)`` for the edges turned
(``l_e`` the edge's length in quads, ``rho_e`` its angle to the nearest axis of the field, in
quarter turns, ``delta_e`` the change of its label), plus ``(1 - l)^2 / max(l, 0.05)`` for
every stretch of length ``l < 1`` quad between two consecutive corners. A change of labels moves
quarter turns between the two ends of the edges turned, so the turns of every loop add up to
what they did, and the cones and the boundary still add up to the Euler characteristic.
"""

from __future__ import annotations

import numpy as np

__all__ = ["relabel_loops", "boundary_loops"]

_INFEASIBLE = 1e6
_TURN = 4.0  # weight of an edge turned across the field


def boundary_loops(a: np.ndarray, b: np.ndarray) -> list[np.ndarray]:
    """The boundary edges ``a[i] -> b[i]`` (indices ``i``) grouped into loops, in order."""
    out_of = {int(x): i for i, x in enumerate(a)}
    seen = np.zeros(a.shape[0], dtype=bool)
    loops = []
    for start in range(a.shape[0]):
        if seen[start]:
            continue
        loop = [start]
        seen[start] = True
        while True:
            nxt = out_of[int(b[loop[-1]])]
            if nxt == start:
                break
            loop.append(nxt)
            seen[nxt] = True
        loops.append(np.array(loop, dtype=np.int64))
    return loops


def _cost(delta, n0, length, rho, cap):
    """Cost of the label changes ``delta`` (per edge of a loop, in order; vertex ``i`` is the
    start of edge ``i``) and its turns."""
    n = n0 + np.roll(delta, 1) - delta
    bad = np.sum(np.maximum(1 - n, 0) + np.maximum(n - cap, 0))
    cost = float(np.sum(_TURN * length**2 * ((rho - delta) ** 2 - rho**2)))
    corner = np.flatnonzero(n != 2)
    if corner.size >= 2:
        cum = np.concatenate([[0.0], np.cumsum(length)])
        total = cum[-1]
        gaps = np.diff(np.concatenate([cum[corner], [cum[corner[0]] + total]]))
        short = gaps[gaps < 1]
        cost += float(np.sum((1 - short) ** 2 / np.maximum(short, 0.05)))
    return _INFEASIBLE * bad + cost, n


def _relabel_loop(n0, length, rho, cap, max_run: int = 4, sweeps: int = 50):
    """Label changes (each -1, 0 or 1) of one loop by local descent: turn runs of up to
    ``max_run`` consecutive edges by a quarter turn while that lowers the cost."""
    m = n0.shape[0]
    delta = np.zeros(m, dtype=np.int64)
    best, _ = _cost(delta, n0, length, rho, cap)
    for _ in range(sweeps):
        found = None
        for start in range(m):
            for run in range(1, min(max_run, m - 1) + 1):
                idx = (start + np.arange(run)) % m
                for step in (-1, 1):
                    trial = delta.copy()
                    trial[idx] += step
                    if np.abs(trial).max() > 1:
                        continue
                    c, _ = _cost(trial, n0, length, rho, cap)
                    if c < best - 1e-9 and (found is None or c < found[0]):
                        found = (c, trial)
        if found is None:
            break
        best, delta = found
    return delta


def relabel_loops(loops, n0: np.ndarray, length: np.ndarray, rho: np.ndarray, fan: np.ndarray):
    """Label changes ``delta`` (per boundary edge) and turns ``n`` (per loop position) for
    every loop (module docstring).

    ``loops``: edge indices in order (:func:`boundary_loops`); ``n0`` (per edge) the quarter
    turns at the edge's start with the nearest labels; ``length`` the edges' lengths in quads;
    ``rho`` their angles to the nearest axis of the field in quarter turns; ``fan`` the number
    of triangles at the edge's start. Returns ``delta`` (per edge) and the turns at every
    edge's start. A loop of three edges, or one that no change brings within those bounds,
    keeps its labels and its turns ``n0``.
    """
    delta = np.zeros(n0.shape[0], dtype=np.int64)
    turns = n0.copy()
    for loop in loops:
        if loop.size < 4:  # a hole of one triangle: a slit, whatever its labels
            continue
        cap = np.minimum(4, 2 * fan[loop] - 1)
        d = _relabel_loop(n0[loop], length[loop], rho[loop], cap)
        if _cost(d, n0[loop], length[loop], rho[loop], cap)[0] >= _INFEASIBLE:
            continue
        delta[loop] = d
        turns[loop] = n0[loop] + np.roll(d, 1) - d
    return delta, turns
