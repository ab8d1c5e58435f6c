"""Edge fields and their singularities in polyscope's viewer, and its screenshots.

Needs the optional extra ``viz`` (``pip install torch_edgevf[viz]``: polyscope 2.x); it is
imported inside the functions. :func:`show_field` registers, in one call, the mesh, the
``n`` directions of an ``n``-direction field at the face barycenters or the vertices (one
vector quantity per direction, all in one colour, each direction of unit length times
``scale`` mean edge lengths) and the singularities (a point cloud at the singular face
barycenters and vertices, green for a positive index and red for a negative one, with the
index as a scalar quantity). It then opens the viewer, or writes a screenshot.

Without a display, polyscope renders through EGL (:func:`init` allows its headless
back-ends): screenshots work on servers with an EGL driver (Mesa's software one
included). ``backend="openGL_mock"`` registers everything and draws nothing, for tests
of the data alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from .._validation import as_verts
from ..fields.representation import face_directions, vertex_directions
from ..fields.singularities import Singularities
from ..fields.singularities import singularities as find_singularities
from ..mesh.topology import Topology
from .scene import _GLYPH_COLOR, _NEGATIVE, _POSITIVE

__all__ = ["PolyscopeField", "init", "show_field", "BACKENDS"]

#: polyscope's back-ends: ``"auto"`` (a window where there is a display, else EGL), a
#: window (GLFW), headless EGL, and the mock one (nothing drawn)
BACKENDS = ("auto", "openGL3_glfw", "openGL3_egl", "openGL_mock")
_MESH_COLOR = (0.80, 0.80, 0.82)
_AT = ("faces", "vertices")


def _polyscope():
    try:
        import polyscope
    except ImportError as e:
        raise ValueError(
            "polyscope is not installed: pip install torch_edgevf[viz] (or pip install polyscope)"
        ) from e
    return polyscope


def init(backend: str = "auto"):
    """Initialise polyscope once (later calls return at once) and return the module.

    Headless back-ends are allowed, so that ``"auto"`` falls back to EGL where there is no
    display. Raises ``ValueError`` for an unknown back-end, and polyscope's own error where
    no back-end can open a context.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    ps = _polyscope()
    if not ps.is_initialized():
        ps.set_allow_headless_backends(True)
        ps.init(backend)
    return ps


@dataclass
class PolyscopeField:
    """What :func:`show_field` registered with polyscope.

    Attributes
    ----------
    mesh : polyscope SurfaceMesh
    vector_names : the names of the ``n`` vector quantities of the mesh (direction ``k`` is
        direction 0 turned by ``2 pi k / n``)
    directions : (F or V, n, 3) array, the vectors registered (``directions[:, k]`` is
        quantity ``vector_names[k]``)
    at : "faces" or "vertices"
    points : (K, 3) array, the singularities' positions (barycenters, then vertices)
    indices : (K,) array, their indices
    singularity_cloud : polyscope PointCloud, or None (no singularity, or none asked for)
    screenshot : path of the screenshot written, or None
    """

    mesh: Any
    vector_names: list[str]
    directions: np.ndarray
    at: str
    points: np.ndarray
    indices: np.ndarray
    singularity_cloud: Any = None
    screenshot: Path | None = None
    singularities: Singularities | None = field(default=None, repr=False)


def _unit_directions(d: torch.Tensor) -> torch.Tensor:
    norm = torch.linalg.vector_norm(d, dim=-1, keepdim=True)
    return torch.where(norm > 0, d / norm.clamp_min(torch.finfo(d.dtype).tiny), torch.zeros_like(d))


