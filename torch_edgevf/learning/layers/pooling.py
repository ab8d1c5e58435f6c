"""Pooling from the edges to vertices, faces or whole meshes, and scale normalisation."""

from __future__ import annotations

import torch
from torch import nn

from ..._device import check_devices, sparse_kernels
from ..._dtypes import real_dtype
from .sparse import _check_features, _check_vector, _kept, _spmm

# --------------------------------------------------------------------------- pooling


def _check_weight(weight, n: int, like: torch.Tensor) -> torch.Tensor:
    if weight is None:
        return torch.ones(n, dtype=like.dtype, device=like.device)
    return _check_vector(weight, n, "weight").to(like.dtype)


def pool_edges_to_vertices(x, edges, num_vertices: int, weight=None) -> torch.Tensor:
    r"""Weighted mean of edge features over the edges incident to each vertex.

    .. math::  y_v = \frac{\sum_{e \ni v} w_e x_e}{\sum_{e \ni v} w_e}

    With ``w = M_z`` (default in the models) this is area weighted. Use it on invariant
    (real) features: a complex edge feature lives in its edge's frame. With a ``weight``
    tensor that needs no gradient (precomputed masses), the mean is one sparse product
    with the ``(V, E)`` matrix of the ``w_e / sum w``, built once per pair of ``edges``
    and ``weight`` tensors and kept while both exist.

    Parameters
    ----------
    x : (E, C) real tensor
    edges : (E, 2) int tensor
    num_vertices : int
    weight : (E,) nonnegative real tensor, optional (default 1)

    Returns
    -------
    (V, C) tensor; vertices with no incident edge get 0.
    """
    x = _check_features(x, "x")
    if not isinstance(edges, torch.Tensor) or edges.shape != (x.shape[0], 2):
        raise ValueError(f"edges must have shape ({x.shape[0]}, 2)")
    check_devices(x=x, edges=edges, weight=weight)
    w = _check_weight(weight, x.shape[0], x.real if x.is_complex() else x)
    return _pool_edges_to_vertices(x, edges, num_vertices, w, w is weight)


def _pool_edges_to_vertices(x, edges, num_vertices: int, w, constant: bool = True) -> torch.Tensor:
    """:func:`pool_edges_to_vertices` on valid inputs, ``w`` the ``(E,)`` weights in the dtype
    of ``x``; ``constant``: ``w`` is a tensor the caller keeps (its pooling matrix is cached)."""
    if (
        constant
        and not (w.requires_grad or x.is_complex())
        and edges.device == x.device == w.device
        and sparse_kernels(x.device, x.dtype)
    ):
        return _spmm(_pooling_operator(edges, w, num_vertices), x)
    e = edges.to(x.device)
    wx = w[:, None] * x
    num = torch.zeros((num_vertices, x.shape[1]), dtype=x.dtype, device=x.device)
    num = num.index_add(0, e[:, 0], wx).index_add(0, e[:, 1], wx)
    return num / _weight_at_vertices(e, w, num_vertices)[:, None]


def _weight_at_vertices(e: torch.Tensor, w: torch.Tensor, num_vertices: int) -> torch.Tensor:
    """The sum of ``w`` over the edges at each vertex, 1 at a vertex on no edge (a divisor)."""
    den = torch.zeros(num_vertices, dtype=w.dtype, device=e.device)
    den = den.index_add(0, e[:, 0], w).index_add(0, e[:, 1], w)
    return torch.where(den > 0, den, torch.ones_like(den))


#: the pooling matrices of :func:`pool_edges_to_vertices` per (edges, weight, vertex count)
_POOL_CACHE: dict[tuple[int, int, int], torch.Tensor] = {}


def _pooling_operator(edges: torch.Tensor, weight: torch.Tensor, num_vertices: int) -> torch.Tensor:
    """The ``(V, E)`` sparse matrix of the weighted mean over the edges at each vertex.

    Entries ``w_e / sum_{e' ni v} w_e'`` at ``(v, e)`` for both ends of each edge; built
    once per pair of constant tensors and kept while both exist.
    """

    def build():
        e = edges.to(torch.int64)
        if e.numel() and (int(e.min()) < 0 or int(e.max()) >= num_vertices):
            raise ValueError(
                f"edges must hold vertex indices in [0, {num_vertices}), got {e.min()}..{e.max()}"
            )
        den = _weight_at_vertices(e, weight, num_vertices)
        rows = torch.cat([e[:, 0], e[:, 1]])
        cols = torch.arange(e.shape[0], device=e.device).repeat(2)
        vals = torch.cat([weight / den[e[:, 0]], weight / den[e[:, 1]]])
        return torch.sparse_coo_tensor(
            torch.stack([rows, cols]), vals, (num_vertices, e.shape[0]), check_invariants=False
        ).coalesce()

    return _kept(_POOL_CACHE, (id(edges), id(weight), num_vertices), (edges, weight), build)


