"""Field glyphs: the n directions of a field at face barycenters."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import torch

from .scene import _GLYPH_COLOR, Picture, _Scene

log = logging.getLogger(__name__)

# --------------------------------------------------------------------------- field glyphs


def face_glyph_directions(verts, faces, z, n: int = 1) -> torch.Tensor:
    """The ``n`` directions of an edge field at face barycenters, as 3D vectors.

    At the barycenter every Crouzeix-Raviart hat ``phi_k = 1 - 2 b_k`` is ``1/3``, so the
    representation vector there is ``w_T = 1/3 sum_k u_k^n z_{e_k}`` in the face frame
    (:func:`torch_edgevf.fields.face_values`); its ``n`` angle roots
    ``|w| e^{i (arg w + 2 pi k) / n}`` are drawn in the frame ``(X_T, N_T x X_T)``.

    Returns
    -------
    (F, n, 3) tensor (the magnitude of each direction is ``|w_T|``).
    """
    from ..fields.representation import face_directions

    return face_directions(verts, faces, z, n)


def _glyph_polygons(center, normal, dirs, length, n):
    """Thin tapered quads (G, 4, 3) for directions ``dirs`` (F, n, 3) of unit-ish length."""
    side = np.cross(normal[:, None, :], dirs)  # (F, n, 3)
    width = 0.09 * length
    c = center[:, None, :]
    if n == 1:  # an arrow through the barycenter: wide tail, sharp head
        tail, head = c - 0.5 * length * dirs, c + 0.5 * length * dirs
        quad = [
            tail - width * side,
            tail + width * side,
            head + 0.15 * width * side,
            head - 0.15 * width * side,
        ]
    else:  # n spokes from the barycenter
        head = c + 0.5 * length * dirs
        quad = [
            c - 0.6 * width * side,
            c + 0.6 * width * side,
            head + 0.2 * width * side,
            head - 0.2 * width * side,
        ]
    return np.stack(quad, axis=2).reshape(-1, 4, 3)


def _check_glyph_options(glyph_spacing, glyph_scale, every) -> None:
    if not isinstance(every, int) or isinstance(every, bool) or every < 1:
        raise ValueError(f"every must be a positive integer, got {every!r}")
    if not isinstance(glyph_scale, (int, float)) or not glyph_scale > 0 or not math.isfinite(glyph_scale):
        raise ValueError(f"glyph_scale must be a positive number, got {glyph_scale!r}")
    if glyph_spacing is not None and (
        not isinstance(glyph_spacing, (int, float)) or not math.isfinite(glyph_spacing) or glyph_spacing < 2
    ):
        raise ValueError(f"glyph_spacing must be a number of pixels >= 2 or None, got {glyph_spacing!r}")


def _glyph_faces(scene: _Scene, candidates: np.ndarray, spacing: float | None) -> np.ndarray:
    """Of the faces ``candidates``, the nearest one per square cell of ``spacing`` pixels."""
    if spacing is None or not candidates.size:
        return candidates
    cell = spacing * scene.pixel
    xy, depth = scene.cam.project(scene.center[candidates])
    ij = np.floor((xy - scene.mid) / cell).astype(np.int64)
    key = (ij[:, 0] - ij[:, 0].min()) * (int(ij[:, 1].max() - ij[:, 1].min()) + 1) + (
        ij[:, 1] - ij[:, 1].min()
    )
    order = np.lexsort((-depth, key))  # by cell, nearest first
    first = np.ones(len(order), dtype=bool)
    first[1:] = key[order][1:] != key[order][:-1]
    return np.sort(candidates[order[first]])


def _add_glyphs(
    scene: _Scene, verts_t, topo, z, n, spacing, glyph_scale, scale_by_magnitude, every, color
) -> None:
    """Glyphs of the field ``z`` on the visible faces, one per screen cell (see render_field)."""
    _check_glyph_options(spacing, glyph_scale, every)
    dirs = face_glyph_directions(verts_t, topo, z, n).detach().cpu().to(torch.float64).numpy()
    mag = np.linalg.norm(dirs[:, 0], axis=-1)
    unit = dirs / np.where(mag > 0, mag, 1.0)[:, None, None]
    face_edge = np.linalg.norm(scene.p - scene.p[:, [1, 2, 0]], axis=-1).mean(axis=1)  # (F,)
    keep = scene.front & (np.arange(len(scene.f)) % every == 0)
    if scale_by_magnitude:
        top = mag.max()
        rel = mag / top if top > 0 else np.zeros_like(mag)
        keep &= rel > 1e-3
    else:
        rel = np.ones_like(mag)
        keep &= mag > 0
    idx = np.flatnonzero(keep)
    if spacing is not None and idx.size:
        # one face per screen cell; its glyph, as long as the cell, goes over every face
        # where its barycenter is visible (drawn in the face's painter slot, a glyph
        # longer than its face would be cut by the neighbours drawn after it)
        idx = _glyph_faces(scene, idx, spacing)
        idx = idx[scene.visible(scene.center[idx], scene.normal[idx], tol=0.5 * face_edge[idx].mean())]
        reach = np.full(len(idx), spacing * scene.pixel)
    else:
        reach = face_edge[idx]
    if not idx.size:
        return
    length = 0.8 * glyph_scale * reach * rel[idx]
    lift = 1e-3 * face_edge[idx, None] * scene.normal[idx]  # keep the glyph on the visible side
    quads = _glyph_polygons(scene.center[idx] + lift, scene.normal[idx], unit[idx], length[:, None, None], n)
    polys = scene.cam.project(quads.reshape(-1, 3))[0].reshape(-1, 4, 2)
    if spacing is None:
        scene.add_polygons(np.repeat(idx, n), polys, np.asarray(color, dtype=np.float64), layer=1)
    else:
        order = np.argsort(np.repeat(scene.face_depth[idx], n), kind="stable")
        scene.add_overlay(polys[order], color)
    log.info("glyphs on %d of %d faces", len(idx), len(scene.f))


def render_field(
    verts,
    faces,
    z,
    path,
    n: int = 1,
    *,
    glyph_spacing: float | None = 14.0,
    glyph_scale: float = 1.0,
    scale_by_magnitude: bool = False,
    every: int = 1,
    glyph_color=_GLYPH_COLOR,
    **options,
) -> Path:
    """Render an ``n``-direction edge field as glyphs at face barycenters.

    Each face of the shaded mesh gets ``n`` short segments, the directions of
    :func:`face_glyph_directions`, lying in the face plane; glyphs on faces turned away
    from the camera are not drawn, and nearer faces hide the others.

    Parameters
    ----------
    verts : (V, 3) tensor
    faces : (F, 3) integer tensor or Topology
    z : (E,) complex tensor, the representation vector (the field itself for ``n = 1``)
    path : where to write the PNG
    n : symmetry order
    glyph_spacing : pixels between glyphs: the image is cut in square cells of this size
        and each cell shows the glyph of the nearest visible face whose barycenter falls
        in it, so that the density on screen does not depend on the mesh resolution.
        ``None``: a glyph on every visible face.
    glyph_scale : glyph length in units of ``0.8 x`` the smaller of the cell and the
        face's mean edge length
    scale_by_magnitude : glyph length proportional to ``|w_T|`` / its maximum
        (else every glyph has the same length)
    every : consider every ``every``-th face only
    options : the camera and the image, as for :func:`~torch_edgevf.render.render_mesh`
        (:class:`~torch_edgevf.render.scene.Picture`)

    Returns
    -------
    pathlib.Path of the PNG.
    """
    picture = Picture(verts, faces, **options)
    picture.scene.add_faces()
    args = (glyph_spacing, glyph_scale, scale_by_magnitude, every, glyph_color)
    _add_glyphs(picture.scene, picture.verts, picture.topo, z, n, *args)
    return picture.draw(path)
