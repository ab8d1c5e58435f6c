"""Headless PNG pictures of meshes, fields, singularities and parametrizations.

Needs matplotlib (the optional extra ``plot``: ``pip install torch_edgevf[plot]``); it is
imported inside the functions, and only the Agg canvas is used (no pyplot, no display, no
global backend switch), so rendering works on servers and in threads.

The renderer is a small orthographic painter: vertices are projected on the image plane of
a camera (:class:`Camera`), faces are drawn back to front with a Lambert shade

.. math::  c_T = c \\, \\big(a + (1 - a) \\max(0, N_T \\cdot \\ell)\\big),

and the overlays are

* field glyphs (:func:`render_field`): the ``n`` directions at each face barycenter, each a
  thin tapered segment lying in the face plane, drawn right after their face (so nearer
  faces hide them) and only on faces turned towards the camera (back-face culling by
  ``N_T \\cdot d > 0``);
* singularity markers (:func:`render_singularities`): discs at face barycenters and
  vertices with a nonzero index, green for positive and red for negative, drawn on top
  where the point is visible (a ray test against the projected faces);
* checkerboards (:func:`render_parametrization`): each face subdivided, each small
  triangle coloured by the parity of ``floor(s u) + floor(s v)`` at its centroid.

The camera is chosen from the mesh unless given (:func:`choose_camera`): ``up="auto"``
takes the side an open surface faces (a terrain is seen from above), else the normal of a
flat mesh, else ``+y``, the usual vertical of OBJ files; ``view="auto"`` then takes, among
views from 25 degrees above the horizon (40 for open and flat meshes), the one with the
largest front-facing projected area. Both accept an axis (``"y"``, ``"-z"``) or a
3-vector, ``elev``/``azim`` (degrees about ``up``) override the view, and ``camera`` a
whole :class:`Camera`.

Glyphs and checkerboards adapt to the picture: one glyph per cell of ``glyph_spacing``
pixels of the image (the nearest visible face in the cell), as long as the cell or the
face, whichever is smaller; checker squares sized so that about ``checker_cells`` of them
span the mesh's largest dimension.

Every function takes tensors (or arrays), writes a PNG, and returns its path.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import torch

from ._validation import as_faces, as_verts, check_vertex_count, list_some
from .mesh.topology import Topology

__all__ = [
    "Camera",
    "choose_camera",
    "render_mesh",
    "render_field",
    "render_singularities",
    "render_parametrization",
    "face_glyph_directions",
    "checker_scale",
]

log = logging.getLogger(__name__)

_BASE_COLOR = (0.72, 0.78, 0.86)
_BACK_COLOR = (0.86, 0.70, 0.55)
_GLYPH_COLOR = (0.08, 0.08, 0.12)
_POSITIVE = (0.10, 0.65, 0.20)
_NEGATIVE = (0.85, 0.10, 0.10)
_CHECKER = ((0.95, 0.95, 0.95), (0.20, 0.35, 0.75))
_AMBIENT = 0.3
_SUPERSAMPLE = 3
_DEFAULT_SIZE = (800, 600)
_AXIS_NAMES = {"x": 0, "y": 1, "z": 2}


# --------------------------------------------------------------------------- camera


class Camera:
    """An orthographic camera looking at the origin of the mesh's bounding box.

    Parameters
    ----------
    elev, azim : float
        Elevation and azimuth in degrees; the camera sits in the direction
        ``d = cos(elev) cos(azim) x + cos(elev) sin(azim) y + sin(elev) up`` (world axes
        ``x, y`` completed by ``up``).
    up : sequence of 3 floats
        The world's vertical (``(0, 0, 1)``; meshes such as Spot are ``(0, 1, 0)``).

    Attributes
    ----------
    view : (3,) unit vector from the scene towards the camera
    right, upward : (3,) unit vectors of the image plane
    """

    def __init__(self, elev: float = 20.0, azim: float = -60.0, up=(0.0, 0.0, 1.0)):
        for name, value in (("elev", elev), ("azim", azim)):
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number of degrees, got {value!r}")
        up = np.asarray(up, dtype=np.float64)
        if up.shape != (3,) or not np.isfinite(up).all() or np.linalg.norm(up) == 0:
            raise ValueError(f"up must be a nonzero 3-vector, got {up!r}")
        up = up / np.linalg.norm(up)
        # a right-handed world basis (a, b, up)
        helper = np.array([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        a = helper - helper.dot(up) * up
        a /= np.linalg.norm(a)
        b = np.cross(up, a)
        if up[2] > 0.9:  # the usual z-up case: a = x, b = y exactly
            a, b = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
        e, z = math.radians(elev), math.radians(azim)
        view = math.cos(e) * (math.cos(z) * a + math.sin(z) * b) + math.sin(e) * up
        right = np.cross(up, view)
        if np.linalg.norm(right) < 1e-9:  # looking straight down or up
            right = math.cos(z + math.pi / 2) * a + math.sin(z + math.pi / 2) * b
        right /= np.linalg.norm(right)
        self.elev, self.azim = float(elev), float(azim)
        self.view = view / np.linalg.norm(view)
        self.right = right
        self.upward = np.cross(self.view, self.right)

    @classmethod
    def from_view(cls, view, up=(0.0, 0.0, 1.0)) -> Camera:
        """The camera in direction ``view`` (from the scene towards the camera) with ``up`` vertical."""
        up_v, view_v = _unit(up, "up"), _unit(view, "view")
        helper = np.array([1.0, 0.0, 0.0]) if abs(up_v[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        a = helper - helper.dot(up_v) * up_v
        a /= np.linalg.norm(a)
        b = np.cross(up_v, a)
        if up_v[2] > 0.9:
            a, b = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
        elev = math.degrees(math.asin(float(np.clip(view_v @ up_v, -1.0, 1.0))))
        azim = math.degrees(math.atan2(float(view_v @ b), float(view_v @ a)))
        return cls(elev, azim, up_v)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Image coordinates ``(P, 2)`` and depth ``(P,)`` (larger is nearer the camera)."""
        return np.stack([points @ self.right, points @ self.upward], axis=-1), points @ self.view

    def light(self) -> np.ndarray:
        """A head light, slightly above and left of the camera."""
        l = self.view + 0.45 * self.upward - 0.3 * self.right
        return l / np.linalg.norm(l)


