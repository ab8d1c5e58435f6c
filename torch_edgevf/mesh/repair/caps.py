"""Zero-area caps re-triangulated by an edge flip: no vertex moved, the surface unchanged.

A cap is a triangle ``(a, b, c)`` whose corner ``c`` lies on its longest edge ``ab``
(collinear corners, zero area) but not on ``a`` or ``b``. With the triangle ``(b, a, d)``
across ``ab``, the quadrilateral ``a, d, b, c`` is the neighbour's triangle itself, and
flipping ``ab`` into ``cd`` covers it with ``(a, d, c)`` and ``(d, b, c)``, both of
positive area when ``d`` is off the line ``ab``. The positions, the covered surface and
the winding are unchanged, and the file written from the result holds no zero-area face
there, so the operators accept it without mollified lengths.
"""

from __future__ import annotations

import numpy as np

from .degenerate import find_degenerate_faces, scaled_edges


def flip_caps(v: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """Flip the longest edge of every zero-area cap that has a neighbour across it.

    ``faces`` index ``v`` and form a manifold, consistently oriented mesh. Returns the
    faces (a copy when changed; the triangles stay in their rows, the cap's row holding
    ``(a, d, c)`` and its neighbour's ``(d, b, c)``) and the rows of the flipped caps.
    A flip is made only when both new triangles pass the operators' area test and the
    edge ``cd`` is not an edge already, and each face takes part in one flip at most (so
    that every new triangle lies in a cap and its neighbour); other zero-area faces are
    left as they are.
    """
    flipped: list[int] = []
    bad = find_degenerate_faces(v, faces)
    if not len(bad):
        return faces, flipped
    faces = faces.copy()
    nv = len(v)
    half = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    directed = {int(k): i for i, k in enumerate(half[:, 0] * nv + half[:, 1])}
    undirected = set((np.minimum(half[:, 0], half[:, 1]) * nv + np.maximum(half[:, 0], half[:, 1])).tolist())
    touched: set[int] = set()  # faces already flipped (their entries in the maps are stale)
    for t in bad.tolist():
        if t in touched:
            continue
        f = faces[t]
        lengths = np.linalg.norm(scaled_edges(v[f][None])[0], axis=1)  # opposite each corner
        k = int(np.argmax(lengths))
        c, a, b = int(f[k]), int(f[(k + 1) % 3]), int(f[(k + 2) % 3])
        if lengths[(k + 1) % 3] == 0 or lengths[(k + 2) % 3] == 0:
            continue  # c is on a or b: a needle, not a cap
        across = directed.get(b * nv + a)
        if across is None or across // 3 == t or across // 3 in touched:
            continue
        g = across // 3
        d = int(faces[g, (across % 3 + 2) % 3])
        if d in (a, b, c) or min(c, d) * nv + max(c, d) in undirected:
            continue
        new = np.array([[a, d, c], [d, b, c]], dtype=faces.dtype)
        if len(find_degenerate_faces(v, new)):
            continue
        faces[t], faces[g] = new
        flipped.append(t)
        touched.update((t, g))
        undirected.add(min(c, d) * nv + max(c, d))
    return faces, flipped
