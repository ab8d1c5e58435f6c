"""PyTorch Geometric: a transform that adds the operators, and a ``Data`` type that batches them.

Needs the optional extra ``pyg`` (``pip install torch_edgevf[pyg]``: ``torch-geometric``,
pure Python; neither ``torch-scatter`` nor ``torch-sparse`` is used).

* :class:`ComputeOperators` (a ``BaseTransform``) takes a ``Data(pos, face)`` (``face`` in
  PyG's ``(3, F)`` layout) and returns an :class:`OperatorData` with what the networks of
  :mod:`torch_edgevf.learning.models` need: the operators of
  :func:`~torch_edgevf.learning.precompute.compute_operators` (read from an
  :class:`~torch_edgevf.learning.cache.OperatorCache` when a cache folder is given) and
  heat kernel signatures as vertex features ``x``. Use it as a dataset's ``pre_transform``
  (computed once, saved with the dataset) or ``transform``.
* :class:`OperatorData` tells PyG's ``DataLoader`` how to batch them (``__inc__`` /
  ``__cat_dim__``): per-vertex, per-edge and per-face tensors are concatenated, edge
  endpoints offset by the number of vertices before them and face edges by the number of
  edges, eigenvalues stacked to ``(B, k)``, and the sparse operators, held as index and value
  pairs, offset by rows and columns so that they are block diagonal. The pairs survive
  everything PyG does with a ``Data`` (``InMemoryDataset``, ``to_data_list``, ``.to()``,
  worker processes).
* :func:`to_mesh_batch` (or ``batch.to_mesh_batch()``) turns a PyG batch (or one
  ``OperatorData``) into the library's :class:`~torch_edgevf.learning.batching.MeshBatch`;
  the networks call it themselves, so ``model(batch)`` takes the PyG batch as it is.

The attributes that :class:`ComputeOperators` adds, per mesh (``V`` vertices, ``E`` edges,
``F`` faces; the names of :class:`~torch_edgevf.learning.precompute.MeshFields`):

========================================  ===================  =========================
attribute                                 shape                batched
========================================  ===================  =========================
``x``                                     ``(V, C)``           concatenated
``mesh_edge``                             ``(2, E)`` int64     along dim 1, ``+ V``
``face_edge``                             ``(3, F)`` int64     along dim 1, ``+ E``
``edge_mass``, ``edge_evecs``             ``(E,)``, ``(E, k)``  concatenated
``vertex_mass``, ``vertex_evecs``         ``(V,)``, ``(V, k)``  concatenated
``face_area``                             ``(F,)``             concatenated
``edge_evals``, ``vertex_evals``          ``(k,)``             stacked to ``(B, k)``
``<op>_index``, ``<op>_value``            ``(2, nnz)``, nnz    along the last dim, ``+ (rows, cols)``
``n``, ``num_mesh_edges``,                int                  a ``(B,)`` tensor
``num_mesh_faces``
========================================  ===================  =========================

with ``<op>`` each of ``gradient`` (``(E, V)``), ``connection_laplacian`` (``(E, E)``)
and ``vertex_gradient`` (``(V, V)``, with ``vertex_gradient=True``). ``pos``, ``face`` and
every other attribute of the input (``y``, ...) are kept as they are.
"""

from __future__ import annotations

from typing import Any

import torch
from torch_geometric.data import Data
from torch_geometric.transforms import BaseTransform

from .learning.batching import MeshBatch
from .learning.cache import OperatorCache
from .learning.precompute import MeshOperators, compute_operators, heat_kernel_signature

__all__ = ["ComputeOperators", "OperatorData", "to_mesh_batch", "FEATURES"]

#: the vertex features :class:`ComputeOperators` can add: the logarithm of the heat kernel
#: signature (the input of the recommended ``EdgeFieldNet``), the signature itself
#: (DiffusionNet's input as published), or none (``x`` as given)
FEATURES = ("log_hks", "hks", None)

#: the sparse operators: name -> (rows, cols) as "vertices" / "edges"
_OPERATORS = {
    "gradient": ("edges", "vertices"),
    "connection_laplacian": ("edges", "edges"),
    "vertex_gradient": ("vertices", "vertices"),
}
_PER_VERTEX = ("vertex_mass", "vertex_evecs")
_PER_EDGE = ("edge_mass", "edge_evecs")
_STACKED = ("edge_evals", "vertex_evals")
_REQUIRED = (
    "pos",
    "face",
    "mesh_edge",
    "face_edge",
    "face_area",
    *_PER_VERTEX,
    *_PER_EDGE,
    *_STACKED,
    "gradient_index",
    "gradient_value",
    "connection_laplacian_index",
    "connection_laplacian_value",
    "num_mesh_edges",
    "num_mesh_faces",
    "n",
)