def _unit(x, name: str) -> np.ndarray:
    """A unit 3-vector from an axis name (``"y"``, ``"-z"``) or three numbers."""
    if isinstance(x, str):
        t = x.strip().lower()
        sign = -1.0 if t.startswith("-") else 1.0
        axis = _AXIS_NAMES.get(t.lstrip("+-"))
        if axis is None:
            raise ValueError(
                f"{name} must be 'auto', an axis name (x, y, z, -x, ...) or a 3-vector, got {x!r}"
            )
        out = np.zeros(3)
        out[axis] = sign
        return out
    a = np.asarray(x, dtype=np.float64)
    if a.shape != (3,) or not np.isfinite(a).all() or np.linalg.norm(a) == 0:
        raise ValueError(f"{name} must be a nonzero 3-vector or an axis name, got {x!r}")
    return a / np.linalg.norm(a)


def _snap(d: np.ndarray, degrees: float = 20.0) -> np.ndarray:
    """``d`` replaced by the nearest signed world axis when within ``degrees`` of it."""
    k = int(np.argmax(np.abs(d)))
    if abs(d[k]) >= math.cos(math.radians(degrees)):
        out = np.zeros(3)
        out[k] = math.copysign(1.0, d[k])
        return out
    return d


def _auto_up(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, bool]:
    """The vertical chosen for a mesh, and whether the mesh is open or flat."""
    p = v[f]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    total = max(float(area2.sum()), 1e-300)
    facing = cross.sum(axis=0) / total  # mean unit normal, area-weighted; 0 for closed meshes
    if np.linalg.norm(facing) > 0.3:  # an open surface turned mostly one way (a terrain)
        return _snap(facing / np.linalg.norm(facing)), True
    center = p.mean(axis=1)
    mean = (area2[:, None] * center).sum(0) / total
    d = center - mean
    values, vectors = np.linalg.eigh((area2[:, None] * d).T @ d / total)
    if values[0] < 0.35**2 * values[1]:  # flat: the thin direction is vertical
        normal = vectors[:, 0]
        if normal @ facing < 0 or (abs(normal @ facing) < 1e-3 and normal[np.argmax(np.abs(normal))] < 0):
            normal = -normal
        return _snap(normal), True
    return np.array([0.0, 1.0, 0.0]), False


