"""Learning layers on complex edge features.

Features live on the edges of a mesh as complex numbers, one per channel: ``z`` of shape
``(E, C)`` is ``C`` tangent vector fields in the edge-based representation (the value at
each edge midpoint, in the frame of the edge oriented from its lower to its higher vertex
index; thesis 2.2). Every layer here is **gauge equivariant**: rotating the frame of an
edge (``z_e -> e^{i theta_e} z_e``, which is what a change of edge orientation does with
``theta_e = pi``) rotates its output the same way, or leaves it unchanged for the real
invariant readouts. Layers therefore give the same answer for any vertex numbering.

Every ``nn.Module`` is a thin wrapper over a function of this file (``LearnedDiffusion``
over :func:`spectral_diffusion` / :func:`implicit_diffusion`, ``ComplexLinear`` over
:func:`complex_linear`, ...); the tests pin each pair together.

==========================  ===========================================================
function / module           operation
==========================  ===========================================================
spectral_diffusion          ``z(t) = Phi diag(exp(-lambda t)) Phi^H M z`` (thesis 3.2)
implicit_diffusion          ``(M + t L)^{-1} M z`` (one implicit Euler step)
gradient_features           ``z = M_z^{-1} G f``: vertex scalars to edge vectors (4.2)
divergence_features         ``-M_v^{-1} G^* z = div + i curl`` per vertex (4.2, B.4)
complex_linear              ``z W``, ``W`` complex ``(C_in, C_out)``, no bias
modulus_relu                ``z relu(|z| + b) / |z|``
invariant_features          ``|z|`` and ``Re(z conj(z A))`` (real, gauge invariant)
pool_edges_to_vertices      weighted mean over the edges around each vertex
pool_edges_to_faces         weighted mean over the three edges of each face
pool_global                 weighted mean over each mesh of a batch
normalize_modulus           ``z / rms_M(z)`` per mesh and channel (scale normalisation)
dropout                     ``F.dropout`` with a faster CPU mask (the same masks)
==========================  ===========================================================

Sparse operators are torch sparse COO tensors (as returned by :mod:`torch_edgevf.operators`,
or block-diagonal ones from :func:`torch_edgevf.data.collate_meshes`); products with them
are written as gathers and ``index_add`` so that gradients reach both the features and
the operator values.
"""

from __future__ import annotations

from .diffusion import MIN_TIME, LearnedDiffusion, implicit_diffusion, positive_time, spectral_diffusion
from .dropout import Dropout, dropout
from .gradient import DivergenceFeatures, GradientFeatures, divergence_features, gradient_features
from .pointwise import (
    ComplexLinear,
    InvariantReadout,
    ModReLU,
    complex_linear,
    invariant_features,
    modulus_relu,
)
from .pooling import (
    EdgePooling,
    ModulusNorm,
    normalize_modulus,
    pool_edges_to_faces,
    pool_edges_to_vertices,
    pool_global,
)
from .sparse import adjoint_on_basis

__all__ = [
    "spectral_diffusion",
    "implicit_diffusion",
    "gradient_features",
    "divergence_features",
    "adjoint_on_basis",
    "complex_linear",
    "modulus_relu",
    "invariant_features",
    "pool_edges_to_vertices",
    "pool_edges_to_faces",
    "pool_global",
    "normalize_modulus",
    "positive_time",
    "MIN_TIME",
    "LearnedDiffusion",
    "GradientFeatures",
    "DivergenceFeatures",
    "ComplexLinear",
    "ModReLU",
    "InvariantReadout",
    "EdgePooling",
    "ModulusNorm",
    "dropout",
    "Dropout",
]
