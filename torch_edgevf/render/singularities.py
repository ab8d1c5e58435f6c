"""Singularity markers: discs at the faces and vertices with a nonzero index."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import torch

from .._validation import list_some
from .field import _add_glyphs
from .scene import _GLYPH_COLOR, _NEGATIVE, _POSITIVE, Picture

log = logging.getLogger(__name__)

# --------------------------------------------------------------------------- singularities


def _index_vector(x, count: int, name: str) -> np.ndarray | None:
    if x is None:
        return None
    a = np.asarray(torch.as_tensor(x).detach().cpu(), dtype=np.float64)
    if a.shape != (count,):
        raise ValueError(f"{name} must have shape ({count},), got {a.shape}")
    bad = np.flatnonzero(~np.isfinite(a))
    if bad.size:
        raise ValueError(f"{name} has NaN or Inf values at [{list_some(bad)}]")
    return a


def render_singularities(
    verts,
    faces,
    path,
    face_index=None,
    vertex_index=None,
    *,
    z=None,
    n: int = 1,
    marker_scale: float = 1.0,
    glyph_spacing: float | None = 14.0,
    **options,
) -> Path:
    """Render singularities: positive indices green, negative red, sized by ``|index|``.

    Markers sit at face barycenters (``face_index``) and vertices (``vertex_index``);
    hidden ones (facing away, or behind a nearer part of the mesh) are not drawn.

    Parameters
    ----------
    verts : (V, 3) tensor
    faces : (F, 3) integer tensor or Topology
    path : where to write the PNG
    face_index : (F,) indices (e.g. :attr:`Singularities.face_index`), optional
    vertex_index : (V,) indices, optional
    z : optional (E,) representation vector, also drawn as glyphs (with ``n``)
    marker_scale : marker radius in units of 5 pixels (up to twice that for the
        largest ``|index|``)
    glyph_spacing : pixels between the glyphs of ``z`` (see :func:`render_field`)
    options : the camera and the image, as for :func:`~torch_edgevf.render.render_mesh`
        (:class:`~torch_edgevf.render.scene.Picture`)

    Returns
    -------
    pathlib.Path of the PNG.
    """
    if not isinstance(marker_scale, (int, float)) or not math.isfinite(marker_scale) or marker_scale <= 0:
        raise ValueError(f"marker_scale must be a positive number, got {marker_scale!r}")
    picture = Picture(verts, faces, **options)
    verts_t, topo, scene = picture.verts, picture.topo, picture.scene
    v, f, cam = scene.v, scene.f, scene.cam
    fi = _index_vector(face_index, topo.num_faces, "face_index")
    vi = _index_vector(vertex_index, topo.num_vertices, "vertex_index")
    scene.add_faces()
    if z is not None:  # the field's glyphs under the markers
        _add_glyphs(scene, verts_t, topo, z, n, glyph_spacing, 1.0, False, 1, _GLYPH_COLOR)
    edge_len = np.linalg.norm(scene.p - scene.p[:, [1, 2, 0]], axis=-1).mean()
    points, normals, values = [], [], []
    if fi is not None:
        sel = np.flatnonzero(np.abs(fi) > 1e-9)
        points.append(scene.center[sel])
        normals.append(scene.normal[sel])
        values.append(fi[sel])
    if vi is not None:
        sel = np.flatnonzero(np.abs(vi) > 1e-9)
        vn = np.zeros_like(v)
        np.add.at(vn, f.ravel(), np.repeat(scene.normal, 3, axis=0))
        vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)
        points.append(v[sel])
        normals.append(vn[sel])
        values.append(vi[sel])
    if points:
        pts, nrm, val = np.concatenate(points), np.concatenate(normals), np.concatenate(values)
        shown = scene.visible(pts, nrm, tol=0.5 * edge_len)
        radius = 5.0 * marker_scale * scene.pixel
        xy = cam.project(pts)[0]
        smallest = max(float(np.abs(val).min()), 1e-12)
        for k in np.flatnonzero(shown):
            r = radius * min(2.0, 0.5 + 0.5 * abs(val[k]) / smallest)
            scene.add_marker(xy[k], r, _POSITIVE if val[k] > 0 else _NEGATIVE)
        log.info("%d of %d singular regions visible", int(shown.sum()), len(pts))
    return picture.draw(path)