def show_field(
    verts,
    faces,
    z=None,
    n: int = 1,
    *,
    at: str = "faces",
    singularities: bool | Singularities = True,
    name: str = "mesh",
    scale: float = 0.5,
    screenshot=None,
    show: bool | None = None,
    backend: str = "auto",
    window_size: tuple[int, int] | None = (1024, 768),
) -> PolyscopeField:
    """Show a mesh, the ``n`` directions of an edge field and its singularities in polyscope.

    Parameters
    ----------
    verts : (V, 3) tensor or array
    faces : (F, 3) integer tensor or array, or a Topology
    z : (E,) complex tensor, the representation vector of an ``n``-direction field (edges
        of :class:`~torch_edgevf.mesh.topology.Topology`), or None (the mesh alone)
    n : int, the symmetry of the field
    at : {"faces", "vertices"}
        The directions at face barycenters
        (:func:`~torch_edgevf.fields.representation.face_directions`) or at the vertices
        (:func:`~torch_edgevf.fields.representation.vertex_directions`).
    singularities : bool or Singularities
        Show the singularities: computed from ``z`` (True), given, or not (False).
    name : the name of the mesh in polyscope (its quantities and the singularities' point
        cloud are named after it); a structure of that name is replaced
    scale : length of the drawn directions, in mean edge lengths
    screenshot : path of a PNG to write (opaque background), or None
    show : open the viewer (blocks until it is closed); default: when no screenshot is asked
    backend : one of :data:`BACKENDS` (see :func:`init`)
    window_size : (width, height) in pixels of the window or screenshot, or None (polyscope's)

    Returns
    -------
    PolyscopeField
    """
    if at not in _AT:
        raise ValueError(f"at must be one of {_AT}, got {at!r}")
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not scale > 0:
        raise ValueError(f"scale must be a positive number, got {scale!r}")
    if not isinstance(name, str) or not name:
        raise ValueError(f"name must be a non-empty string, got {name!r}")
    verts = as_verts(verts).detach()
    topo = faces if isinstance(faces, Topology) else Topology(faces, num_vertices=verts.shape[0])
    v = verts.to(torch.float64)
    if z is not None:
        if not isinstance(z, torch.Tensor):
            z = torch.as_tensor(z)
        if z.shape != (topo.num_edges,):
            raise ValueError(f"z must have shape (E,) with E = {topo.num_edges} edges, got {tuple(z.shape)}")
        z = z.detach().to(torch.complex128)
        take = face_directions if at == "faces" else vertex_directions
        d = take(v, topo, z, n)
    else:
        d = torch.zeros(topo.num_faces if at == "faces" else topo.num_vertices, 0, 3, dtype=torch.float64)
    e = topo.edges
    length = float(torch.linalg.vector_norm(v[e[:, 0]] - v[e[:, 1]], dim=1).mean())
    directions = (_unit_directions(d) * (scale * length)).numpy()
    diagonal = max(float(torch.linalg.vector_norm(v.max(0).values - v.min(0).values)), 1e-300)
    sing: Singularities | None = None
    if isinstance(singularities, Singularities):
        sing = singularities
    elif singularities is True and z is not None:
        sing = find_singularities(v, topo, z, n)
    elif not isinstance(singularities, bool):
        raise ValueError(
            f"singularities must be a bool or a Singularities, got {type(singularities).__name__}"
        )
    points, indices = np.zeros((0, 3)), np.zeros(0)
    if sing is not None:
        if sing.face_index.shape != (topo.num_faces,) or sing.vertex_index.shape != (topo.num_vertices,):
            raise ValueError("the singularities are of another mesh (face_index (F,), vertex_index (V,))")
        sf, sv = sing.singular_faces, sing.singular_vertices
        points = torch.cat([v[topo.faces[sf]].mean(1), v[sv]]).numpy()
        indices = torch.cat([sing.face_index[sf], sing.vertex_index[sv]]).to(torch.float64).numpy()

    ps = init(backend)
    if window_size is not None:
        ps.set_window_size(*window_size)
    ps.set_ground_plane_mode("none")
    cloud_name = f"{name} singularities"
    if ps.has_point_cloud(cloud_name):
        ps.remove_point_cloud(cloud_name)
    mesh = ps.register_surface_mesh(
        name, v.numpy(), topo.faces.numpy(), color=_MESH_COLOR, smooth_shade=False, edge_width=0.0
    )
    names = [f"{name} direction {k}" for k in range(directions.shape[1])]
    for k, qname in enumerate(names):
        mesh.add_vector_quantity(
            qname,
            directions[:, k],
            defined_on=at,
            vectortype="ambient",
            enabled=True,
            color=_GLYPH_COLOR,
            radius=0.06 * scale * length / diagonal,  # relative to the scene's size
        )
    cloud = None
    if len(points):
        colors = np.where(indices[:, None] > 0, np.array(_POSITIVE), np.array(_NEGATIVE))
        cloud = ps.register_point_cloud(cloud_name, points, radius=0.4 * length, color=_POSITIVE)
        cloud.set_radius(0.4 * length, relative=False)
        cloud.add_color_quantity("sign", colors, enabled=True)
        cloud.add_scalar_quantity("index", indices)
    ps.reset_camera_to_home_view()
    out = PolyscopeField(mesh, names, directions, at, points, indices, cloud, None, sing)
    if screenshot is not None:
        path = Path(screenshot)
        ps.screenshot(str(path), transparent_bg=False)
        out.screenshot = path
    if show or (show is None and screenshot is None):
        ps.show()
    return out
