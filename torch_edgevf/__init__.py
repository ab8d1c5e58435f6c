"""torch_edgevf: tangent vector fields on triangle meshes, one complex number per edge.

The representation and every operator follow "Tangent Vector Fields on Triangulated
Surfaces: An Edge-Based Approach" (see README for the citations): the value of a field at
each edge midpoint, in a frame along the edge from its lower to its higher vertex index,
interpolated inside faces with the Crouzeix-Raviart (mid-edge) hat basis.

The sub-packages follow the pipeline (see ``docs/architecture.md``): :mod:`.mesh`
(topology, geometry, repair) and :mod:`.linalg` (sparse solves, eigenpairs, exponentials)
at the bottom, :mod:`.operators` on the mesh, :mod:`.fields` on the operators, :mod:`.quad`
(quad meshes) on the fields,
:mod:`.learning` on top, with :mod:`.io`, :mod:`.render` and :mod:`.cli` beside it.

The public names of the package are those of :data:`_EXPORTS` (and the modules of
:data:`_MODULES`): ``__all__``, the lazy loading below and the API page of the
documentation are derived from them. Names are imported on first use, so that
``import torch_edgevf`` (and ``edgevf --help``) does not import torch.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from ._version import __version__ as __version__

#: the modules that are attributes of the package: name -> module (the short names
#: ``geometry``, ``design``, ... are modules of the sub-packages)
_MODULES: dict[str, str] = {
    "mesh": ".mesh",
    "operators": ".operators",
    "linalg": ".linalg",
    "fields": ".fields",
    "learning": ".learning",
    "io": ".io",
    "render": ".render",
    "allocator": ".allocator",
    "geometry": ".mesh.geometry",
    "meshes": ".mesh.meshes",
    "topology": ".mesh.topology",
    "module": ".operators.module",
    "design": ".fields.design",
    "param": ".fields.param",
    "poisson": ".fields.poisson",
    "quad": ".quad",
}

#: the public names of the package, by the module that defines them (separated by spaces)
_EXPORTS: dict[str, str] = {
    ".mesh.topology": "Topology remove_unreferenced_vertices",
    ".mesh.meshes": "icosphere",
    ".mesh.repair": "repair RepairResult RepairReport",
    ".mesh.geometry": (
        "FaceGeometry face_geometry edge_lengths face_areas face_normals vertex_normals "
        "corner_angles dihedral_angles angle_defects transport_coefficients"
    ),
    ".operators.functional": (
        "mass_matrix connection_laplacian gradient curl_div_operator face_curl face_div "
        "vertex_div_curl real_form curl_energy div_energy laplace_beltrami vertex_mass "
        "covariant_derivative cotan_laplacian"
    ),
    ".operators.module": "EdgeOperators",
    ".linalg": (
        "EigenPairs SparseSolver eigsh expm_multiply factorize implicit_euler solve "
        "solve_constrained solve_fixed"
    ),
    ".fields.powers": "nth_power nth_root nth_roots",
    ".fields.representation": "edge_vectors edges_from_vectors",
    ".fields.design": (
        "FieldDesigner smoothest_field curl_free_field div_free_field constrained_field "
        "aligned_field heat_diffuse curvature_field curvature_aligned_field"
    ),
    ".fields.singularities": "Singularities singularities locate_singularities split_singular_faces",
    ".fields.poisson": "GradientProjector project_on_gradients",
    ".fields.transport": "Transporter transport",
    ".fields.param": "parametrize",
    ".quad.igm": "integer_grid_map",
    ".quad.mesh": "quad_mesh",
    ".learning.losses": "smoothness_loss alignment_loss curl_loss div_loss spectral_loss",
    ".io": "MeshData MeshReport FieldData load_mesh save_mesh default_mesh load_field save_field",
    ".allocator": "tune_allocator",
}

if TYPE_CHECKING:  # generated from _MODULES and _EXPORTS (tests/test_public_api.py)
    from . import allocator as allocator
    from . import fields as fields
    from . import io as io
    from . import learning as learning
    from . import linalg as linalg
    from . import mesh as mesh
    from . import operators as operators
    from . import quad as quad
    from . import render as render
    from .allocator import tune_allocator as tune_allocator
    from .fields import design as design
    from .fields import param as param
    from .fields import poisson as poisson
    from .fields.design import FieldDesigner as FieldDesigner
    from .fields.design import aligned_field as aligned_field
    from .fields.design import constrained_field as constrained_field
    from .fields.design import curl_free_field as curl_free_field
    from .fields.design import curvature_aligned_field as curvature_aligned_field
    from .fields.design import curvature_field as curvature_field
    from .fields.design import div_free_field as div_free_field
    from .fields.design import heat_diffuse as heat_diffuse
    from .fields.design import smoothest_field as smoothest_field
    from .fields.param import parametrize as parametrize
    from .fields.poisson import GradientProjector as GradientProjector
    from .fields.poisson import project_on_gradients as project_on_gradients
    from .fields.powers import nth_power as nth_power
    from .fields.powers import nth_root as nth_root
    from .fields.powers import nth_roots as nth_roots
    from .fields.representation import edge_vectors as edge_vectors
    from .fields.representation import edges_from_vectors as edges_from_vectors
    from .fields.singularities import Singularities as Singularities
    from .fields.singularities import locate_singularities as locate_singularities
    from .fields.singularities import singularities as singularities
    from .fields.singularities import split_singular_faces as split_singular_faces
    from .fields.transport import Transporter as Transporter
    from .fields.transport import transport as transport
    from .io import FieldData as FieldData
    from .io import MeshData as MeshData
    from .io import MeshReport as MeshReport
    from .io import default_mesh as default_mesh
    from .io import load_field as load_field
    from .io import load_mesh as load_mesh
    from .io import save_field as save_field
    from .io import save_mesh as save_mesh
    from .learning.losses import alignment_loss as alignment_loss
    from .learning.losses import curl_loss as curl_loss
    from .learning.losses import div_loss as div_loss
    from .learning.losses import smoothness_loss as smoothness_loss
    from .learning.losses import spectral_loss as spectral_loss
    from .linalg import EigenPairs as EigenPairs
    from .linalg import SparseSolver as SparseSolver
    from .linalg import eigsh as eigsh
    from .linalg import expm_multiply as expm_multiply
    from .linalg import factorize as factorize
    from .linalg import implicit_euler as implicit_euler
    from .linalg import solve as solve
    from .linalg import solve_constrained as solve_constrained
    from .linalg import solve_fixed as solve_fixed
    from .mesh import geometry as geometry
    from .mesh import meshes as meshes
    from .mesh import topology as topology
    from .mesh.geometry import FaceGeometry as FaceGeometry
    from .mesh.geometry import angle_defects as angle_defects
    from .mesh.geometry import corner_angles as corner_angles
    from .mesh.geometry import dihedral_angles as dihedral_angles
    from .mesh.geometry import edge_lengths as edge_lengths
    from .mesh.geometry import face_areas as face_areas
    from .mesh.geometry import face_geometry as face_geometry
    from .mesh.geometry import face_normals as face_normals
    from .mesh.geometry import transport_coefficients as transport_coefficients
    from .mesh.geometry import vertex_normals as vertex_normals
    from .mesh.meshes import icosphere as icosphere
    from .mesh.repair import RepairReport as RepairReport
    from .mesh.repair import RepairResult as RepairResult
    from .mesh.repair import repair as repair
    from .mesh.topology import Topology as Topology
    from .mesh.topology import remove_unreferenced_vertices as remove_unreferenced_vertices
    from .operators import module as module
    from .operators.functional import connection_laplacian as connection_laplacian
    from .operators.functional import cotan_laplacian as cotan_laplacian
    from .operators.functional import covariant_derivative as covariant_derivative
    from .operators.functional import curl_div_operator as curl_div_operator
    from .operators.functional import curl_energy as curl_energy
    from .operators.functional import div_energy as div_energy
    from .operators.functional import face_curl as face_curl
    from .operators.functional import face_div as face_div
    from .operators.functional import gradient as gradient
    from .operators.functional import laplace_beltrami as laplace_beltrami
    from .operators.functional import mass_matrix as mass_matrix
    from .operators.functional import real_form as real_form
    from .operators.functional import vertex_div_curl as vertex_div_curl
    from .operators.functional import vertex_mass as vertex_mass
    from .operators.module import EdgeOperators as EdgeOperators
    from .quad.igm import integer_grid_map as integer_grid_map
    from .quad.mesh import quad_mesh as quad_mesh

# name -> (module, attribute); attribute None: the module itself
_LAZY: dict[str, tuple[str, str | None]] = {
    **{name: (module, None) for name, module in _MODULES.items()},
    **{name: (module, name) for module, names in _EXPORTS.items() for name in names.split()},
}

__all__ = list(_LAZY)


def __getattr__(name: str):
    try:
        module_name, attribute = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    module = importlib.import_module(module_name, __name__)
    value = module if attribute is None else getattr(module, attribute)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*__all__, "__version__"})
