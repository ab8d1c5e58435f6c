"""Tangent vector fields: the edge-based representation and what is computed on it.

The package namespace is the representation (:mod:`.representation`: frames,
conversions to ambient vectors, interpolation, n-RoSy powers and roots), as
``torch_edgevf.fields.edge_vectors`` etc. The computations on fields are modules:

* :mod:`.design`: smoothest, aligned, constrained and curvature fields (thesis 4);
* :mod:`.singularities`: indices, singular faces and their location (thesis 3.2);
* :mod:`.poisson`: projection on gradients, the Poisson problem of thesis 4.2;
* :mod:`.transport`: parallel transport by the heat method (thesis 5);
* :mod:`.param`: seamless parametrization from a cross field.

Their entry points (``smoothest_field``, ``singularities``, ``transport``, ...) are
exported by :mod:`torch_edgevf`; they are not re-exported here, so that
``torch_edgevf.fields.singularities`` is the module.
"""

from .representation import (
    edge_directions,
    edge_frames,
    edge_vectors,
    edges_from_vectors,
    edges_to_vertices,
    face_directions,
    face_edge_coefficients,
    face_frames,
    face_values,
    face_vectors,
    from_one_form,
    interpolate,
    nth_power,
    nth_root,
    nth_roots,
    point_directions,
    point_vectors,
    to_one_form,
    to_vectors,
    vertex_directions,
    vertex_frames,
    vertex_transport,
    vertex_vectors,
    vertices_to_edges,
)

__all__ = [
    "nth_power",
    "nth_root",
    "nth_roots",
    "face_frames",
    "edge_frames",
    "vertex_frames",
    "face_edge_coefficients",
    "interpolate",
    "face_values",
    "to_vectors",
    "point_vectors",
    "edge_vectors",
    "edges_from_vectors",
    "face_vectors",
    "vertex_vectors",
    "edge_directions",
    "face_directions",
    "vertex_directions",
    "point_directions",
    "vertex_transport",
    "edges_to_vertices",
    "vertices_to_edges",
    "to_one_form",
    "from_one_form",
]
