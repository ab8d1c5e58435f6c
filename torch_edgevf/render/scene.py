"""The painter: projected faces drawn back to front with a Lambert shade, overlays, Agg."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import torch

from .._validation import list_some
from ..mesh.topology import Topology
from .camera import Camera, _camera, _mesh

log = logging.getLogger(__name__)

_BASE_COLOR = (0.72, 0.78, 0.86)
_BACK_COLOR = (0.86, 0.70, 0.55)
_GLYPH_COLOR = (0.08, 0.08, 0.12)
_POSITIVE = (0.10, 0.65, 0.20)
_NEGATIVE = (0.85, 0.10, 0.10)
_CHECKER = ((0.95, 0.95, 0.95), (0.20, 0.35, 0.75))
_FLIPPED = (0.90, 0.15, 0.10)
_AMBIENT = 0.3
_SUPERSAMPLE = 3
_DEFAULT_SIZE = (800, 600)


# --------------------------------------------------------------------------- mesh


def _face_frames(v: np.ndarray, f: np.ndarray):
    p = v[f]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    norm = np.linalg.norm(cross, axis=1, keepdims=True)
    normal = cross / np.where(norm > 0, norm, 1.0)
    return p, normal, p.mean(axis=1)


class _Scene:
    """Projected faces, their shades and draw order, plus overlays, drawn with Agg."""

    def __init__(self, v, f, cam: Camera, base_color=_BASE_COLOR, back_color=_BACK_COLOR):
        self.cam = cam
        self.v, self.f = v, f
        self.p, self.normal, self.center = _face_frames(v, f)
        self.xy, depth = cam.project(v)
        self.face_xy = self.xy[f]  # (F, 3, 2)
        self.face_depth = depth[f].mean(axis=1)
        self.front = self.normal @ cam.view > 0
        cos = self.normal @ cam.light()
        shade = np.where(self.front, np.maximum(cos, 0.0), np.maximum(-cos, 0.0))
        self.shade = _AMBIENT + (1 - _AMBIENT) * shade
        base = np.where(self.front[:, None], np.asarray(base_color), np.asarray(back_color))
        self.face_color = base * self.shade[:, None]
        # polygons drawn in order of (face depth, layer): a face, then what lies on it
        self.items: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]] = []
        self.markers: list[tuple[np.ndarray, float, object]] = []
        self.overlay: list[tuple[np.ndarray, np.ndarray]] = []  # polygons on top of every face
        self.frame((1, 1))

    def frame(self, size: tuple[int, int], top: int = 0) -> None:
        """Fit the drawing to an image of ``size`` (width, height) less ``top`` pixels for a title.

        Sets the limits (``mid``, ``half``) and ``pixel``, the world length of a pixel.
        """
        w, h = size
        top = min(top, h // 4)
        lo, hi = self.xy.min(axis=0), self.xy.max(axis=0)
        half_w = max((hi - lo)[0] / 2, (hi - lo)[1] / 2 * w / (h - top), 1e-12) * 1.06
        self.pixel = 2 * half_w / w
        self.half = np.array([half_w, half_w * h / w])
        self.mid = (lo + hi) / 2 + np.array([0.0, top / 2 * self.pixel])

    def add_faces(self, face_color=None):
        colors = self.face_color if face_color is None else face_color
        polys = self.face_xy
        self.add_polygons(np.arange(len(self.f)), polys, colors, layer=0)

    def add_polygons(self, owner: np.ndarray, polys: np.ndarray, colors: np.ndarray, layer: int):
        """Polygons ``(P, k, 2)`` lying on faces ``owner`` (P,), drawn right after them."""
        colors = np.broadcast_to(np.asarray(colors, dtype=np.float64), (len(owner), 3))
        self.items.append((owner, polys, colors, np.full(len(owner), layer), len(self.items)))

    def visible(self, points: np.ndarray, normals: np.ndarray, tol: float) -> np.ndarray:
        """Points (P, 3) on the surface, with normals, that no nearer face hides."""
        xy, depth = self.cam.project(points)
        ok = normals @ self.cam.view > 0
        fxy = self.face_xy[self.front]
        fdepth = self.cam.project(self.p[self.front].reshape(-1, 3))[1].reshape(-1, 3)
        if not len(fxy):
            return ok
        a, b, c = fxy[:, 0], fxy[:, 1], fxy[:, 2]
        det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
        safe = np.where(np.abs(det) > 1e-300, det, 1.0)
        for start in range(0, len(points), 256):
            q = xy[start : start + 256, None, :]  # (Q, 1, 2)
            l1 = (
                (q[..., 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (q[..., 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
            ) / safe
            l2 = (
                (b[:, 0] - a[:, 0]) * (q[..., 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (q[..., 0] - a[:, 0])
            ) / safe
            l0 = 1 - l1 - l2
            inside = (l0 > 1e-9) & (l1 > 1e-9) & (l2 > 1e-9) & (np.abs(det) > 1e-300)
            zq = l0 * fdepth[:, 0] + l1 * fdepth[:, 1] + l2 * fdepth[:, 2]
            hidden = (inside & (zq > depth[start : start + 256, None] + tol)).any(axis=1)
            ok[start : start + 256] &= ~hidden
        return ok

    def add_marker(self, xy: np.ndarray, radius: float, color):
        self.markers.append((xy, radius, color))

    def add_overlay(self, polys: np.ndarray, colors) -> None:
        """Polygons ``(P, k, 2)`` drawn over every face, in the given order."""
        colors = np.broadcast_to(np.asarray(colors, dtype=np.float64), (len(polys), 3))
        self.overlay.append((polys, colors))

    def draw(self, path, size: tuple[int, int], dpi: int, background, title: str | None, edges: bool) -> Path:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.collections import PolyCollection
        from matplotlib.figure import Figure
        from matplotlib.patches import Circle

        owners = np.concatenate([it[0] for it in self.items])
        layers = np.concatenate([it[3] for it in self.items])
        polys: list = []
        colors = np.concatenate([it[2] for it in self.items])
        for it in self.items:
            polys.extend(list(it[1]))
        order = np.lexsort((layers, self.face_depth[owners]))
        polys = [polys[i] for i in order]
        colors = colors[order]
        is_face = layers[order] == 0

        ss = _SUPERSAMPLE
        fig = Figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi * ss, facecolor=background)
        canvas = FigureCanvasAgg(fig)
        ax = fig.add_axes((0, 0, 1, 1))
        ax.set_axis_off()
        ax.set_facecolor(background)
        # aliased polygons at ss x the resolution, box-filtered down: smooth silhouettes
        # and no anti-aliasing seams between neighbouring triangles
        edgecolors = np.where(is_face[:, None], 0.35 * colors, colors) if edges else "none"
        coll = PolyCollection(
            polys,
            facecolors=colors,
            edgecolors=edgecolors,
            linewidths=np.where(is_face, 0.4, 0.0) if edges else 0.0,
            antialiased=False,
        )
        ax.add_collection(coll)
        for over, over_colors in self.overlay:
            ax.add_collection(
                PolyCollection(
                    list(over), facecolors=over_colors, edgecolors="none", antialiased=False, zorder=2
                )
            )
        for xy, radius, color in self.markers:
            ax.add_patch(
                Circle(
                    (float(xy[0]), float(xy[1])),
                    radius,
                    facecolor=color,
                    edgecolor="black",
                    linewidth=0.6,
                    zorder=3,
                )
            )
        self.frame(size, 24 if title else 0)
        ax.set_xlim(self.mid[0] - self.half[0], self.mid[0] + self.half[0])
        ax.set_ylim(self.mid[1] - self.half[1], self.mid[1] + self.half[1])
        ax.set_aspect("equal")
        if title:
            ax.text(0.02, 0.98, title, transform=ax.transAxes, va="top", ha="left", fontsize=9)
        canvas.draw()
        rgba = np.asarray(canvas.buffer_rgba(), dtype=np.float64)
        h, w = rgba.shape[0] // ss, rgba.shape[1] // ss
        image = rgba[: h * ss, : w * ss].reshape(h, ss, w, ss, 4).mean(axis=(1, 3)) / 255.0
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        from matplotlib.image import imsave

        imsave(path, np.clip(image[..., :3], 0.0, 1.0), format="png")
        log.info(
            "wrote %s (%d faces, %d overlay polygons, %d markers)",
            path,
            len(self.f),
            int((~is_face).sum()),
            len(self.markers),
        )
        return path


def _check_image(size, dpi) -> tuple[int, int]:
    """``size`` (an int for a square, or (width, height)) as (width, height)."""
    pair = (size, size) if isinstance(size, int) else tuple(size) if isinstance(size, (tuple, list)) else ()
    if len(pair) != 2 or not all(
        isinstance(x, int) and not isinstance(x, bool) and 16 <= x <= 8192 for x in pair
    ):
        raise ValueError(
            f"size must be a number of pixels or a (width, height) pair, each in [16, 8192], got {size!r}"
        )
    if not isinstance(dpi, int) or isinstance(dpi, bool) or dpi <= 0:
        raise ValueError(f"dpi must be a positive integer, got {dpi!r}")
    return pair


class Picture:
    """What every picture shares: the mesh, the camera, the image and its caption.

    The keyword options of every ``render_*`` function (``**options``):

    up, view, elev, azim : the camera (see :func:`choose_camera`), or ``camera`` itself
        (a :class:`Camera`)
    size : image width and height in pixels, ``(width, height)`` or one number for a
        square (default 800 x 600); dpi : int (default 100)
    edges : draw the mesh edges; background : colour (default white)
    title : text in the top-left corner (a title and a legend), or None
    """

    def __init__(
        self,
        verts,
        faces,
        *,
        up="auto",
        view="auto",
        elev: float | None = None,
        azim: float | None = None,
        camera: Camera | None = None,
        size: int | tuple[int, int] = _DEFAULT_SIZE,
        dpi: int = 100,
        edges: bool = False,
        background="white",
        title: str | None = None,
    ):
        self.size = _check_image(size, dpi)
        self.verts, self.topo, v, f = _mesh(verts, faces)
        self.scene = _Scene(v, f, _camera(camera, v, f, up, view, elev, azim))
        self.scene.frame(self.size)
        self.dpi, self.edges, self.background, self.title = dpi, edges, background, title

    def draw(self, path, edges: bool | None = None) -> Path:
        """Write the PNG (with the mesh edges if ``edges``, by default the option's)."""
        edges = self.edges if edges is None else edges
        return self.scene.draw(path, self.size, self.dpi, self.background, self.title, edges)


def render_mesh(verts, faces, path, *, face_colors=None, **options) -> Path:
    """Render a shaded mesh to a PNG.

    Parameters
    ----------
    verts : (V, 3) tensor
    faces : (F, 3) integer tensor or Topology
    path : where to write the PNG
    face_colors : optional (F, 3) RGB in [0, 1] (shaded by the Lambert term)
    options : the camera and the image (:class:`Picture`: ``up``, ``view``, ``elev``,
        ``azim``, ``camera``, ``size``, ``dpi``, ``edges``, ``background``, ``title``)

    Returns
    -------
    pathlib.Path of the PNG.
    """
    picture = Picture(verts, faces, **options)
    picture.scene.add_faces(_face_colors(picture.scene, face_colors, picture.topo))
    return picture.draw(path)


def _face_colors(scene: _Scene, face_colors, topo: Topology):
    if face_colors is None:
        return None
    c = np.asarray(torch.as_tensor(face_colors).detach().cpu(), dtype=np.float64)
    if c.shape != (topo.num_faces, 3):
        raise ValueError(f"face_colors must have shape ({topo.num_faces}, 3), got {c.shape}")
    bad = np.flatnonzero(~np.isfinite(c).all(1) | (c < 0).any(1) | (c > 1).any(1))
    if bad.size:
        raise ValueError(f"face_colors must be RGB values in [0, 1]; violated at faces [{list_some(bad)}]")
    return c * scene.shade[:, None]
