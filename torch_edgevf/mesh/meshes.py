"""Procedural meshes with fixed seeds, for tests, examples and benchmarks."""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["icosphere", "grid", "sphere_delaunay", "ellipsoid", "cylinder"]


def _icosahedron() -> tuple[np.ndarray, np.ndarray]:
    t = (1 + 5**0.5) / 2
    v = np.array(
        [
            [-1, t, 0],
            [1, t, 0],
            [-1, -t, 0],
            [1, -t, 0],
            [0, -1, t],
            [0, 1, t],
            [0, -1, -t],
            [0, 1, -t],
            [t, 0, -1],
            [t, 0, 1],
            [-t, 0, -1],
            [-t, 0, 1],
        ],
        dtype=np.float64,
    )
    f = np.array(
        [
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ],
        dtype=np.int64,
    )
    return v / np.linalg.norm(v, axis=1, keepdims=True), f


def _subdivide(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One 1-to-4 midpoint subdivision; new vertices are projected to the unit sphere."""
    nv = v.shape[0]
    a, b, c = f[:, 0], f[:, 1], f[:, 2]
    pairs = np.stack([np.stack([b, c], 1), np.stack([c, a], 1), np.stack([a, b], 1)], 1).reshape(-1, 2)
    pairs.sort(axis=1)
    keys, inv = np.unique(pairs[:, 0] * nv + pairs[:, 1], return_inverse=True)
    mid = (v[keys // nv] + v[keys % nv]) / 2
    mid /= np.linalg.norm(mid, axis=1, keepdims=True)
    m = inv.reshape(-1, 3) + nv
    ma, mb, mc = m[:, 0], m[:, 1], m[:, 2]  # midpoints opposite a, b, c
    faces = np.concatenate(
        [
            np.stack([a, mc, mb], 1),
            np.stack([b, ma, mc], 1),
            np.stack([c, mb, ma], 1),
            np.stack([ma, mb, mc], 1),
        ]
    )
    return np.concatenate([v, mid]), faces


def icosphere(level: int = 3, dtype: torch.dtype = torch.float64) -> tuple[torch.Tensor, torch.Tensor]:
    """The unit icosphere: ``20 * 4**level`` faces, vertices exactly on the sphere.

    Level 6 has 81,920 faces (122,880 edges); level 8 has 1,310,720 faces.

    Returns
    -------
    verts : (V, 3) tensor of ``dtype``
    faces : (F, 3) int64 tensor, counter-clockwise seen from outside
    """
    if level < 0:
        raise ValueError(f"level must be >= 0, got {level}")
    v, f = _icosahedron()
    for _ in range(level):
        v, f = _subdivide(v, f)
    return torch.from_numpy(v).to(dtype), torch.from_numpy(f)


def grid(nx: int = 8, ny: int = 8, size=(1.0, 1.0), dtype: torch.dtype = torch.float64):
    """A flat triangulated rectangle ``[0, sx] x [0, sy]`` in the plane z = 0, with boundary.

    Returns ``(verts (V, 3), faces (F, 3))`` with ``V = (nx + 1) (ny + 1)``, ``F = 2 nx ny``.
    """
    if nx < 1 or ny < 1:
        raise ValueError(f"grid needs nx, ny >= 1, got {nx}, {ny}")
    x, y = np.meshgrid(np.linspace(0, size[0], nx + 1), np.linspace(0, size[1], ny + 1), indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    idx = np.arange((nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return torch.from_numpy(v).to(dtype), torch.from_numpy(f)


def _outward(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Orient the faces of a convex hull outwards: normals away from an interior point."""
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    inside = v[np.unique(f)].mean(0)  # the mean of the hull's vertices (the origin may lie outside)
    flip = (n * (v[f].mean(1) - inside)).sum(1) < 0
    f = f.copy()
    f[flip] = f[flip][:, [0, 2, 1]]
    return f


def sphere_delaunay(num_points: int = 500, seed: int = 0, dtype: torch.dtype = torch.float64):
    """A random Delaunay triangulation of the unit sphere (convex hull of uniform points)."""
    from scipy.spatial import ConvexHull

    rng = np.random.default_rng(seed)
    v = rng.normal(size=(num_points, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    f = _outward(v, ConvexHull(v).simplices.astype(np.int64))
    return torch.from_numpy(v).to(dtype), torch.from_numpy(f)


def ellipsoid(axes=(1.0, 0.7, 0.5), level: int = 3, dtype: torch.dtype = torch.float64):
    """An icosphere scaled to the ellipsoid with the given semi-axes."""
    v, f = icosphere(level, dtype)
    return v * torch.tensor(axes, dtype=dtype), f


def cylinder(
    radius: float = 1.0,
    height: float = 2.0,
    n_around: int = 32,
    n_along: int = 16,
    dtype: torch.dtype = torch.float64,
):
    """An open cylinder around the z axis (two boundary loops), outward oriented."""
    theta = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    z = np.linspace(-height / 2, height / 2, n_along + 1)
    t, zz = np.meshgrid(theta, z, indexing="ij")
    v = np.stack([radius * np.cos(t).ravel(), radius * np.sin(t).ravel(), zz.ravel()], 1)
    idx = np.arange(n_around * (n_along + 1)).reshape(n_around, n_along + 1)
    nxt = np.roll(idx, -1, axis=0)
    a, b = idx[:, :-1].ravel(), nxt[:, :-1].ravel()
    c, d = nxt[:, 1:].ravel(), idx[:, 1:].ravel()
    f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return torch.from_numpy(v).to(dtype), torch.from_numpy(f)
