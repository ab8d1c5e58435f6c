"""Learning on meshes with edge-based fields.

* :mod:`.layers`: complex layers on edge fields (diffusion, gradient features, pooling);
* :mod:`.models`: the edge-field network (recommended) and a faithful DiffusionNet;
* :mod:`.losses`: differentiable energies of fields and spectra;
* :mod:`.precompute`: the per-mesh operators the networks take, and input features;
* :mod:`.cache`: an on-disk cache of them;
* :mod:`.batching`: several meshes as one batch (a ``DataLoader``'s ``collate_fn``);
* :mod:`.datasets`: mesh datasets (the Princeton Segmentation Benchmark);
* :mod:`.augment`: random stretches and smooth warps of meshes, for training;
* :mod:`.prepare`: the PSB file built from the benchmark's files (``edgevf prepare-psb``);
* :mod:`.progress`: a progress bar for the precomputation.

The names a training script needs are exported here: ``EdgeFieldNet``, ``DiffusionNet``,
``compute_operators``, ``heat_kernel_signature``, ``OperatorCache``, ``MeshSample``,
``collate_meshes``, ``PSBDataset`` and ``resolve_device`` (a ``--device`` option checked).
"""

from .._device import resolve_device
from . import augment, batching, cache, datasets, layers, losses, models, precompute, progress
from .batching import MeshBatch, MeshSample, collate_meshes
from .cache import OperatorCache
from .datasets import PSBDataset
from .models import DiffusionNet, EdgeFieldNet
from .precompute import compute_operators, heat_kernel_signature, mean_curvature_signature

__all__ = [
    "augment",
    "batching",
    "cache",
    "datasets",
    "layers",
    "losses",
    "models",
    "precompute",
    "progress",
    "EdgeFieldNet",
    "DiffusionNet",
    "compute_operators",
    "heat_kernel_signature",
    "mean_curvature_signature",
    "OperatorCache",
    "MeshSample",
    "MeshBatch",
    "collate_meshes",
    "PSBDataset",
    "resolve_device",
]
