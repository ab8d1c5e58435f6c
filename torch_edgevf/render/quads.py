"""Pictures of quad meshes: shaded quads with their edges, irregular vertices marked."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from .camera import _camera
from .scene import _DEFAULT_SIZE, _check_image, _Scene

__all__ = ["render_quad_mesh"]

_VALENCE_COLORS = {3: (0.20, 0.45, 0.95), 5: (0.95, 0.30, 0.20)}
_OTHER_COLOR = (0.95, 0.80, 0.10)


def render_quad_mesh(
    verts,
    quads,
    path,
    *,
    irregular: bool = True,
    up="auto",
    view="auto",
    elev: float | None = None,
    azim: float | None = None,
    camera=None,
    size: int | tuple[int, int] = _DEFAULT_SIZE,
    dpi: int = 100,
    background="white",
    title: str | None = None,
) -> Path:
    """Render a quad mesh to a PNG: shaded quads with dark edges; with ``irregular``, the
    interior vertices of valence 3 (blue), 5 (red) and others (yellow) as dots.

    Parameters
    ----------
    verts : (V, 3) tensor or array
    quads : (Q, 4) int tensor or array, counter-clockwise
    path : where to write the PNG
    irregular : mark the interior vertices whose valence is not 4
    up, view, elev, azim, camera, size, dpi, background, title : the camera and the image,
        as for every picture (:class:`~torch_edgevf.render.scene.Picture`); the quads need
        not form a valid triangle mesh (a quad with a repeated vertex is drawn as a triangle)

    Returns
    -------
    pathlib.Path of the PNG.
    """
    v = np.asarray(torch.as_tensor(verts).detach().cpu(), dtype=np.float64)
    q = np.asarray(torch.as_tensor(quads).detach().cpu(), dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or not np.isfinite(v).all():
        raise ValueError(f"verts must be a finite (V, 3) array, got shape {v.shape}")
    if q.ndim != 2 or q.shape[1] != 4 or q.shape[0] == 0:
        raise ValueError(f"quads must have shape (Q, 4) with Q >= 1, got {q.shape}")
    if q.min() < 0 or q.max() >= v.shape[0]:
        raise ValueError(f"quad indices must lie in [0, {v.shape[0]})")
    size = _check_image(size, dpi)
    tri = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    used = np.unique(q)
    if used.size < v.shape[0]:  # the picture's mesh: the vertices the quads use
        remap = np.full(v.shape[0], -1, dtype=np.int64)
        remap[used] = np.arange(used.size)
        v, q, tri = v[used], remap[q], remap[tri]
    scene = _Scene(v, tri, _camera(camera, v, tri, up, view, elev, azim))
    scene.frame(size)
    nq = q.shape[0]
    colors = 0.5 * (scene.face_color[:nq] + scene.face_color[nq:])
    scene.add_polygons(np.arange(nq), scene.xy[q], colors, layer=0)
    if irregular:
        valence = np.bincount(q.ravel(), minlength=v.shape[0])
        edges = np.sort(np.stack([q, np.roll(q, -1, 1)], -1).reshape(-1, 2), 1)
        uniq, count = np.unique(edges, axis=0, return_counts=True)
        boundary = np.zeros(v.shape[0], dtype=bool)
        boundary[uniq[count == 1].ravel()] = True
        marked = np.flatnonzero((valence != 4) & (valence > 0) & ~boundary)
        normals = np.zeros_like(v)
        np.add.at(normals, tri.ravel(), np.repeat(scene.normal, 3, axis=0))
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
        lengths = np.linalg.norm(v[uniq[:, 0]] - v[uniq[:, 1]], axis=1)
        seen = scene.visible(v[marked], normals[marked], tol=0.5 * float(lengths.mean()))
        for i in marked[seen]:
            color = _VALENCE_COLORS.get(int(valence[i]), _OTHER_COLOR)
            scene.add_marker(scene.xy[i], 4.0 * scene.pixel, color)
    return scene.draw(path, size, dpi, background, title, True)  # the quad edges, not the diagonals