def choose_camera(verts, faces, *, up="auto", view="auto", elev=None, azim=None) -> Camera:
    """The camera the render functions use by default.

    Parameters
    ----------
    verts : (V, 3) tensor
    faces : (F, 3) integer tensor or Topology
    up : ``"auto"``, an axis name (``"x"``, ``"-z"``, ...) or a 3-vector. ``"auto"``: for an
        open surface whose area-weighted mean normal is large (a terrain) that direction,
        for a flat mesh (smallest principal extent below 0.35 of the middle one) its normal,
        otherwise ``+y``, the usual vertical of OBJ files; directions within 20 degrees of
        a world axis snap to it.
    view : ``"auto"``, an axis name or a 3-vector from the mesh towards the camera.
        ``"auto"``: elevation 25 degrees (40 for open or flat meshes) and the azimuth, in
        steps of 15 degrees, with the largest front-facing projected area.
    elev, azim : degrees about ``up`` (see :class:`Camera`); either one replaces the
        automatic choice of that angle (not allowed with an explicit ``view``).

    Returns
    -------
    Camera
    """
    _, _, v, f = _mesh(verts, faces)
    return _choose_camera(v, f, up, view, elev, azim)


def _choose_camera(v, f, up, view, elev, azim) -> Camera:
    for name, value in (("elev", elev), ("azim", azim)):
        if value is not None and (
            not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value)
        ):
            raise ValueError(f"{name} must be a finite number of degrees, got {value!r}")
    auto_up = isinstance(up, str) and up == "auto"
    auto_view = isinstance(view, str) and view == "auto"
    if not auto_view and (elev is not None or azim is not None):
        raise ValueError("give either view or elev/azim, not both")
    up_v, open_or_flat = _auto_up(v, f) if auto_up else (_unit(up, "up"), False)
    if not auto_view:
        return Camera.from_view(_unit(view, "view"), up_v)
    if elev is None:
        elev = 40.0 if open_or_flat else 25.0
    if azim is None:
        p = v[f]
        cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        candidates = np.arange(0.0, 360.0, 15.0)
        views = np.stack([Camera(elev, a, up_v).view for a in candidates])
        # twice the projected area of the faces turned towards each candidate
        score = np.maximum(cross @ views.T, 0.0).sum(axis=0)
        azim = float(candidates[int(np.argmax(score))])
    return Camera(elev, azim, up_v)


def _camera(camera, v, f, up, view, elev, azim) -> Camera:
    if camera is None:
        return _choose_camera(v, f, up, view, elev, azim)
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a torch_edgevf.render.Camera, got {type(camera).__name__}")
    return camera


# --------------------------------------------------------------------------- mesh


def _mesh(verts, faces):
    """Validated numpy copies of ``verts`` (V, 3) float64 and the topology."""
    verts_t = as_verts(verts)
    topo = faces if isinstance(faces, Topology) else Topology(as_faces(faces), num_vertices=verts_t.shape[0])
    check_vertex_count(verts_t, topo.num_vertices)
    v = verts_t.detach().cpu().to(torch.float64).numpy()
    f = topo.faces.numpy()
    return verts_t, topo, v, f


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


