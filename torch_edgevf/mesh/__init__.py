"""Meshes: topology, geometry, procedural shapes, diagnostics and repair.

The bottom of the pipeline, with :mod:`torch_edgevf.linalg` beside it: nothing here
imports the layers above (operators, fields, learning).

* :mod:`.topology`: :class:`Topology`, incidences computed once from the faces;
* :mod:`.geometry`: lengths, areas, angles and transport from positions;
* :mod:`.meshes`: procedural test shapes (icosphere, grid, ellipsoid, ...);
* :mod:`.diagnose`: a report on a mesh's suitability;
* :mod:`.repair`: :func:`~.repair.repair` of triangle soups (orientation, non-manifold
  cuts, duplicates, intrinsic mollification), and collapse of zero-area faces.
"""

from . import diagnose, geometry, meshes, repair, topology
from .topology import Topology, remove_unreferenced_vertices

__all__ = ["Topology", "diagnose", "geometry", "meshes", "remove_unreferenced_vertices", "repair", "topology"]
