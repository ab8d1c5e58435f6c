"""Learning on meshes with edge-based fields.

* :mod:`.layers`: complex layers on edge fields (diffusion, gradient features, pooling);
* :mod:`.models`: networks built from them (and a DiffusionNet-style baseline);
* :mod:`.losses`: differentiable energies of fields and spectra;
* :mod:`.precompute`: the per-mesh operators the layers take;
* :mod:`.cache`: an on-disk cache of them;
* :mod:`.batching`: several meshes as one batch (a ``DataLoader``'s ``collate_fn``);
* :mod:`.datasets`: the Princeton Segmentation Benchmark;
* :mod:`.augment`: random stretches and smooth warps of meshes, for training;
* :mod:`.progress`: a progress bar for the precomputation.

``torch_edgevf.nn``, ``torch_edgevf.models``, ``torch_edgevf.losses`` and
``torch_edgevf.data`` re-export these modules under their earlier names.
"""

from . import augment, batching, cache, datasets, layers, losses, models, precompute, progress

__all__ = ["augment", "batching", "cache", "datasets", "layers", "losses", "models", "precompute", "progress"]
