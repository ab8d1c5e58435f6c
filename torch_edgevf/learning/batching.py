"""Batches of meshes of different sizes, as one disconnected mesh.

:func:`collate_meshes` concatenates features, offsets indices, makes the sparse operators
block diagonal and adds batch index vectors; it is the ``collate_fn`` of a
``DataLoader`` (worker processes included).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from .._validation import mesh_list
from .precompute import MeshFields, MeshOperators, compute_operators

__all__ = ["MeshSample", "MeshBatch", "collate_meshes"]


@dataclass
class MeshSample:
    """One item of a mesh dataset: operators, vertex features ``(V, C)`` and a label.

    ``label`` is an int (whole-shape), or a ``(V,)`` / ``(F,)`` int tensor (segmentation).
    """

    operators: MeshOperators
    features: torch.Tensor
    label: int | torch.Tensor | None = None
    index: int = -1


def _block_diagonal(mats: Sequence[torch.Tensor], row_offsets, col_offsets) -> torch.Tensor:
    idx, vals = [], []
    for m, r, c in zip(mats, row_offsets, col_offsets):
        m = m.coalesce()
        idx.append(m.indices() + torch.tensor([[r], [c]], device=m.device))
        vals.append(m.values())
    shape = (int(row_offsets[-1]), int(col_offsets[-1]))
    return torch.sparse_coo_tensor(
        torch.cat(idx, 1), torch.cat(vals), shape, is_coalesced=True, check_invariants=False
    )


@dataclass(kw_only=True)
class MeshBatch(MeshFields):
    """Several meshes as one disconnected mesh: what the models take.

    The tensors of :class:`~torch_edgevf.learning.precompute.MeshFields`, concatenated:
    vertices, edges and faces of mesh ``b`` are rows ``offsets[b]:offsets[b+1]``;
    ``edges``, ``faces`` and ``face_edges`` hold global indices; sparse operators are
    block diagonal; eigenpairs are stacked row-wise with ``edge_evals``/``vertex_evals``
    of shape ``(B, k)``. A single mesh is a batch of one (:meth:`from_operators`).

    Attributes
    ----------
    features : (V, C) tensor, the vertex features of all meshes
    labels : (B,) or (V,) / (F,) int64 tensor, or None
    vertex_offsets, edge_offsets, face_offsets : (B + 1,) int64 tensors
    vertex_batch, edge_batch, face_batch : (V,), (E,), (F,) int64 tensors, the mesh of each element
    indices : (B,) int64 tensor, the dataset index of each mesh
    """

    features: torch.Tensor
    labels: torch.Tensor | None
    vertex_offsets: torch.Tensor
    edge_offsets: torch.Tensor
    face_offsets: torch.Tensor
    vertex_batch: torch.Tensor
    edge_batch: torch.Tensor
    face_batch: torch.Tensor
    indices: torch.Tensor = field(default_factory=lambda: torch.zeros(0, dtype=torch.int64))

    @property
    def num_meshes(self) -> int:
        return int(self.vertex_offsets.shape[0] - 1)

    def host_offsets(self, kind: str) -> tuple[int, ...]:
        """The ``{kind}_offsets`` (``kind`` one of vertex, edge, face) as Python ints.

        Kept with the batch (and carried by :meth:`to`), so that the networks slice the
        meshes of a batch on an accelerator without reading the offsets back from it at
        every layer (a synchronisation each), and on the ``meta`` device at all.
        """
        tensor = getattr(self, f"{kind}_offsets")
        cache = self.__dict__.setdefault("_host_offsets", {})
        held = cache.get(kind)
        if held is None or held[0] is not tensor:
            held = cache[kind] = (tensor, tuple(int(o) for o in tensor.tolist()))
        return held[1]

    def _moved_from(self, source) -> None:
        self._host_offsets = {
            kind: (getattr(self, f"{kind}_offsets"), source.host_offsets(kind))
            for kind in ("vertex", "edge", "face")
        }

    @classmethod
    def from_operators(cls, operators: MeshOperators, features, label=None) -> MeshBatch:
        return collate_meshes([MeshSample(operators, features, label)])

    @classmethod
    def from_meshes(cls, meshes, features, labels=None, cache=None, **options) -> MeshBatch:
        """The batch of a ``pytorch3d.structures.Meshes`` (anything with ``verts_list()`` and
        ``faces_list()``), its operators computed (:func:`compute_operators` with
        ``options``; through ``cache``, an :class:`~torch_edgevf.learning.cache.OperatorCache`,
        if given) and returned on the device of its vertices.

        Parameters
        ----------
        meshes : a batch of meshes with ``verts_list()`` / ``faces_list()``
        features : a list of ``(V_b, C)`` tensors, one per mesh, or a ``(sum V_b, C)``
            tensor of all vertices in the batch's order (pytorch3d's packed layout)
        labels : a list of ints or of ``(V_b,)`` / ``(F_b,)`` tensors, one per mesh, optional
        cache : :class:`~torch_edgevf.learning.cache.OperatorCache`, optional
        options : the options of :func:`compute_operators`; ``dtype`` defaults to that of
            the features (float32 for pytorch3d's meshes)
        """
        pairs = mesh_list(meshes)
        first = features if isinstance(features, torch.Tensor) else next(iter(features), None)
        if isinstance(first, torch.Tensor) and first.is_floating_point():
            options.setdefault("dtype", first.dtype)
        ops = [
            cache.get(v, f, **options) if cache is not None else compute_operators(v, f, **options)
            for v, f in pairs
        ]
        if isinstance(features, torch.Tensor):
            sizes = [o.num_vertices for o in ops]
            if features.dim() != 2 or features.shape[0] != sum(sizes):
                raise ValueError(
                    f"packed features must have shape ({sum(sizes)}, C) for meshes of {sizes} vertices, "
                    f"got {tuple(features.shape)}"
                )
            features = list(torch.split(features, sizes))
        features = list(features)
        labels = [None] * len(ops) if labels is None else list(labels)
        if len(features) != len(ops) or len(labels) != len(ops):
            raise ValueError(
                f"{len(ops)} meshes but {len(features)} feature tensors and {len(labels)} labels"
            )
        return collate_meshes(
            [MeshSample(o, x, lab, i) for i, (o, x, lab) in enumerate(zip(ops, features, labels))]
        )


def collate_meshes(samples: Sequence[MeshSample]) -> MeshBatch:
    """Batch meshes of different sizes (the ``collate_fn`` of a ``DataLoader``).

    Parameters
    ----------
    samples : sequence of :class:`MeshSample`, all with the same feature width, numbers
        of eigenpairs, ``n``, dtypes and kind of label.

    Returns
    -------
    MeshBatch
    """
    if not samples:
        raise ValueError("collate_meshes needs at least one sample")
    for s in samples:
        if not isinstance(s, MeshSample):
            raise ValueError(f"collate_meshes expects MeshSample items, got {type(s).__name__}")
    ops_list = [s.operators for s in samples]
    first = ops_list[0]
    device = first.verts.device
    for o, s in zip(ops_list, samples):
        if o.verts.device != device:
            raise ValueError(
                f"sample {s.index} has its operators on {o.verts.device} but sample "
                f"{samples[0].index} on {device}: batch samples on one device (operators.to(device))"
            )
        if s.features.device != device:
            raise ValueError(
                f"sample {s.index} has its features on {s.features.device} but its operators on "
                f"{device}: move one of them (features.to(device) or operators.to(device))"
            )
        if o.edge_evals.shape != first.edge_evals.shape or o.vertex_evals.shape != first.vertex_evals.shape:
            raise ValueError("all meshes of a batch need the same numbers of eigenpairs")
        if o.n != first.n or o.verts.dtype != first.verts.dtype:
            raise ValueError("all meshes of a batch need the same n and dtype")
        if (o.vertex_gradient is None) != (first.vertex_gradient is None):
            raise ValueError("either all or no meshes of a batch have a vertex_gradient")
        if s.features.dtype != o.verts.dtype:
            raise ValueError(
                f"sample {s.index} has {s.features.dtype} features but {o.verts.dtype} operators: "
                f"convert one of them (features.to({o.verts.dtype}) or operators.to({s.features.dtype}))"
            )
        if s.features.dim() != 2 or s.features.shape[0] != o.num_vertices:
            raise ValueError(
                f"features must have shape (V, C) with V = {o.num_vertices}, got {tuple(s.features.shape)}"
            )
        if s.features.shape[1] != samples[0].features.shape[1]:
            raise ValueError("all samples of a batch need the same number of feature channels")
    # the offsets are computed on the host and kept there too (MeshBatch.host_offsets)
    host = {
        kind: np.cumsum([0] + [getattr(o, f"num_{kind}") for o in ops_list]).tolist()
        for kind in ("vertices", "edges", "faces")
    }
    nv, ne, nf = (torch.tensor(host[k], dtype=torch.int64, device=device) for k in host)
    cat = torch.cat

    def batch_vector(kind):
        counts = np.diff(host[kind]).tolist()
        return torch.repeat_interleave(
            torch.arange(len(samples), device=device),
            torch.tensor(counts, dtype=torch.int64, device=device),
            output_size=host[kind][-1],
        )

    labels: list[Any] = [s.label for s in samples]  # narrowed by the checks below
    if all(lab is None for lab in labels):
        label_t = None
    elif all(
        isinstance(lab, (int, np.integer)) or (isinstance(lab, torch.Tensor) and lab.dim() == 0)
        for lab in labels
    ):
        label_t = torch.tensor([int(lab) for lab in labels], dtype=torch.int64, device=device)
    elif all(isinstance(lab, torch.Tensor) and lab.dim() == 1 for lab in labels):
        label_t = cat([lab.to(device=device, dtype=torch.int64) for lab in labels])
    else:
        raise ValueError("labels must be all ints, all 1-D tensors, or all None")
    batch = MeshBatch(
        features=cat([s.features for s in samples]),
        labels=label_t,
        verts=cat([o.verts for o in ops_list]),
        faces=cat([o.faces + host["vertices"][b] for b, o in enumerate(ops_list)]),
        edges=cat([o.edges + host["vertices"][b] for b, o in enumerate(ops_list)]),
        face_edges=cat([o.face_edges + host["edges"][b] for b, o in enumerate(ops_list)]),
        edge_mass=cat([o.edge_mass for o in ops_list]),
        vertex_mass=cat([o.vertex_mass for o in ops_list]),
        face_area=cat([o.face_area for o in ops_list]),
        gradient=_block_diagonal([o.gradient for o in ops_list], host["edges"], host["vertices"]),
        connection_laplacian=_block_diagonal(
            [o.connection_laplacian for o in ops_list], host["edges"], host["edges"]
        ),
        edge_evals=torch.stack([o.edge_evals for o in ops_list]),
        edge_evecs=cat([o.edge_evecs for o in ops_list]),
        vertex_evals=torch.stack([o.vertex_evals for o in ops_list]),
        vertex_evecs=cat([o.vertex_evecs for o in ops_list]),
        vertex_gradient=(
            None
            if first.vertex_gradient is None
            else _block_diagonal(
                [o.vertex_gradient for o in ops_list if o.vertex_gradient is not None],
                host["vertices"],
                host["vertices"],
            )
        ),
        vertex_offsets=nv,
        edge_offsets=ne,
        face_offsets=nf,
        vertex_batch=batch_vector("vertices"),
        edge_batch=batch_vector("edges"),
        face_batch=batch_vector("faces"),
        indices=torch.tensor([s.index for s in samples], dtype=torch.int64, device=device),
    )
    batch._host_offsets = {
        kind: (getattr(batch, f"{kind}_offsets"), tuple(host[plural]))
        for kind, plural in (("vertex", "vertices"), ("edge", "edges"), ("face", "faces"))
    }
    return batch
