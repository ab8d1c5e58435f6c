"""Mesh repair: triangle soups made into meshes the operators accept, every change reported.

:func:`repair` takes vertex positions and polygons as they come from a file and returns a
:class:`RepairResult`: a manifold, consistently oriented triangle mesh, maps from its
vertices and faces to the input ones, edge lengths that are valid even where faces have
zero area (intrinsic mollification), and a :class:`RepairReport` that names every
element that was changed. No vertex is ever moved; the input is never modified. Zero-area
caps (a corner on the opposite edge) are re-triangulated by an edge flip
(:func:`flip_caps`), so that the repaired positions themselves, written to a file, have
no zero-area face there.

Zero-width cracks (coincident vertices, where a vertex was split at one position, and
T-junctions; see :mod:`~torch_edgevf.mesh.diagnose`) are valid boundaries to the
topology: :func:`repair` always reports them and closes them only when asked
(``merge_coincident=True``, ``split_t_junctions=True``), since either changes the
topology the input describes.

:func:`repair_degenerate_faces` is the older, extrinsic alternative for closed manifold
meshes: it removes zero-area faces by edge collapse.
"""

from __future__ import annotations

from .caps import flip_caps
from .degenerate import find_degenerate_faces, repair_degenerate_faces
from .mollify import MOLLIFY_FACTOR, mollify_lengths
from .pipeline import repair
from .polygons import triangulate
from .report import RepairReport
from .result import MappedEdgeField, RepairResult

__all__ = [
    "RepairReport",
    "RepairResult",
    "MappedEdgeField",
    "repair",
    "mollify_lengths",
    "MOLLIFY_FACTOR",
    "triangulate",
    "find_degenerate_faces",
    "flip_caps",
    "repair_degenerate_faces",
]
