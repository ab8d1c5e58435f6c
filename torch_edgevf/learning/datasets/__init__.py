"""Mesh datasets for learning, one module each.

* :mod:`.psb`: the Princeton Segmentation Benchmark, watertight track, 2,000 faces per mesh
  (shape classification; built by ``edgevf prepare-psb``);
* :mod:`.rna`: the RNA Surface Segmentation Dataset (per-vertex segmentation of molecular
  surfaces, read as published, every vertex of every file kept).
"""

from . import psb, rna
from .psb import *  # noqa: F403
from .rna import *  # noqa: F403

__all__ = [*psb.__all__, *rna.__all__]