class OperatorData(Data):
    """A PyG ``Data`` with the operators of :class:`ComputeOperators`, batched correctly.

    See the module docstring for its attributes and how ``DataLoader`` batches each.
    :meth:`to_mesh_batch` gives the :class:`~torch_edgevf.learning.batching.MeshBatch` the
    networks take (they call it themselves).
    """

    def _count(self, what: str) -> int:
        if what == "vertices":
            return int(self.num_nodes)
        return int(self.num_mesh_edges)

    def __inc__(self, key: str, value: Any, *args, **kwargs) -> Any:
        if key == "mesh_edge":
            return int(self.num_nodes)
        if key == "face_edge":
            return int(self.num_mesh_edges)
        if key.endswith("_index") and key[: -len("_index")] in _OPERATORS:
            rows, cols = _OPERATORS[key[: -len("_index")]]
            return torch.tensor([[self._count(rows)], [self._count(cols)]])
        if key in (*_PER_VERTEX, *_PER_EDGE, *_STACKED, "face_area", "n", "num_mesh_edges", "num_mesh_faces"):
            return 0
        if key.endswith("_value") and key[: -len("_value")] in _OPERATORS:
            return 0
        return super().__inc__(key, value, *args, **kwargs)

    def __cat_dim__(self, key: str, value: Any, *args, **kwargs) -> Any:
        if key in ("mesh_edge", "face_edge"):
            return 1
        if key.endswith("_index") and key[: -len("_index")] in _OPERATORS:
            return 1
        if key in _STACKED:
            return None
        if key in (*_PER_VERTEX, *_PER_EDGE, "face_area"):
            return 0
        if key.endswith("_value") and key[: -len("_value")] in _OPERATORS:
            return 0
        return super().__cat_dim__(key, value, *args, **kwargs)

    def to_mesh_batch(self) -> MeshBatch:
        """The :class:`~torch_edgevf.learning.batching.MeshBatch` of this mesh or batch
        (:func:`to_mesh_batch`)."""
        return to_mesh_batch(self)


# PyG's InMemoryDataset saves the class of its data beside the tensors and loads them with
# torch.load(weights_only=True): the class is a plain Data, safe to name there
torch.serialization.add_safe_globals([OperatorData])


def _check_input(data) -> tuple[torch.Tensor, torch.Tensor]:
    """``(pos, face)`` of a ``Data``, or ``ValueError`` naming what is wrong."""
    if not isinstance(data, Data):
        raise ValueError(f"ComputeOperators takes a torch_geometric.data.Data, got {type(data).__name__}")
    pos, face = getattr(data, "pos", None), getattr(data, "face", None)
    if not isinstance(pos, torch.Tensor):
        raise ValueError("ComputeOperators needs data.pos, the (V, 3) vertex positions")
    if pos.dim() != 2 or pos.shape[1] != 3 or pos.shape[0] == 0:
        raise ValueError(f"data.pos must have shape (V, 3), got {tuple(pos.shape)}")
    if not pos.is_floating_point():
        raise ValueError(f"data.pos must be a floating tensor, got {pos.dtype}")
    if not isinstance(face, torch.Tensor):
        raise ValueError(
            "ComputeOperators needs data.face, the (3, F) triangles (a mesh: PyG's point clouds "
            "and graphs have no faces)"
        )
    if face.dim() != 2 or face.shape[0] != 3 or face.shape[1] == 0:
        hint = " (PyG's layout is (3, F): pass face.t())" if face.dim() == 2 and face.shape[1] == 3 else ""
        raise ValueError(f"data.face must have shape (3, F), got {tuple(face.shape)}{hint}")
    if face.is_floating_point() or face.is_complex() or face.dtype == torch.bool:
        raise ValueError(f"data.face must be an integer tensor, got {face.dtype}")
    return pos, face


