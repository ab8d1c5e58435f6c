"""torch_edgevf: tangent vector fields on triangle meshes, one complex number per edge.

The representation and every operator follow "Tangent Vector Fields on Triangulated
Surfaces: An Edge-Based Approach" (see README for the citations): the value of a field at
each edge midpoint, in a frame along the edge from its lower to its higher vertex index,
interpolated inside faces with the Crouzeix-Raviart (mid-edge) hat basis.

The sub-packages follow the pipeline (see ``docs/architecture.md``): :mod:`.mesh`
(topology, geometry) and :mod:`.linalg` (sparse solves, eigenpairs, exponentials) at the
bottom, :mod:`.operators` on the mesh, :mod:`.fields` on the operators, :mod:`.learning`
on top, with :mod:`.io`, :mod:`.render` and :mod:`.cli` beside it. Every name of
``__all__`` below is the public API; the short module names ``geometry``, ``topology``,
``meshes``, ``module``, ``design``, ``poisson``, ``param``, ``data``, ``nn``, ``models``
and ``losses`` are kept as attributes.
"""

from . import fields, io, learning, linalg, mesh, operators, render
from . import allocator, data, losses, models, nn
from ._version import __version__ as __version__
from .allocator import tune_allocator
from .fields import design, param, poisson
from .fields.design import (
    FieldDesigner,
    aligned_field,
    constrained_field,
    curl_free_field,
    curvature_aligned_field,
    curvature_field,
    div_free_field,
    heat_diffuse,
    smoothest_field,
)
from .fields.param import parametrize
from .fields.poisson import GradientProjector, project_on_gradients
from .fields.representation import edges_from_vectors, edge_vectors, nth_power, nth_root, nth_roots
from .fields.singularities import Singularities, locate_singularities, singularities, split_singular_faces
from .fields.transport import Transporter, transport
from .io import FieldData, MeshData, MeshReport, default_mesh, load_field, load_mesh, save_field, save_mesh
from .learning.losses import alignment_loss, curl_loss, div_loss, smoothness_loss, spectral_loss
from .linalg import (
    EigenPairs,
    SparseSolver,
    eigsh,
    expm_multiply,
    factorize,
    implicit_euler,
    solve,
    solve_constrained,
    solve_fixed,
)
from .mesh import geometry, meshes, topology
from .mesh.geometry import (
    FaceGeometry,
    angle_defects,
    corner_angles,
    dihedral_angles,
    edge_lengths,
    face_areas,
    face_geometry,
    face_normals,
    transport_coefficients,
    vertex_normals,
)
from .mesh.meshes import icosphere
from .mesh.topology import Topology, remove_unreferenced_vertices
from .operators import module
from .operators.functional import (
    connection_laplacian,
    cotan_laplacian,
    covariant_derivative,
    curl_div_operator,
    curl_energy,
    div_energy,
    face_curl,
    face_div,
    gradient,
    laplace_beltrami,
    mass_matrix,
    real_form,
    vertex_div_curl,
    vertex_mass,
)
from .operators.module import EdgeOperators

__all__ = [
    # sub-packages and modules
    "mesh",
    "operators",
    "linalg",
    "fields",
    "learning",
    "io",
    "render",
    "allocator",
    # short module names kept as attributes
    "geometry",
    "meshes",
    "topology",
    "module",
    "design",
    "param",
    "poisson",
    "data",
    "losses",
    "models",
    "nn",
    # mesh
    "Topology",
    "remove_unreferenced_vertices",
    "icosphere",
    "FaceGeometry",
    "face_geometry",
    "edge_lengths",
    "face_areas",
    "face_normals",
    "vertex_normals",
    "corner_angles",
    "dihedral_angles",
    "angle_defects",
    "transport_coefficients",
    # operators
    "mass_matrix",
    "connection_laplacian",
    "gradient",
    "curl_div_operator",
    "face_curl",
    "face_div",
    "vertex_div_curl",
    "real_form",
    "curl_energy",
    "div_energy",
    "laplace_beltrami",
    "vertex_mass",
    "covariant_derivative",
    "cotan_laplacian",
    "EdgeOperators",
    # linear algebra
    "EigenPairs",
    "SparseSolver",
    "eigsh",
    "expm_multiply",
    "factorize",
    "implicit_euler",
    "solve",
    "solve_constrained",
    "solve_fixed",
    # fields
    "nth_power",
    "nth_root",
    "nth_roots",
    "edge_vectors",
    "edges_from_vectors",
    "FieldDesigner",
    "smoothest_field",
    "curl_free_field",
    "div_free_field",
    "constrained_field",
    "aligned_field",
    "heat_diffuse",
    "curvature_field",
    "curvature_aligned_field",
    "Singularities",
    "singularities",
    "locate_singularities",
    "split_singular_faces",
    "GradientProjector",
    "project_on_gradients",
    "Transporter",
    "transport",
    "parametrize",
    # learning
    "smoothness_loss",
    "alignment_loss",
    "curl_loss",
    "div_loss",
    "spectral_loss",
    # input and output
    "MeshData",
    "MeshReport",
    "FieldData",
    "load_mesh",
    "save_mesh",
    "default_mesh",
    "load_field",
    "save_field",
    # process
    "tune_allocator",
]
