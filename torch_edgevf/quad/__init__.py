"""Quad meshes from cross fields: integer-grid maps and quad extraction (thesis chapter 4).

* :mod:`.mesh`: :func:`~.mesh.quad_mesh`, the whole pipeline (field, map, extraction), the
  quality report of a quad mesh and its file output;
* :mod:`.igm`: :func:`~.igm.integer_grid_map`, a seamless map with integer seam translations
  and cones at integer points, locally injective, with :mod:`.cones` (cones at vertices,
  split and cancelled), :mod:`.seams` (the cut mesh and its unknowns), :mod:`.rounding`
  (mixed-integer rounding) and :mod:`.untangle` (foldover-free repair of flips);
* :mod:`.extract`: the pure quad mesh of the integer iso-lines of such a map.

``quad_mesh`` and ``integer_grid_map`` are exported by :mod:`torch_edgevf`.
"""

from .extract import QuadExtraction, extract_quads
from .igm import IntegerGridMap, integer_grid_map
from .mesh import QuadMesh, QuadMeshReport, quad_mesh, quad_mesh_report, save_quad_mesh, sharp_edges

__all__ = [
    "quad_mesh",
    "QuadMesh",
    "quad_mesh_report",
    "QuadMeshReport",
    "save_quad_mesh",
    "sharp_edges",
    "integer_grid_map",
    "IntegerGridMap",
    "extract_quads",
    "QuadExtraction",
]
