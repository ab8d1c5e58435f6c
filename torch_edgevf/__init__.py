"""torch_edgevf: tangent vector fields on triangle meshes, one complex number per edge.

The representation and every operator follow "Tangent Vector Fields on Triangulated
Surfaces: An Edge-Based Approach" (see README for the citations): the value of a field at
each edge midpoint, in a frame along the edge from its lower to its higher vertex index,
interpolated inside faces with the Crouzeix-Raviart (mid-edge) hat basis.
"""

from . import geometry, meshes, operators
from .geometry import (
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
from .meshes import icosphere
from .module import EdgeOperators
from .operators import (
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
from .topology import Topology, remove_unreferenced_vertices
from .allocator import tune_allocator

__version__ = "0.1.0"

from . import io
from .io import FieldData, MeshData, MeshReport, default_mesh, load_field, load_mesh, save_field, save_mesh

from . import linalg
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

from . import fields
from .design import (
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
from .fields import nth_power, nth_root, nth_roots

from .singularities import Singularities, locate_singularities, singularities, split_singular_faces
from .poisson import GradientProjector, project_on_gradients
from .transport import Transporter, transport
from .param import parametrize

from . import data, losses, models, nn, render
from .losses import alignment_loss, curl_loss, div_loss, smoothness_loss, spectral_loss