def render_mesh(
    verts,
    faces,
    path,
    *,
    up="auto",
    view="auto",
    elev: float | None = None,
    azim: float | None = None,
    camera: Camera | None = None,
    size: int | tuple[int, int] = _DEFAULT_SIZE,
    dpi: int = 100,
    edges: bool = False,
    face_colors=None,
    background="white",
    title: str | None = None,
) -> Path:
    """Render a shaded mesh to a PNG.

    Parameters
    ----------
    verts : (V, 3) tensor
    faces : (F, 3) integer tensor or Topology
    path : where to write the PNG
    up, view, elev, azim : the camera (see :func:`choose_camera`), or ``camera`` itself
    size : image width and height in pixels, ``(width, height)`` or one number for a square
    edges : draw the mesh edges
    face_colors : optional (F, 3) RGB in [0, 1] (shaded by the Lambert term)

    Returns
    -------
    pathlib.Path of the PNG.
    """
    size = _check_image(size, dpi)
    _, topo, v, f = _mesh(verts, faces)
    scene = _Scene(v, f, _camera(camera, v, f, up, view, elev, azim))
    scene.add_faces(_face_colors(scene, face_colors, topo))
    return scene.draw(path, size, dpi, background, title, edges)


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
    from .fields.representation import face_directions

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
    up="auto",
    view="auto",
    elev: float | None = None,
    azim: float | None = None,
    camera: Camera | None = None,
    size: int | tuple[int, int] = _DEFAULT_SIZE,
    dpi: int = 100,
    glyph_spacing: float | None = 14.0,
    glyph_scale: float = 1.0,
    scale_by_magnitude: bool = False,
    every: int = 1,
    glyph_color=_GLYPH_COLOR,
    edges: bool = False,
    background="white",
    title: str | None = None,
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
    up, view, elev, azim : the camera (see :func:`choose_camera`), or ``camera`` itself
    size : image width and height in pixels, ``(width, height)`` or one number for a square
    glyph_spacing : pixels between glyphs: the image is cut in square cells of this size
        and each cell shows the glyph of the nearest visible face whose barycenter falls
        in it, so that the density on screen does not depend on the mesh resolution.
        ``None``: a glyph on every visible face.
    glyph_scale : glyph length in units of ``0.8 x`` the smaller of the cell and the
        face's mean edge length
    scale_by_magnitude : glyph length proportional to ``|w_T|`` / its maximum
        (else every glyph has the same length)
    every : consider every ``every``-th face only

    Returns
    -------
    pathlib.Path of the PNG.
    """
    size = _check_image(size, dpi)
    verts_t, topo, v, f = _mesh(verts, faces)
    scene = _Scene(v, f, _camera(camera, v, f, up, view, elev, azim))
    scene.frame(size)
    scene.add_faces()
    _add_glyphs(
        scene, verts_t, topo, z, n, glyph_spacing, glyph_scale, scale_by_magnitude, every, glyph_color
    )
    return scene.draw(path, size, dpi, background, title, edges)


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
    up="auto",
    view="auto",
    elev: float | None = None,
    azim: float | None = None,
    camera: Camera | None = None,
    size: int | tuple[int, int] = _DEFAULT_SIZE,
    dpi: int = 100,
    marker_scale: float = 1.0,
    glyph_spacing: float | None = 14.0,
    edges: bool = False,
    background="white",
    title: str | None = None,
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
    up, view, elev, azim : the camera (see :func:`choose_camera`), or ``camera`` itself
    size : image width and height in pixels, ``(width, height)`` or one number for a square
    marker_scale : marker radius in units of 5 pixels (up to twice that for the
        largest ``|index|``)
    glyph_spacing : pixels between the glyphs of ``z`` (see :func:`render_field`)

    Returns
    -------
    pathlib.Path of the PNG.
    """
    size = _check_image(size, dpi)
    if not isinstance(marker_scale, (int, float)) or not math.isfinite(marker_scale) or marker_scale <= 0:
        raise ValueError(f"marker_scale must be a positive number, got {marker_scale!r}")
    verts_t, topo, v, f = _mesh(verts, faces)
    fi = _index_vector(face_index, topo.num_faces, "face_index")
    vi = _index_vector(vertex_index, topo.num_vertices, "vertex_index")
    cam = _camera(camera, v, f, up, view, elev, azim)
    scene = _Scene(v, f, cam)
    scene.frame(size)
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
    return scene.draw(path, size, dpi, background, title, edges)


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
    up="auto",
    view="auto",
    elev: float | None = None,
    azim: float | None = None,
    camera: Camera | None = None,
    size: int | tuple[int, int] = _DEFAULT_SIZE,
    dpi: int = 100,
    colors=_CHECKER,
    edges: bool = False,
    background="white",
    title: str | None = None,
) -> Path:
    """Render a parametrization as a checkerboard texture.

    Each face is split into ``subdivide**2`` triangles; a triangle with centroid
    parameters ``(u, v)`` (linear in the face from the per-corner values) gets colour
    ``colors[(floor(scale u) + floor(scale v)) mod 2]``, Lambert-shaded.

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
    up, view, elev, azim : the camera (see :func:`choose_camera`), or ``camera`` itself
    size : image width and height in pixels, ``(width, height)`` or one number for a square

    Returns
    -------
    pathlib.Path of the PNG.
    """
    size = _check_image(size, dpi)
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
    _, topo, v, f = _mesh(verts, faces)
    uv = np.asarray(torch.as_tensor(uv).detach().cpu(), dtype=np.float64)
    if uv.shape != (topo.num_faces, 3, 2):
        raise ValueError(f"uv must have shape ({topo.num_faces}, 3, 2) (per corner), got {uv.shape}")
    bad = np.flatnonzero(~np.isfinite(uv).reshape(len(uv), -1).all(1))
    if bad.size:
        raise ValueError(f"uv has NaN or Inf values at faces [{list_some(bad)}]")
    scene = _Scene(v, f, _camera(camera, v, f, up, view, elev, azim))
    scene.frame(size)
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
    pts = np.einsum("tck,fkd->ftcd", sub, scene.face_xy)  # (F, T, 3, 2)
    ntri = sub.shape[0]
    scene.add_polygons(np.repeat(np.arange(len(f)), ntri), pts.reshape(-1, 3, 2), col.reshape(-1, 3), layer=0)
    return scene.draw(path, size, dpi, background, title, edges and subdivide == 1)
