"""The Princeton Segmentation Benchmark (watertight track, 2k faces) for shape classification."""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ...mesh.repair import find_degenerate_faces, repair_degenerate_faces
from ..batching import MeshSample
from ..cache import OperatorCache
from ..precompute import compute_operators, heat_kernel_signature
from ..progress import progress

logger = logging.getLogger(__name__)

__all__ = ["PSBDataset", "PSB_ENV", "psb_path", "psb_mesh"]

PSB_ENV = "TORCH_EDGEVF_PSB"
"""Environment variable naming ``psb_watertight_2k.npz`` when no path is given."""


def psb_path(path=None) -> Path:
    """The path of ``psb_watertight_2k.npz``: ``path``, else ``$TORCH_EDGEVF_PSB``.

    Raises
    ------
    ValueError
        Neither is given, or the file does not exist. The message says how to build the
        file (``edgevf prepare-psb``).
    """
    how = (
        "build it from the Princeton Segmentation Benchmark with "
        "'edgevf prepare-psb SRC_DIR psb_watertight_2k.npz' (see docs/learning.md)"
    )
    if path is None:
        path = os.environ.get(PSB_ENV) or None
        if path is None:
            raise ValueError(f"no PSB file given: pass path= or set ${PSB_ENV}; {how}")
    path = Path(path).expanduser()
    if not path.is_file():
        raise ValueError(f"PSB file not found: {path}; {how}")
    return path


def psb_mesh(arrays, i: int) -> tuple[np.ndarray, np.ndarray]:
    """Mesh ``i`` of the arrays of ``psb_watertight_2k.npz``: its vertices as stored
    (float32) and its faces as int64, both ``(N, 3)``.

    ``arrays`` maps names to arrays; read an ``np.load`` file into a dict first when taking
    many meshes, since an ``NpzFile`` decompresses an array again on every access."""
    vo, fo = arrays["vert_offsets"], arrays["face_offsets"]
    return arrays["verts"][vo[i] : vo[i + 1]], arrays["faces"][fo[i] : fo[i + 1]].astype(np.int64)


class PSBDataset(torch.utils.data.Dataset):
    """The Princeton Segmentation Benchmark (watertight, 2k faces) for shape classification.

    Items are :class:`MeshSample` with heat-kernel-signature vertex features (from the
    cotangent Laplacian's eigenpairs: intrinsic) and the class index as label; batch them
    with :func:`collate_meshes`. Operators are computed once (with a progress bar) and
    kept in an :class:`OperatorCache`.

    Degenerate faces: one mesh (psb id 351) has a zero-area face, which the operators
    reject. ``degenerate="repair"`` (default) collapses a short edge of each such face
    (:func:`repair_degenerate_faces`: one vertex and two faces fewer, no vertex moved)
    and logs a warning naming the psb ids; ``"skip"`` leaves such meshes out, with a warning
    listing their ids;
    ``"error"`` raises ``ValueError``.

    Parameters
    ----------
    path : path of ``psb_watertight_2k.npz``; None: ``$TORCH_EDGEVF_PSB`` (:func:`psb_path`)
    split : {"train", "test", "all"} (the file's fixed split: 16 / 4 meshes per class)
    cache_dir : path of the operator cache; None computes without caching
    n, k_edge, k_vertex, vertex_gradient : options of :func:`compute_operators`
    hks_count : int, number of HKS times
    log_hks : bool
        The features are the logarithm of the heat kernel signatures (default; the input
        of the recommended :class:`~torch_edgevf.learning.models.EdgeFieldNet`), or the
        signatures themselves (``False``; DiffusionNet's input as published).
    dtype : torch.float32 (default) or torch.float64, for the returned tensors
    degenerate : {"repair", "skip", "error"}
    ids : optional sequence of psb ids to keep (small subsets for tests)
    show_progress : bool or None (auto: a terminal, not pytest)
    """

    def __init__(
        self,
        path=None,
        split: str = "train",
        cache_dir=None,
        n: int = 1,
        k_edge: int = 32,
        k_vertex: int = 32,
        vertex_gradient: bool = True,
        hks_count: int = 16,
        log_hks: bool = True,
        dtype: torch.dtype = torch.float32,
        degenerate: str = "repair",
        ids=None,
        show_progress: bool | None = None,
    ):
        if split not in ("train", "test", "all"):
            raise ValueError(f"split must be 'train', 'test' or 'all', got {split!r}")
        if degenerate not in ("repair", "skip", "error"):
            raise ValueError(f"degenerate must be 'repair', 'skip' or 'error', got {degenerate!r}")
        if dtype not in (torch.float32, torch.float64):
            raise ValueError(f"dtype must be torch.float32 or torch.float64, got {dtype}")
        path = psb_path(path)
        with np.load(path, allow_pickle=False) as data:
            d = {name: data[name] for name in data.files}
        self.classes = [str(c) for c in d["classes"]]
        keep = np.ones(len(d["labels"]), dtype=bool)
        if split != "all":
            keep &= d["split"] == (0 if split == "train" else 1)
        if ids is not None:
            keep &= np.isin(d["psb_ids"], np.asarray(list(ids)))
        self.options: dict[str, Any] = dict(
            n=n, k_edge=k_edge, k_vertex=k_vertex, vertex_laplacian="cotan", vertex_gradient=vertex_gradient
        )
        self.cache = OperatorCache(cache_dir) if cache_dir is not None else None
        self.dtype, self.hks_count, self.log_hks = dtype, hks_count, log_hks
        meshes, repaired, skipped = [], [], []
        for i in np.nonzero(keep)[0]:
            v, f = psb_mesh(d, int(i))
            pid = int(d["psb_ids"][i])
            if len(find_degenerate_faces(v, f)):
                if degenerate == "error":
                    raise ValueError(
                        f"PSB mesh {pid} has zero-area faces {find_degenerate_faces(v, f).tolist()}"
                    )
                if degenerate == "skip":
                    skipped.append(pid)
                    continue
                v, f, _, _ = repair_degenerate_faces(v, f)
                repaired.append(pid)
            meshes.append((pid, int(d["labels"][i]), v, f))
        if skipped:
            logger.warning("PSB: skipped %d mesh(es) with zero-area faces: psb ids %s", len(skipped), skipped)
        if repaired:
            logger.warning("PSB: repaired zero-area faces (edge collapse) of psb ids %s", repaired)
        self.skipped, self.repaired = skipped, repaired
        self.psb_ids = [m[0] for m in meshes]
        self.labels = [m[1] for m in meshes]
        self.samples: list[MeshSample] = []
        for j, (_pid, label, v, f) in enumerate(
            progress(meshes, desc=f"PSB {split} operators", enabled=show_progress)
        ):
            o = (
                self.cache.get(v, f, **self.options)
                if self.cache
                else compute_operators(v, f, **self.options)
            )
            area = float(o.face_area.sum())
            feats = heat_kernel_signature(
                o.vertex_evals, o.vertex_evecs, count=hks_count, area=area, log=log_hks
            )
            self.samples.append(MeshSample(o.to(dtype), feats.to(dtype), label, j))

    def __len__(self) -> int:
        return len(self.samples)

    def __getitem__(self, i: int) -> MeshSample:
        return self.samples[i]
