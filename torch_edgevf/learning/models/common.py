"""What the networks share: their checks at the boundary, the MLP, the readout, the eigenbasis.

A network checks its arguments once, in ``__init__``, and its batch once, at the top of
``forward`` (:func:`check_batch`); the layers inside then run on inputs known to be valid
(the unchecked kernels of :mod:`torch_edgevf.learning.layers`).
"""

from __future__ import annotations

import torch
from torch import nn

from ..layers.diffusion import _spectral_diffusion
from ..layers.dropout import Dropout
from ..layers.pointwise import _invariant_products
from ..layers.pooling import _pool_edges_to_vertices, _pool_global

__all__ = [
    "HEADS",
    "VECTORS",
    "FIELDS",
    "check_options",
    "check_vector_options",
    "as_mesh_batch",
    "check_batch",
    "mini_mlp",
    "readout",
    "diffuse_vertices",
    "vertex_invariants",
    "mesh_slices",
    "offsets_of",
    "per_mesh",
    "synthesize",
    "project",
]

#: the outputs of a network: one row per mesh, per vertex or per face
HEADS = ("global", "vertex", "face")
#: the vector stream of :class:`~torch_edgevf.learning.models.EdgeFieldNet`
VECTORS = ("edge", "vertex", "none")
#: the fields of its edge stream: diffused in the L_c eigenbasis, or local on every edge
FIELDS = ("smooth", "local")


def check_options(in_channels, out_channels, width, num_blocks, head, dropout) -> None:
    """``ValueError`` naming the first argument of a network that is out of its range."""
    for name, v in (
        ("in_channels", in_channels),
        ("out_channels", out_channels),
        ("width", width),
        ("num_blocks", num_blocks),
    ):
        if not isinstance(v, int) or isinstance(v, bool) or v < (0 if name == "num_blocks" else 1):
            raise ValueError(f"{name} must be a positive integer, got {v!r}")
    if head not in HEADS:
        raise ValueError(f"head must be one of {HEADS}, got {head!r}")
    if isinstance(dropout, bool) or not isinstance(dropout, (int, float)) or not 0 <= dropout < 1:
        raise ValueError(f"dropout must be a probability in [0, 1), got {dropout!r}")


def check_vector_options(vector, fields) -> None:
    """``ValueError`` for a vector stream or a kind of fields that is not one, or fields
    chosen for a stream that has no edge fields."""
    if vector not in VECTORS:
        raise ValueError(f"vector must be one of {VECTORS}, got {vector!r}")
    if fields not in FIELDS:
        raise ValueError(f"fields must be one of {FIELDS}, got {fields!r}")
    if fields != "smooth" and vector != "edge":
        raise ValueError(f"fields={fields!r} needs vector='edge' (the edge fields), got vector={vector!r}")


def as_mesh_batch(batch):
    """``batch`` itself (a :class:`~torch_edgevf.learning.batching.MeshBatch`), or what its
    ``to_mesh_batch()`` returns where it has one (a PyG batch of ``torch_edgevf.pyg``'s
    ``OperatorData``): the networks take both."""
    convert = getattr(batch, "to_mesh_batch", None)
    return convert() if callable(convert) else batch


def check_batch(model: nn.Module, batch, in_channels: int, needs: tuple[str, ...] = ()) -> None:
    """The batch a network takes, checked once: ``features`` ``(V, in_channels)``, the
    operators in ``needs`` present, the device of every tensor the network reads that of its
    parameters, and the dtype of the features and of the operators the network reads that
    of its parameters."""
    f = getattr(batch, "features", None)
    if not isinstance(f, torch.Tensor) or f.dim() != 2 or f.shape[1] != in_channels:
        shape = tuple(f.shape) if isinstance(f, torch.Tensor) else type(f).__name__
        raise ValueError(f"batch.features must be (V, {in_channels}), got {shape}")
    for name in needs:
        if getattr(batch, name, None) is None:
            raise ValueError(f"the model needs batch.{name} (see compute_operators)")
    p = next(model.parameters())
    read = (
        "features",
        "vertex_mass",
        "vertex_evecs",
        "vertex_evals",
        "vertex_batch",
        "faces",
        "edges",
        *needs,
    )
    for name in dict.fromkeys(read):
        t = getattr(batch, name, None)
        if isinstance(t, torch.Tensor) and t.device != p.device:
            raise ValueError(
                f"batch.{name} is on {t.device} but the model's parameters are on {p.device}: "
                f"move one of them (batch.to({str(p.device)!r}) or model.to({str(t.device)!r}))"
            )
    for name in ("features", "vertex_mass", "vertex_evecs", *(n for n in ("edge_mass",) if n in needs)):
        t = getattr(batch, name)
        if t.dtype != p.dtype:
            raise ValueError(
                f"batch.{name} is {t.dtype} but the model's parameters are {p.dtype}: "
                f"convert one of them (operators.to({p.dtype}) or model.to({t.dtype}))"
            )


