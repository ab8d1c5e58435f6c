"""Differentiable sparse linear algebra: solves, eigenpairs and matrix exponentials.

All matrices are torch sparse tensors (coalesced COO preferred); gradients with respect
to a matrix are returned on its sparsity pattern, through its values.
"""

from ._utils import sparse_matrix, to_scipy
from .eigen import EigenPairs, eigsh
from .expm import expm_multiply, implicit_euler
from .factor import NotPositiveDefiniteError, factorize
from .solve import SparseSolver, solve, solve_constrained, solve_fixed

__all__ = [
    "EigenPairs",
    "eigsh",
    "expm_multiply",
    "implicit_euler",
    "NotPositiveDefiniteError",
    "SparseSolver",
    "factorize",
    "solve",
    "solve_constrained",
    "solve_fixed",
    "sparse_matrix",
    "to_scipy",
]
