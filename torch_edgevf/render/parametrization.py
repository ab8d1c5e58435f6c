"""Checkerboards of a parametrization."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import torch

from .._validation import list_some
from ..mesh.topology import Topology
from .scene import _CHECKER, _FLIPPED, Picture

log = logging.getLogger(__name__)

# --------------------------------------------------------------------------- parametrization


def _subdivision(k: int):
    """Barycentric coordinates of the corners (T, 3, 3) of the k^2 sub-triangles."""
    tris = []
    for i in range(k):
        for j in range(k - i):
            tris.append([(i, j), (i + 1, j), (i, j + 1)])
            if j + i + 1 < k:
                tris.append([(i + 1, j), (i + 1, j + 1), (i, j + 1)])
    out = np.zeros((len(tris), 3, 3))
    for t, tri in enumerate(tris):
        for c, (i, j) in enumerate(tri):
            out[t, c] = [(k - i - j) / k, i / k, j / k]
    return out


def checker_scale(verts, faces, uv, cells: float = 15.0) -> float:
    """Checker squares per unit of uv for about ``cells`` squares across the mesh.

    The ratio ``r`` of summed uv to summed 3D edge lengths (per face, so seams and the
    layout of charts do not matter) turns the largest dimension ``D`` of the bounding box
    into a uv length ``r D``; the scale ``cells / (r D)`` is rounded to an integer when
    above 1, else to ``1/k``.
    """
    v = np.asarray(torch.as_tensor(verts).detach().cpu(), dtype=np.float64)
    f = np.asarray(
        faces.faces if isinstance(faces, Topology) else torch.as_tensor(faces).cpu(), dtype=np.int64
    )
    uv = np.asarray(torch.as_tensor(uv).detach().cpu(), dtype=np.float64)
    p = v[f]
    xyz_len = np.linalg.norm(p - p[:, [1, 2, 0]], axis=-1).sum()
    uv_len = np.linalg.norm(uv - uv[:, [1, 2, 0]], axis=-1).sum()
    extent = float((v.max(axis=0) - v.min(axis=0)).max())
    if not (xyz_len > 0 and uv_len > 0 and extent > 0):
        return 1.0
    raw = cells / (uv_len / xyz_len * extent)
    return float(max(1, round(raw))) if raw >= 1 else 1.0 / max(1, round(1 / raw))


def render_parametrization(
    verts,
    faces,
    uv,
    path,
    *,
    scale: float | str = "auto",
    subdivide: int | str = "auto",
    checker_cells: float = 15.0,
    colors=_CHECKER,
    flipped_color=_FLIPPED,
    **options,
) -> Path:
    """Render a parametrization as a checkerboard texture, its flipped faces marked.

    Each face is split into ``subdivide**2`` triangles; a triangle with centroid
    parameters ``(u, v)`` (linear in the face from the per-corner values) gets colour
    ``colors[(floor(scale u) + floor(scale v)) mod 2]``, Lambert-shaded. A face whose
    ``(u, v)`` triangle has negative signed area (flipped: the map folds over there) is
    drawn whole in ``flipped_color`` (red; ``None`` draws it as the others).

    Parameters
    ----------
    verts : (V, 3) tensor
    faces : (F, 3) integer tensor or Topology
    uv : (F, 3, 2) per-corner parameters (seams allowed)
    path : where to write the PNG
    scale : checker squares per unit of ``u`` and ``v``. ``"auto"``: about
        ``checker_cells`` squares across the mesh's largest dimension, from the ratio of
        the uv to the 3D edge lengths (seams and chart layout do not matter); rounded to an
        integer when above 1 (or to ``1/k``), so that squares of an integer-seamless
        parametrization meet along seams.
    subdivide : sub-triangles per face edge (1: one colour per face, at its barycenter).
        ``"auto"``: about 12 sub-triangles across a square, none smaller than 2 pixels,
        at most 16.
    checker_cells : squares across the mesh for ``scale="auto"``
    options : the camera and the image, as for :func:`~torch_edgevf.render.render_mesh`
        (:class:`~torch_edgevf.render.scene.Picture`)
        (``edges`` only with ``subdivide=1``)

    Returns
    -------
    pathlib.Path of the PNG.
    """
    if subdivide != "auto" and (
        not isinstance(subdivide, int) or isinstance(subdivide, bool) or not 1 <= subdivide <= 64
    ):
        raise ValueError(f"subdivide must be 'auto' or an integer in [1, 64], got {subdivide!r}")
    if scale != "auto" and (
        not isinstance(scale, (int, float))
        or isinstance(scale, bool)
        or not math.isfinite(scale)
        or scale <= 0
    ):
        raise ValueError(f"scale must be 'auto' or a positive number, got {scale!r}")
    if not isinstance(checker_cells, (int, float)) or not math.isfinite(checker_cells) or checker_cells <= 0:
        raise ValueError(f"checker_cells must be a positive number, got {checker_cells!r}")
    picture = Picture(verts, faces, **options)
    topo, scene = picture.topo, picture.scene
    v, f = scene.v, scene.f
    uv = np.asarray(torch.as_tensor(uv).detach().cpu(), dtype=np.float64)
    if uv.shape != (topo.num_faces, 3, 2):
        raise ValueError(f"uv must have shape ({topo.num_faces}, 3, 2) (per corner), got {uv.shape}")
    bad = np.flatnonzero(~np.isfinite(uv).reshape(len(uv), -1).all(1))
    if bad.size:
        raise ValueError(f"uv has NaN or Inf values at faces [{list_some(bad)}]")
    uv_edge = np.linalg.norm(uv - uv[:, [1, 2, 0]], axis=-1)  # (F, 3)
    if scale == "auto":
        scale = checker_scale(v, f, uv, checker_cells)
    scale = float(scale)
    if subdivide == "auto":
        squares_per_face = float(np.median(uv_edge.mean(axis=1))) * scale
        face_pixels = float(np.median(np.linalg.norm(scene.face_xy - scene.face_xy[:, [1, 2, 0]], axis=-1)))
        finest = max(1, min(16, math.ceil(face_pixels / scene.pixel / 2)))  # sub-triangles >= 2 pixels
        subdivide = int(np.clip(math.ceil(12 * squares_per_face), 1, finest))
        log.info("checker scale %g, %d sub-triangles per face edge", scale, subdivide)
    sub = _subdivision(int(subdivide))  # (T, 3, 3)
    centroid = sub.mean(axis=1)  # (T, 3)
    uvc = np.einsum("tk,fkd->ftd", centroid, uv)  # (F, T, 2)
    parity = np.floor(scale * uvc).sum(-1).astype(np.int64) % 2  # (F, T)
    palette = np.asarray(colors, dtype=np.float64)
    if palette.shape != (2, 3):
        raise ValueError(f"colors must be two RGB triples, got shape {palette.shape}")
    col = palette[parity] * scene.shade[:, None, None]  # (F, T, 3)
    if flipped_color is not None:
        a, b = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
        flipped = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0] < 0
        col[flipped] = np.asarray(flipped_color, dtype=np.float64) * scene.shade[flipped, None, None]
    pts = np.einsum("tck,fkd->ftcd", sub, scene.face_xy)  # (F, T, 3, 2)
    ntri = sub.shape[0]
    scene.add_polygons(np.repeat(np.arange(len(f)), ntri), pts.reshape(-1, 3, 2), col.reshape(-1, 3), layer=0)
    return picture.draw(path, picture.edges and subdivide == 1)
