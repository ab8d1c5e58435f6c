"""The RNA Surface Segmentation Dataset, read as published, with every vertex's label kept.

Poulenard, Rakotosaona, Ponty, Ovsjanikov, "Effective Rotation-invariant Point CNN with
Spherical Harmonics Kernels", 3DV 2019 (MIT licence): 683 molecular surfaces
(``git clone https://github.com/nmwsharp/RNA-Surface-Segmentation-Dataset``), laid out as

- ``off/NAME.off``: triangles; many meshes hold vertices that belong to no face (they
  still carry labels), some have non-manifold vertices, several components, poor elements;
- ``labels/NAME.txt``: one integer per vertex of the OFF file, in ``[-1, 258]``; the
  reader adds 1 (:data:`RNA_CLASSES` = 260 classes);
- ``train.txt`` / ``test.txt``: the official split (file names, one a line).

The mesh a network sees may differ from the file's (repaired, decimated), so each
:class:`RNAMesh` carries ``vertex_map``: for every vertex of the file, the vertex of the
network's mesh that stands for it (the nearest one). Predictions per vertex of the
network's mesh are carried back with ``pred[vertex_map]`` and scored against
``labels``, every vertex of the file counted, as the dataset's authors ask.
"""

from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.spatial import cKDTree

from ...io import read_triangles
from ...mesh.repair import repair
from ..batching import MeshSample
from ..cache import OperatorCache
from ..precompute import compute_operators, heat_kernel_signature
from ..progress import progress

logger = logging.getLogger(__name__)

__all__ = [
    "RNA_CLASSES",
    "RNA_ENV",
    "RNAMesh",
    "RNADataset",
    "prepare_rna_mesh",
    "read_rna_mesh",
    "rna_path",
    "rna_split",
]

RNA_ENV = "TORCH_EDGEVF_RNA"
"""Environment variable naming the dataset's folder when no path is given."""

#: labels ``[-1, 258]`` shifted by one
RNA_CLASSES = 260


def rna_path(path=None) -> Path:
    """The dataset folder: ``path``, else ``$TORCH_EDGEVF_RNA``; it must hold ``off/`` and ``labels/``."""
    how = "git clone https://github.com/nmwsharp/RNA-Surface-Segmentation-Dataset"
    if path is None:
        path = os.environ.get(RNA_ENV) or None
        if path is None:
            raise ValueError(f"no RNA dataset folder given: pass path= or set ${RNA_ENV} ({how})")
    path = Path(path).expanduser()
    for sub in ("off", "labels"):
        if not (path / sub).is_dir():
            raise ValueError(f"{path} is not the RNA dataset folder: it has no {sub}/ ({how})")
    return path


def _names(path: Path) -> list[str]:
    return [Path(line.strip()).stem for line in path.read_text().splitlines() if line.strip()]


def rna_split(root=None, split_file=None) -> dict[str, list[str]]:
    """The mesh names of the training and test sets, ``{"train": [...], "test": [...]}``.

    Default: the official split (``train.txt``, ``test.txt``). ``split_file``: a JSON file
    ``{"train": [names], "test": [names]}`` (names without ``.off``). Raises ``ValueError``
    for a name without its mesh, a mesh in both sets, or a malformed file.
    """
    root = rna_path(root)
    if split_file is None:
        split = {part: _names(root / f"{part}.txt") for part in ("train", "test")}
    else:
        try:
            split = json.loads(Path(split_file).read_text())
        except (OSError, json.JSONDecodeError) as error:
            raise ValueError(f"cannot read the split file {split_file}: {error}") from error
        if not isinstance(split, dict) or not all(
            isinstance(split.get(k), list) and all(isinstance(n, str) for n in split[k])
            for k in ("train", "test")
        ):
            raise ValueError(f'split file {split_file} must be {{"train": [names], "test": [names]}}')
        split = {k: [Path(n).stem for n in split[k]] for k in ("train", "test")}
    both = sorted(set(split["train"]) & set(split["test"]))
    if both:
        raise ValueError(f"meshes in both the training and the test set: {both[:10]}")
    missing = [n for k in ("train", "test") for n in split[k] if not (root / "off" / f"{n}.off").is_file()]
    if missing:
        raise ValueError(f"{len(missing)} meshes of the split are not in {root / 'off'}: {missing[:10]}")
    return split


