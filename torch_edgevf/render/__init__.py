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
* quad meshes (:func:`render_quad_mesh`): the quads with their edges, irregular vertices
  marked;
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

from .camera import Camera, choose_camera
from .field import face_glyph_directions, render_field
from .parametrization import checker_scale, render_parametrization
from .quads import render_quad_mesh
from .scene import Picture, render_mesh
from .singularities import render_singularities

__all__ = [
    "Camera",
    "Picture",
    "choose_camera",
    "render_mesh",
    "render_field",
    "render_singularities",
    "render_parametrization",
    "render_quad_mesh",
    "face_glyph_directions",
    "checker_scale",
]
