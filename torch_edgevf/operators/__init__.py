"""The edge-based operators: sparse matrices assembled from per-face contributions.

* :mod:`.patterns`: fixed sparsity patterns, sorted once per topology;
* :mod:`.kernels`: the per-face value kernels and the cached assembly plans (the
  internal API of the two modules below);
* :mod:`.functional`: one public function per operator (the table of formulas);
* :mod:`.module`: :class:`EdgeOperators`, all operators of a mesh as an ``nn.Module``.

The functions are re-exported here: ``torch_edgevf.operators.mass_matrix`` etc.
"""

from . import functional, kernels, module, patterns
from .functional import (
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
from .module import EdgeOperators

__all__ = [
    "functional",
    "kernels",
    "module",
    "patterns",
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
]
