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

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from ._version import __version__ as __version__

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and editors
    from . import allocator, data, fields, io, learning, linalg, losses, mesh, models, nn, operators, render
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
    from .fields.representation import edge_vectors, edges_from_vectors, nth_power, nth_root, nth_roots
    from .fields.singularities import Singularities, locate_singularities, singularities, split_singular_faces
    from .fields.transport import Transporter, transport
    from .io import (
        FieldData,
        MeshData,
        MeshReport,
        default_mesh,
        load_field,
        load_mesh,
        save_field,
        save_mesh,
    )
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
    from .mesh.repair import RepairReport, RepairResult, repair
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

# name -> (module, attribute); attribute None: the module itself. Imported on first use,
# so that ``import torch_edgevf`` (and ``edgevf --help``) does not import torch.
_LAZY: dict[str, tuple[str, str | None]] = {
    "allocator": (".allocator", None),
    "data": (".data", None),
    "fields": (".fields", None),
    "io": (".io", None),
    "learning": (".learning", None),
    "linalg": (".linalg", None),
    "losses": (".losses", None),
    "mesh": (".mesh", None),
    "models": (".models", None),
    "nn": (".nn", None),
    "operators": (".operators", None),
    "render": (".render", None),
    "tune_allocator": (".allocator", "tune_allocator"),
    "design": (".fields.design", None),
    "param": (".fields.param", None),
    "poisson": (".fields.poisson", None),
    "FieldDesigner": (".fields.design", "FieldDesigner"),
    "aligned_field": (".fields.design", "aligned_field"),
    "constrained_field": (".fields.design", "constrained_field"),
    "curl_free_field": (".fields.design", "curl_free_field"),
    "curvature_aligned_field": (".fields.design", "curvature_aligned_field"),
    "curvature_field": (".fields.design", "curvature_field"),
    "div_free_field": (".fields.design", "div_free_field"),
    "heat_diffuse": (".fields.design", "heat_diffuse"),
    "smoothest_field": (".fields.design", "smoothest_field"),
    "parametrize": (".fields.param", "parametrize"),
    "GradientProjector": (".fields.poisson", "GradientProjector"),
    "project_on_gradients": (".fields.poisson", "project_on_gradients"),
    "edge_vectors": (".fields.representation", "edge_vectors"),
    "edges_from_vectors": (".fields.representation", "edges_from_vectors"),
    "nth_power": (".fields.representation", "nth_power"),
    "nth_root": (".fields.representation", "nth_root"),
    "nth_roots": (".fields.representation", "nth_roots"),
    "Singularities": (".fields.singularities", "Singularities"),
    "locate_singularities": (".fields.singularities", "locate_singularities"),
    "singularities": (".fields.singularities", "singularities"),
    "split_singular_faces": (".fields.singularities", "split_singular_faces"),
    "Transporter": (".fields.transport", "Transporter"),
    "transport": (".fields.transport", "transport"),
    "FieldData": (".io", "FieldData"),
    "MeshData": (".io", "MeshData"),
    "MeshReport": (".io", "MeshReport"),
    "default_mesh": (".io", "default_mesh"),
    "load_field": (".io", "load_field"),
    "load_mesh": (".io", "load_mesh"),
    "save_field": (".io", "save_field"),
    "save_mesh": (".io", "save_mesh"),
    "alignment_loss": (".learning.losses", "alignment_loss"),
    "curl_loss": (".learning.losses", "curl_loss"),
    "div_loss": (".learning.losses", "div_loss"),
    "smoothness_loss": (".learning.losses", "smoothness_loss"),
    "spectral_loss": (".learning.losses", "spectral_loss"),
    "EigenPairs": (".linalg", "EigenPairs"),
    "SparseSolver": (".linalg", "SparseSolver"),
    "eigsh": (".linalg", "eigsh"),
    "expm_multiply": (".linalg", "expm_multiply"),
    "factorize": (".linalg", "factorize"),
    "implicit_euler": (".linalg", "implicit_euler"),
    "solve": (".linalg", "solve"),
    "solve_constrained": (".linalg", "solve_constrained"),
    "solve_fixed": (".linalg", "solve_fixed"),
    "geometry": (".mesh.geometry", None),
    "meshes": (".mesh.meshes", None),
    "topology": (".mesh.topology", None),
    "FaceGeometry": (".mesh.geometry", "FaceGeometry"),
    "angle_defects": (".mesh.geometry", "angle_defects"),
    "corner_angles": (".mesh.geometry", "corner_angles"),
    "dihedral_angles": (".mesh.geometry", "dihedral_angles"),
    "edge_lengths": (".mesh.geometry", "edge_lengths"),
    "face_areas": (".mesh.geometry", "face_areas"),
    "face_geometry": (".mesh.geometry", "face_geometry"),
    "face_normals": (".mesh.geometry", "face_normals"),
    "transport_coefficients": (".mesh.geometry", "transport_coefficients"),
    "vertex_normals": (".mesh.geometry", "vertex_normals"),
    "icosphere": (".mesh.meshes", "icosphere"),
    "repair": (".mesh.repair", "repair"),
    "RepairResult": (".mesh.repair", "RepairResult"),
    "RepairReport": (".mesh.repair", "RepairReport"),
    "Topology": (".mesh.topology", "Topology"),
    "remove_unreferenced_vertices": (".mesh.topology", "remove_unreferenced_vertices"),
    "module": (".operators.module", None),
    "connection_laplacian": (".operators.functional", "connection_laplacian"),
    "cotan_laplacian": (".operators.functional", "cotan_laplacian"),
    "covariant_derivative": (".operators.functional", "covariant_derivative"),
    "curl_div_operator": (".operators.functional", "curl_div_operator"),
    "curl_energy": (".operators.functional", "curl_energy"),
    "div_energy": (".operators.functional", "div_energy"),
    "face_curl": (".operators.functional", "face_curl"),
    "face_div": (".operators.functional", "face_div"),
    "gradient": (".operators.functional", "gradient"),
    "laplace_beltrami": (".operators.functional", "laplace_beltrami"),
    "mass_matrix": (".operators.functional", "mass_matrix"),
    "real_form": (".operators.functional", "real_form"),
    "vertex_div_curl": (".operators.functional", "vertex_div_curl"),
    "vertex_mass": (".operators.functional", "vertex_mass"),
    "EdgeOperators": (".operators.module", "EdgeOperators"),
}


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
    "repair",
    "RepairResult",
    "RepairReport",
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