class ComputeOperators(BaseTransform):
    """Add the operators and input features of the networks to a ``Data(pos, face)``.

    Returns an :class:`OperatorData` (a new object: the input is never modified) with the
    attributes listed in the module docstring. The operators are those of
    :func:`~torch_edgevf.learning.precompute.compute_operators`, computed on the CPU in
    float64 (on a CPU copy of ``pos``) and returned in ``dtype``; with ``cache_dir`` they
    are read from (or written to) an :class:`~torch_edgevf.learning.cache.OperatorCache`
    there. The features are heat kernel signatures
    (:func:`~torch_edgevf.learning.precompute.heat_kernel_signature`, ``hks_count`` times,
    scale normalised), appended to ``x`` where the input has one.

    Parameters
    ----------
    n, k_edge, k_vertex, vertex_laplacian, vertex_gradient
        Options of :func:`~torch_edgevf.learning.precompute.compute_operators`;
        ``vertex_gradient=True`` (default) adds what ``DiffusionNet`` and
        ``EdgeFieldNet(vector="vertex")`` need.
    features : {"log_hks", "hks", None}, see :data:`FEATURES`
    hks_count : int, number of signature times
    dtype : torch.float32 (default) or torch.float64, of the real tensors added (complex
        ones in the matching complex dtype); that of the network's parameters
    cache_dir : path of an operator cache, or None (compute every time)

    Raises
    ------
    ValueError
        For a ``Data`` without ``pos`` or ``face``, shapes other than ``(V, 3)`` and
        ``(3, F)``, an ``x`` with another number of rows, and every mesh that
        :func:`~torch_edgevf.learning.precompute.compute_operators` refuses.
    """

    def __init__(
        self,
        n: int = 1,
        k_edge: int = 32,
        k_vertex: int = 32,
        vertex_laplacian: str = "cotan",
        vertex_gradient: bool = True,
        features: str | None = "log_hks",
        hks_count: int = 16,
        dtype: torch.dtype = torch.float32,
        cache_dir=None,
    ):
        if features not in FEATURES:
            raise ValueError(f"features must be one of {FEATURES}, got {features!r}")
        if dtype not in (torch.float32, torch.float64):
            raise ValueError(f"dtype must be torch.float32 or torch.float64, got {dtype!r}")
        if not isinstance(hks_count, int) or isinstance(hks_count, bool) or hks_count < 1:
            raise ValueError(f"hks_count must be a positive integer, got {hks_count!r}")
        self.options: dict[str, Any] = dict(
            n=n,
            k_edge=k_edge,
            k_vertex=k_vertex,
            vertex_laplacian=vertex_laplacian,
            vertex_gradient=vertex_gradient,
        )
        self.features, self.hks_count, self.dtype = features, hks_count, dtype
        self.cache = OperatorCache(cache_dir) if cache_dir is not None else None

    def __repr__(self) -> str:
        options = ", ".join(f"{k}={v!r}" for k, v in self.options.items())
        return f"{type(self).__name__}({options}, features={self.features!r}, dtype={self.dtype})"

    def operators(self, pos: torch.Tensor, face: torch.Tensor) -> MeshOperators:
        """The float64 operators of a mesh (``face`` ``(3, F)``), from the cache if there is one."""
        verts = pos.detach().cpu().to(torch.float64)
        faces = face.detach().cpu().to(torch.int64).t().contiguous()
        if self.cache is not None:
            return self.cache.get(verts, faces, **self.options)
        return compute_operators(verts, faces, **self.options)

    def forward(self, data) -> OperatorData:
        pos, face = _check_input(data)
        x = getattr(data, "x", None)
        if x is not None and (not isinstance(x, torch.Tensor) or x.dim() != 2 or x.shape[0] != pos.shape[0]):
            shape = tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__
            raise ValueError(f"data.x must have shape (V, C) with V = {pos.shape[0]}, got {shape}")
        o = self.operators(pos, face)
        out = OperatorData(**{key: value for key, value in data.items()})
        device = pos.device
        features = []
        if x is not None:
            features.append(x.to(self.dtype))
        if self.features is not None:
            area = float(o.face_area.sum())
            hks = heat_kernel_signature(
                o.vertex_evals,
                o.vertex_evecs,
                count=self.hks_count,
                area=area,
                log=self.features == "log_hks",
            )
            features.append(hks.to(device=device, dtype=self.dtype))
        if features:
            out.x = torch.cat(features, dim=1)
        ops = o.to(self.dtype)
        out.mesh_edge = ops.edges.t().contiguous().to(device)
        out.face_edge = ops.face_edges.t().contiguous().to(device)
        for name in (*_PER_VERTEX, *_PER_EDGE, *_STACKED, "face_area"):
            setattr(out, name, getattr(ops, name).to(device))
        for name in _OPERATORS:
            op = getattr(ops, name)
            if op is None:
                continue
            op = op.coalesce()
            setattr(out, f"{name}_index", op.indices().to(device))
            setattr(out, f"{name}_value", op.values().to(device))
        out.n = int(ops.n)
        out.num_mesh_edges = ops.num_edges
        out.num_mesh_faces = ops.num_faces
        return out


def _counts(value, name: str) -> torch.Tensor:
    """An int or a ``(B,)`` tensor of per-mesh counts as a ``(B,)`` int64 tensor."""
    t = torch.as_tensor(value).reshape(-1)
    if t.dtype not in (torch.int32, torch.int64):
        raise ValueError(f"{name} must hold integers, got {t.dtype}")
    return t.to(torch.int64)


def _offsets(counts: torch.Tensor) -> torch.Tensor:
    return torch.cat([counts.new_zeros(1), counts.cumsum(0)])


