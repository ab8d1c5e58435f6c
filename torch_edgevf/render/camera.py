"""The camera of the pictures: chosen from the mesh (up, view) or given."""

from __future__ import annotations

import math

import numpy as np
import torch

from .._validation import as_faces, as_verts, check_vertex_count
from ..mesh.topology import Topology

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


def _mesh(verts, faces):
    """Validated numpy copies of ``verts`` (V, 3) float64 and the topology."""
    verts_t = as_verts(verts)
    topo = faces if isinstance(faces, Topology) else Topology(as_faces(faces), num_vertices=verts_t.shape[0])
    check_vertex_count(verts_t, topo.num_vertices)
    v = verts_t.detach().cpu().to(torch.float64).numpy()
    f = topo.faces.numpy()
    return verts_t, topo, v, f