def mini_mlp(sizes, dropout: float = 0.5) -> nn.Sequential:
    """Linear layers with ReLU between them and dropout before every layer but the first."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        if dropout > 0 and i > 0:
            layers.append(Dropout(dropout))
        layers.append(nn.Linear(a, b))
        if i < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


def readout(x, last: nn.Linear, batch, head: str) -> torch.Tensor:
    """``last`` per vertex, then the mass-weighted mean over each mesh (``head="global"``),
    the values per vertex (``"vertex"``) or their mean over each face (``"face"``)."""
    x = last(x)
    if head == "global":
        return _pool_global(x, batch.vertex_mass.to(x.dtype), batch.vertex_batch, batch.num_meshes)
    if head == "vertex":
        return x
    return x[batch.faces].mean(1)


def diffuse_vertices(diffusion, x, batch) -> torch.Tensor:
    """The vertex scalars ``x`` diffused by ``diffusion`` (a spectral
    :class:`~torch_edgevf.learning.layers.LearnedDiffusion`) in the batch's vertex eigenbasis."""
    t = diffusion.times.to(x.dtype)
    return _spectral_diffusion(
        x,
        batch.vertex_evals.to(t.dtype),
        batch.vertex_evecs,
        batch.vertex_mass,
        t,
        offsets_of(batch, "vertex"),
    )


def vertex_invariants(u, products, batch, vector: str) -> torch.Tensor:
    """``tanh Re(u conj(u A))`` of fields ``u``, at the vertices (pooled from the edges,
    weighted by ``M_z``, for ``vector="edge"``; vertex fields as they are)."""
    inv = torch.tanh(_invariant_products(u, products))
    if vector == "edge":
        inv = _pool_edges_to_vertices(inv, batch.edges, batch.num_vertices, batch.edge_mass)
    return inv


def offsets_of(batch, kind: str):
    """The ``{kind}_offsets`` of ``batch`` (vertex, edge or face) as Python ints: those kept
    with a :class:`~torch_edgevf.learning.batching.MeshBatch` (no read from the device), else
    read from the tensor."""
    host = getattr(batch, "host_offsets", None)
    if callable(host):
        return host(kind)
    return [int(o) for o in getattr(batch, f"{kind}_offsets")]


def mesh_slices(offsets) -> list[slice]:
    """The rows of each mesh of a batch, from its ``(B + 1,)`` offsets."""
    o = [int(i) for i in offsets]
    return [slice(a, b) for a, b in zip(o[:-1], o[1:])]


def per_mesh(rows: torch.Tensor, c: torch.Tensor, meshes: list[slice]) -> torch.Tensor:
    """``rows[s_b] @ c[b]`` for each mesh ``b`` of a batch (rows ``s_b``), stacked row-wise."""
    parts = [rows[s].to(c.dtype) @ c[b] for b, s in enumerate(meshes)]
    return parts[0] if len(parts) == 1 else torch.cat(parts, dim=0)


def synthesize(c: torch.Tensor, batch) -> torch.Tensor:
    """Edge fields ``Phi c`` from coefficients ``(B, k, C)`` in each mesh's edge eigenbasis."""
    return per_mesh(batch.edge_evecs, c, mesh_slices(offsets_of(batch, "edge")))


def project(z: torch.Tensor, batch) -> torch.Tensor:
    """Coefficients ``Phi^H M_z z`` ``(B, k, C)`` of edge fields ``z`` in each mesh's eigenbasis."""
    x = z * batch.edge_mass.to(z.real.dtype)[:, None]
    phi = batch.edge_evecs
    return torch.stack([phi[s].to(x.dtype).mH @ x[s] for s in mesh_slices(offsets_of(batch, "edge"))])
