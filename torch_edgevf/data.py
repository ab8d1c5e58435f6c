"""Data for learning, under the name ``torch_edgevf.data``.

Re-exports :mod:`torch_edgevf.learning.precompute`, :mod:`~torch_edgevf.learning.cache`,
:mod:`~torch_edgevf.learning.batching`, :mod:`~torch_edgevf.learning.datasets`,
:mod:`~torch_edgevf.learning.progress` and the mesh repair of :mod:`torch_edgevf.mesh.repair`.
"""

from .learning.batching import (
    MeshBatch,
    MeshSample,
    collate_meshes,
)
from .learning.cache import (
    OperatorCache,
)
from .learning.datasets import (
    DEFAULT_PSB_PATH,
    PSB_ENV,
    PSBDataset,
    psb_path,
)
from .learning.precompute import (
    MeshFields,
    MeshOperators,
    compute_operators,
    heat_kernel_signature,
    mean_curvature_signature,
    vertex_gradient_operator,
)
from .learning.progress import (
    progress,
)
from .mesh.repair import (
    find_degenerate_faces,
    repair_degenerate_faces,
)

__all__ = [
    "MeshBatch",
    "MeshSample",
    "collate_meshes",
    "OperatorCache",
    "DEFAULT_PSB_PATH",
    "PSB_ENV",
    "PSBDataset",
    "psb_path",
    "MeshFields",
    "MeshOperators",
    "compute_operators",
    "heat_kernel_signature",
    "mean_curvature_signature",
    "vertex_gradient_operator",
    "progress",
    "find_degenerate_faces",
    "repair_degenerate_faces",
]