def pool_edges_to_faces(x, face_edges, weight=None) -> torch.Tensor:
    """Weighted mean of edge features over the three edges of each face.

    Parameters
    ----------
    x : (E, C) real tensor
    face_edges : (F, 3) int tensor (:attr:`Topology.face_edges`)
    weight : (E,) nonnegative real tensor, optional

    Returns
    -------
    (F, C) tensor.
    """
    x = _check_features(x, "x")
    if not isinstance(face_edges, torch.Tensor) or face_edges.dim() != 2 or face_edges.shape[1] != 3:
        raise ValueError("face_edges must have shape (F, 3)")
    check_devices(x=x, face_edges=face_edges, weight=weight)
    w = _check_weight(weight, x.shape[0], x.real if x.is_complex() else x)
    fe = face_edges.to(x.device)
    wf = w[fe]  # (F, 3)
    return (wf[..., None] * x[fe]).sum(1) / wf.sum(1).clamp_min(torch.finfo(w.dtype).tiny)[:, None]


def pool_global(x, weight=None, batch=None, num_meshes: int | None = None) -> torch.Tensor:
    """Weighted mean of features over each mesh of a batch.

    Parameters
    ----------
    x : (N, C) tensor
    weight : (N,) nonnegative real tensor, optional (e.g. ``M_z`` for edges)
    batch : (N,) int tensor, mesh index of each row; default all 0
    num_meshes : int, default ``batch.max() + 1``

    Returns
    -------
    (B, C) tensor.
    """
    x = _check_features(x, "x")
    check_devices(x=x, weight=weight, batch=batch)
    w = _check_weight(weight, x.shape[0], x.real if x.is_complex() else x)
    if batch is None:
        batch = torch.zeros(x.shape[0], dtype=torch.int64, device=x.device)
    if not isinstance(batch, torch.Tensor) or batch.shape != (x.shape[0],):
        raise ValueError(f"batch must be a ({x.shape[0]},) int tensor")
    nb = int(batch.max()) + 1 if num_meshes is None else int(num_meshes)
    return _pool_global(x, w, batch, nb)


def _pool_global(x, w, batch, nb: int) -> torch.Tensor:
    """:func:`pool_global` on valid inputs: ``w`` ``(N,)`` in the dtype of ``x``, ``nb`` meshes."""
    num = torch.zeros((nb, x.shape[1]), dtype=x.dtype, device=x.device).index_add(0, batch, w[:, None] * x)
    den = torch.zeros(nb, dtype=w.dtype, device=x.device).index_add(0, batch, w)
    return num / den.clamp_min(torch.finfo(w.dtype).tiny)[:, None]


class EdgePooling(nn.Module):
    """Module form of the three pooling functions.

    Parameters
    ----------
    to : {"vertex", "face", "global"}

    Forward
    -------
    ``vertex``: ``forward(x, edges=..., num_vertices=..., weight=None)``;
    ``face``: ``forward(x, face_edges=..., weight=None)``;
    ``global``: ``forward(x, weight=None, batch=None, num_meshes=None)``.
    """

    def __init__(self, to: str = "global"):
        super().__init__()
        if to not in ("vertex", "face", "global"):
            raise ValueError(f"to must be 'vertex', 'face' or 'global', got {to!r}")
        self.to_ = to

    def forward(
        self, x, weight=None, edges=None, num_vertices=None, face_edges=None, batch=None, num_meshes=None
    ):
        if self.to_ == "vertex":
            if edges is None or num_vertices is None:
                raise ValueError("vertex pooling needs edges and num_vertices")
            return pool_edges_to_vertices(x, edges, num_vertices, weight)
        if self.to_ == "face":
            if face_edges is None:
                raise ValueError("face pooling needs face_edges")
            return pool_edges_to_faces(x, face_edges, weight)
        return pool_global(x, weight, batch, num_meshes)

    def extra_repr(self) -> str:
        return f"to={self.to_!r}"


def normalize_modulus(
    z, weight=None, batch=None, num_meshes: int | None = None, eps: float = 1e-8
) -> torch.Tensor:
    r"""Divide each channel of each mesh by its weighted root-mean-square modulus.

    .. math::  z_e \leftarrow z_e \Big/
               \sqrt{\textstyle\sum_{e'} w_{e'} |z_{e'}|^2 / \sum_{e'} w_{e'} + \epsilon}

    over the edges of the same mesh; gauge equivariant (the scale is invariant).

    Parameters
    ----------
    z : (N, C) complex or real tensor
    weight : (N,) real tensor, optional (``M_z`` for edges)
    batch : (N,) int tensor, optional (mesh of each row)
    """
    z = _check_features(z)
    power = pool_global(z.real**2 + z.imag**2 if z.is_complex() else z**2, weight, batch, num_meshes)
    scale = torch.rsqrt(power + eps)
    return z * (scale if batch is None else scale[batch]).to(real_dtype(z.dtype))


class ModulusNorm(nn.Module):
    """Module form of :func:`normalize_modulus` (no parameters)."""

    def __init__(self, eps: float = 1e-8):
        super().__init__()
        self.eps = eps

    def forward(self, z, weight=None, batch=None, num_meshes=None):
        return normalize_modulus(z, weight, batch, num_meshes, self.eps)