def to_mesh_batch(data) -> MeshBatch:
    """The :class:`~torch_edgevf.learning.batching.MeshBatch` of a PyG batch of
    :class:`OperatorData` (or of one of them): what the networks take.

    ``features`` are ``x`` (None where there is none), ``labels`` are ``y`` (a scalar
    ``y`` becomes a ``(1,)`` tensor), the sparse operators are built block diagonal from
    their index and value pairs, and the offsets and per-element mesh indices come from
    PyG's ``ptr`` and ``batch`` and from ``num_mesh_edges`` / ``num_mesh_faces``. The
    tensors stay on the device of the data.

    Raises
    ------
    ValueError
        The data lacks an attribute of :class:`ComputeOperators` (it names it), or its
        meshes have different ``n``.
    """
    missing = [name for name in _REQUIRED if getattr(data, name, None) is None]
    if not isinstance(data, Data) or missing:
        raise ValueError(
            "to_mesh_batch needs the attributes of ComputeOperators; missing "
            f"{missing or type(data).__name__}: apply torch_edgevf.pyg.ComputeOperators to each "
            "Data (transform= or pre_transform=)"
        )
    device = data.pos.device
    nv_total = int(data.pos.shape[0])
    ptr = getattr(data, "ptr", None)
    vertex_offsets = ptr.to(torch.int64) if ptr is not None else torch.tensor([0, nv_total], device=device)
    edge_counts = _counts(data.num_mesh_edges, "num_mesh_edges").to(device)
    face_counts = _counts(data.num_mesh_faces, "num_mesh_faces").to(device)
    vertex_counts = vertex_offsets[1:] - vertex_offsets[:-1]
    num_meshes = int(vertex_counts.shape[0])
    if edge_counts.shape[0] != num_meshes or face_counts.shape[0] != num_meshes:
        raise ValueError(
            f"the batch has {num_meshes} meshes by its vertices but {edge_counts.shape[0]} edge and "
            f"{face_counts.shape[0]} face counts"
        )
    n = torch.as_tensor(data.n).reshape(-1)
    if bool((n != n[0]).any()):
        raise ValueError(f"all meshes of a batch need the same n, got {sorted(set(n.tolist()))}")
    edge_offsets, face_offsets = _offsets(edge_counts), _offsets(face_counts)
    sizes = {"vertices": nv_total, "edges": int(edge_offsets[-1])}

    def operator(name: str) -> torch.Tensor | None:
        index = getattr(data, f"{name}_index", None)
        if index is None:
            return None
        rows, cols = _OPERATORS[name]
        # each mesh's pairs are coalesced (sorted by row, then column) and the blocks are
        # offset in both rows and columns, so the whole stays sorted
        return torch.sparse_coo_tensor(
            index,
            getattr(data, f"{name}_value"),
            (sizes[rows], sizes[cols]),
            is_coalesced=True,
            check_invariants=False,
        )

    def per_mesh(counts: torch.Tensor) -> torch.Tensor:
        return torch.repeat_interleave(torch.arange(num_meshes, device=device), counts)

    def stacked(t: torch.Tensor) -> torch.Tensor:
        return t if t.dim() == 2 else t.unsqueeze(0)

    labels = getattr(data, "y", None)
    if labels is not None:
        labels = torch.as_tensor(labels, device=device)
        labels = labels.reshape(1) if labels.dim() == 0 else labels
    vertex_batch = getattr(data, "batch", None)
    gradient = operator("gradient")
    laplacian = operator("connection_laplacian")
    assert gradient is not None and laplacian is not None  # required above
    return MeshBatch(
        features=getattr(data, "x", None),  # type: ignore[arg-type]  # the networks check it
        labels=labels,
        verts=data.pos.to(data.edge_mass.dtype),
        faces=data.face.t().to(torch.int64),
        edges=data.mesh_edge.t(),
        face_edges=data.face_edge.t(),
        edge_mass=data.edge_mass,
        vertex_mass=data.vertex_mass,
        face_area=data.face_area,
        gradient=gradient,
        connection_laplacian=laplacian,
        edge_evals=stacked(data.edge_evals),
        edge_evecs=data.edge_evecs,
        vertex_evals=stacked(data.vertex_evals),
        vertex_evecs=data.vertex_evecs,
        vertex_gradient=operator("vertex_gradient"),
        vertex_offsets=vertex_offsets,
        edge_offsets=edge_offsets,
        face_offsets=face_offsets,
        vertex_batch=vertex_batch if vertex_batch is not None else per_mesh(vertex_counts),
        edge_batch=per_mesh(edge_counts),
        face_batch=per_mesh(face_counts),
        indices=torch.arange(num_meshes, device=device),
    )