def read_rna_mesh(root, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The file's vertices ``(V0, 3)`` float64, triangles ``(F, 3)`` int64 and labels ``(V0,)``
    int64 in ``[0, 260)``, every vertex kept (unreferenced ones included).

    Raises ``ValueError`` naming the mesh when the label file does not have one label per
    vertex or a label lies outside ``[-1, 258]``.
    """
    root = rna_path(root)
    verts, faces, _ = read_triangles(root / "off" / f"{name}.off")
    label_file = root / "labels" / f"{name}.txt"
    try:
        labels = np.loadtxt(label_file, dtype=np.int64, ndmin=1) + 1
    except (OSError, ValueError) as error:
        raise ValueError(f"RNA mesh {name}: cannot read its labels {label_file}: {error}") from error
    if labels.shape != (len(verts),):
        raise ValueError(f"RNA mesh {name}: {labels.shape[0]} labels for {len(verts)} vertices")
    if labels.min() < 0 or labels.max() >= RNA_CLASSES:
        raise ValueError(f"RNA mesh {name}: labels outside [-1, {RNA_CLASSES - 2}]")
    return verts, faces, labels


@dataclass
class RNAMesh:
    """One molecule: the file's vertices and labels, and the mesh a network sees.

    Attributes
    ----------
    name : str
    labels : (V0,) int64 array, the label of every vertex of the file
    verts, faces : (V, 3) float64 and (F, 3) int64 arrays, the network's mesh (repaired,
        and decimated with ``target_vertices``): manifold, oriented, no unreferenced vertex
    vertex_map : (V0,) int64 array, for every vertex of the file the nearest vertex of
        the network's mesh
    mesh_labels : (V,) int64 array, the label of the file's referenced vertex nearest to
        each vertex of the network's mesh (the training targets)
    report : dict, what was found and changed (unreferenced vertices, split and dropped
        elements, components, vertex counts)
    """

    name: str
    labels: np.ndarray
    verts: np.ndarray
    faces: np.ndarray
    vertex_map: np.ndarray
    mesh_labels: np.ndarray
    report: dict = field(default_factory=dict)

    def carry_back(self, per_vertex: torch.Tensor) -> torch.Tensor:
        """Values per vertex of the network's mesh ``(V, ...)`` on the file's vertices ``(V0, ...)``."""
        return per_vertex[torch.as_tensor(self.vertex_map, device=per_vertex.device)]


def _decimate(verts: np.ndarray, faces: np.ndarray, target: int) -> tuple[np.ndarray, np.ndarray]:
    try:
        import fast_simplification
    except ImportError as error:
        raise ValueError(
            "decimation (target_vertices) needs fast-simplification: pip install 'torch_edgevf[prepare]'"
        ) from error
    used = np.unique(faces)
    v, f = fast_simplification.simplify(
        verts[used], np.searchsorted(used, faces).astype(np.int32), target_reduction=1 - target / len(used)
    )
    return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)


def prepare_rna_mesh(
    verts: np.ndarray,
    faces: np.ndarray,
    labels: np.ndarray,
    name: str = "",
    target_vertices: int | None = 5000,
) -> RNAMesh:
    """The network's mesh of one molecule and the maps between it and the file's vertices.

    Quadric decimation (``fast-simplification``) to about ``target_vertices`` of the
    referenced vertices (None, or a mesh already smaller: none), then
    :func:`~torch_edgevf.mesh.repair.repair` (non-manifold edges cut, vertices split per
    fan, faces oriented, unreferenced vertices dropped). Labels go to the network's
    vertices from the nearest referenced vertex of the file, and every vertex of the file
    (referenced or not) maps to the nearest vertex of the network's mesh. The inputs are
    not modified.
    """
    verts = np.asarray(verts, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    labels = np.asarray(labels, dtype=np.int64)
    used = np.unique(faces)
    report = {
        "file_vertices": len(verts),
        "file_faces": len(faces),
        "unreferenced_vertices": len(verts) - len(used),
    }
    v, f = verts, faces
    if target_vertices is not None and len(used) > target_vertices:
        v, f = _decimate(verts, faces, target_vertices)
        report["decimated_to"] = len(np.unique(f))
    try:
        fixed = repair(v, f)
    except ValueError as error:
        raise ValueError(f"RNA mesh {name}: {error}") from error
    r = fixed.report
    report.update(
        non_manifold_vertices=len(r.non_manifold_vertices),
        non_manifold_edges=len(r.non_manifold_edges),
        dropped_faces=len(r.dropped_faces),
        components=int(fixed.topology.num_components),
    )
    mesh_verts = fixed.verts.numpy().astype(np.float64)
    mesh_faces = fixed.faces.numpy().astype(np.int64)
    report["vertices"], report["faces"] = len(mesh_verts), len(mesh_faces)
    vertex_map = cKDTree(mesh_verts).query(verts)[1].astype(np.int64)
    nearest = cKDTree(verts[used]).query(mesh_verts)[1]
    return RNAMesh(name, labels.copy(), mesh_verts, mesh_faces, vertex_map, labels[used][nearest], report)


class RNADataset(torch.utils.data.Dataset):
    """Molecules of the RNA dataset for per-vertex segmentation.

    Items are :class:`~torch_edgevf.learning.batching.MeshSample` whose ``label`` is the
    ``(V,)`` labels of the network's mesh and whose features are ``hks_count`` heat kernel
    signatures (intrinsic, from the vertex Laplacian's eigenpairs; their logarithm with
    ``log_hks=True``, the default, the input of the recommended
    :class:`~torch_edgevf.learning.models.EdgeFieldNet`); :attr:`meshes` holds each item's
    :class:`RNAMesh` (file labels and ``vertex_map``) for scoring on the file's vertices.
    Operators are computed once per mesh and kept in an :class:`OperatorCache`.

    A mesh that cannot be used (unreadable, or operators that raise) is left out with a
    warning naming it and the problem; :attr:`skipped` lists ``(name, message)``.

    Parameters
    ----------
    root : dataset folder (None: ``$TORCH_EDGEVF_RNA``)
    names : mesh names (see :func:`rna_split`)
    target_vertices : int or None, decimation target of :func:`prepare_rna_mesh`
    cache_dir : operator cache folder (None: no cache)
    k_edge, k_vertex, n, vertex_gradient : options of :func:`compute_operators`
    hks_count : int
    log_hks : bool, the logarithm of the signatures as features (default) or the signatures
    dtype : torch.float32 (default) or torch.float64
    in_memory : bool
        Keep every item's operators in memory (default); ``False`` (with ``cache_dir``)
        reads them from the cache at each access, for datasets larger than the memory.
    show_progress : bool or None

    Attributes
    ----------
    seconds : dict, per mesh whose operators this instance computed, the seconds it took
        (meshes read from the cache are not in it)
    """

    def __init__(
        self,
        root=None,
        names=None,
        target_vertices: int | None = 5000,
        cache_dir=None,
        k_edge: int = 32,
        k_vertex: int = 128,
        n: int = 1,
        vertex_gradient: bool = True,
        hks_count: int = 16,
        log_hks: bool = True,
        dtype: torch.dtype = torch.float32,
        in_memory: bool = True,
        show_progress: bool | None = None,
    ):
        if dtype not in (torch.float32, torch.float64):
            raise ValueError(f"dtype must be torch.float32 or torch.float64, got {dtype}")
        if not in_memory and cache_dir is None:
            raise ValueError("in_memory=False reads the operators from the cache: give cache_dir")
        root = rna_path(root)
        names = rna_split(root)["train"] if names is None else list(names)
        self.options: dict[str, Any] = dict(
            n=n, k_edge=k_edge, k_vertex=k_vertex, vertex_gradient=vertex_gradient
        )
        self.cache = OperatorCache(cache_dir) if cache_dir is not None else None
        self.dtype, self.hks_count, self.in_memory, self.log_hks = dtype, hks_count, in_memory, log_hks
        self.meshes: list[RNAMesh] = []
        self.skipped: list[tuple[str, str]] = []
        self.seconds: dict[str, float] = {}
        self._samples: list[MeshSample] = []
        for name in progress(names, desc="RNA operators", enabled=show_progress):
            try:
                mesh = prepare_rna_mesh(
                    *read_rna_mesh(root, name), name=name, target_vertices=target_vertices
                )
                o = self._operators(mesh)
            except ValueError as error:
                logger.warning("RNA mesh %s skipped: %s", name, error)
                self.skipped.append((name, str(error)))
                continue
            self.meshes.append(mesh)
            if in_memory:
                self._samples.append(self._sample(len(self.meshes) - 1, o))

    def _operators(self, mesh: RNAMesh):
        if self.cache is not None:
            key = self.cache.key(mesh.verts, mesh.faces, **self.options)
            o = self.cache.load(key)
            if o is not None:
                return o
        start = time.perf_counter()
        o = (
            self.cache.get(mesh.verts, mesh.faces, **self.options)
            if self.cache
            else compute_operators(mesh.verts, mesh.faces, **self.options)
        )
        self.seconds[mesh.name] = time.perf_counter() - start
        return o

    def _sample(self, i: int, o) -> MeshSample:
        feats = heat_kernel_signature(
            o.vertex_evals,
            o.vertex_evecs,
            count=self.hks_count,
            area=float(o.face_area.sum()),
            log=self.log_hks,
        )
        label = torch.from_numpy(self.meshes[i].mesh_labels)
        return MeshSample(o.to(self.dtype), feats.to(self.dtype), label, i)

    def __len__(self) -> int:
        return len(self.meshes)

    def __getitem__(self, i: int) -> MeshSample:
        if self.in_memory:
            return self._samples[i]
        return self._sample(i, self._operators(self.meshes[i]))
