"""Reference networks: an edge-field network and a DiffusionNet-style vertex baseline.

Both take a :class:`~torch_edgevf.data.MeshBatch` (one mesh or several) whose
``features`` are intrinsic vertex scalars (e.g. heat kernel signatures), and return
logits per mesh (``head="global"``), per vertex (``"vertex"``) or per face (``"face"``).

:class:`EdgeFieldNet` (this library's representation)::

    vertex scalars f --gradient_features--> edge fields z = M_z^{-1} G f   (E, C_in) complex
      --ModulusNorm, ComplexLinear--> (E, W)
      --EdgeDiffusionBlock x N-->  (learned L_c heat diffusion, complex mixing gated by
                                    invariants, ModReLU, residual)
      --InvariantReadout, symlog--> |z|, Re(z conj(A z))  (E, 2W) real  [+ edge means of f]
      --MLP, pooling (global / vertex / face, M_z weighted)--> logits

:class:`DiffusionNetBaseline` (Sharp et al. 2022, written here from the paper): vertex
scalars, spectral diffusion with the cotangent Laplacian and lumped mass, tangent-plane
vertex gradients with ``tanh(Re(g conj(A g)))`` features, per-vertex MLPs, residual.

Every layer of :class:`EdgeFieldNet` is gauge equivariant and its operators intrinsic,
so with intrinsic input features its outputs are invariant to rigid motions and to the
numbering of the vertices (per-vertex and per-face outputs follow the renumbering).
"""

from __future__ import annotations

import torch
from torch import nn

from .layers import (
    ComplexLinear,
    InvariantReadout,
    LearnedDiffusion,
    ModReLU,
    ModulusNorm,
    gradient_features,
    invariant_features,
    pool_edges_to_faces,
    pool_edges_to_vertices,
    pool_global,
)

__all__ = ["EdgeDiffusionBlock", "EdgeFieldNet", "DiffusionNetBlock", "DiffusionNetBaseline"]

_HEADS = ("global", "vertex", "face")


def _check_common(in_channels, out_channels, width, num_blocks, head):
    for name, v in (
        ("in_channels", in_channels),
        ("out_channels", out_channels),
        ("width", width),
        ("num_blocks", num_blocks),
    ):
        if not isinstance(v, int) or v < (0 if name == "num_blocks" else 1):
            raise ValueError(f"{name} must be a positive integer, got {v!r}")
    if head not in _HEADS:
        raise ValueError(f"head must be one of {_HEADS}, got {head!r}")


def _mlp(sizes, dropout: float = 0.0) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        if i > 0:
            layers.append(nn.ReLU())
            if dropout > 0:
                layers.append(nn.Dropout(dropout))
        layers.append(nn.Linear(a, b))
    return nn.Sequential(*layers)


def _symlog(x: torch.Tensor) -> torch.Tensor:
    """``sign(x) log(1 + |x|)``: tames the heavy tails of invariant features (slivers)."""
    return torch.sign(x) * torch.log1p(x.abs())


def _check_batch(batch, in_channels: int) -> None:
    f = getattr(batch, "features", None)
    if not isinstance(f, torch.Tensor) or f.dim() != 2 or f.shape[1] != in_channels:
        raise ValueError(
            f"batch.features must be (V, {in_channels}), got "
            f"{tuple(f.shape) if isinstance(f, torch.Tensor) else type(f).__name__}"
        )


# --------------------------------------------------------------------------- edge network


class EdgeDiffusionBlock(nn.Module):
    """One residual block on complex edge features ``(E, W)``.

    ``zd = diffuse(z)`` (learned time per channel, ``L_c``), a bounded invariant gate
    ``g = tanh(MLP(symlog(|z|, |zd|, Re(zd conj(A zd)))))``, then
    ``z + ComplexLinear(ModReLU(ComplexLinear([z, zd]) * g))``.

    The gate is bounded and its inputs log-compressed so that a block is at most linear
    in ``z``: gradient features of real meshes have huge outliers on sliver triangles
    (the normal component of a gradient across a nearly flat face), which a gate growing
    with ``|z|`` amplifies block after block.
    """

    def __init__(self, width: int, diffusion: str = "spectral"):
        super().__init__()
        self.diffusion = LearnedDiffusion(width, method=diffusion)
        self.mix = ComplexLinear(2 * width, width)
        self.readout = InvariantReadout(width)
        self.gate = _mlp([3 * width, width, width])
        self.act = ModReLU(width)
        self.out = ComplexLinear(width, width)

    def forward(self, z, batch):
        if self.diffusion.method == "spectral":
            zd = self.diffusion(
                z, batch.edge_mass, evals=batch.edge_evals, evecs=batch.edge_evecs, offsets=batch.edge_offsets
            )
        else:
            zd = self.diffusion(z, batch.edge_mass, L=batch.connection_laplacian)
        inv = _symlog(torch.cat([self.readout(zd), z.abs()], dim=1))
        h = self.mix(torch.cat([z, zd], dim=1)) * torch.tanh(self.gate(inv)).to(z.real.dtype)
        return z + self.out(self.act(h))


class EdgeFieldNet(nn.Module):
    """Network on edge-based tangent vector fields (see the module docstring).

    Parameters
    ----------
    in_channels : int, vertex feature channels
    out_channels : int, classes (or outputs)
    width : int, complex channels of the edge features
    num_blocks : int
    head : {"global", "vertex", "face"}
    dropout : float, in the output MLP
    diffusion : {"spectral", "implicit"}
    use_scalars : bool
        Also feed the edge means of the input scalars to the readout.

    Forward
    -------
    ``forward(batch) -> (B | V | F, out_channels)`` logits.
    """

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        width: int = 32,
        num_blocks: int = 4,
        head: str = "global",
        dropout: float = 0.0,
        diffusion: str = "spectral",
        use_scalars: bool = True,
    ):
        super().__init__()
        _check_common(in_channels, out_channels, width, num_blocks, head)
        self.in_channels, self.head, self.use_scalars = in_channels, head, use_scalars
        self.norm = ModulusNorm()
        self.lift = ComplexLinear(in_channels, width)
        self.blocks = nn.ModuleList(EdgeDiffusionBlock(width, diffusion) for _ in range(num_blocks))
        self.readout = InvariantReadout(width)
        readout_dim = self.readout.out_channels + (width if use_scalars else 0)
        self.scalars = nn.Linear(in_channels, width) if use_scalars else None
        self.edge_mlp = _mlp([readout_dim, width, width], dropout)
        self.out = _mlp([width, width, out_channels], dropout)

    def edge_features(self, batch) -> torch.Tensor:
        """``(E, W)`` real, invariant per-edge features before pooling."""
        _check_batch(batch, self.in_channels)
        f = batch.features
        z = gradient_features(f, batch.gradient, batch.edge_mass)
        z = self.norm(z, batch.edge_mass, batch.edge_batch, batch.num_meshes)
        z = self.lift(z)
        for block in self.blocks:
            z = block(z, batch)
        s = _symlog(self.readout(z))
        if self.scalars is not None:
            e = batch.edges
            s = torch.cat([s, self.scalars(0.5 * (f[e[:, 0]] + f[e[:, 1]])).to(s.dtype)], dim=1)
        return self.edge_mlp(s)

    def forward(self, batch):
        s = self.edge_features(batch)
        w = batch.edge_mass.to(s.dtype)
        if self.head == "global":
            pooled = pool_global(s, w, batch.edge_batch, batch.num_meshes)
        elif self.head == "vertex":
            pooled = pool_edges_to_vertices(s, batch.edges, batch.num_vertices, w)
        else:
            pooled = pool_edges_to_faces(s, batch.face_edges, w)
        return self.out(torch.relu(pooled))


# --------------------------------------------------------------------------- baseline


class DiffusionNetBlock(nn.Module):
    """DiffusionNet block on vertex scalars ``(V, W)``: diffusion, gradient features, MLP, residual."""

    def __init__(self, width: int, dropout: float = 0.0):
        super().__init__()
        self.diffusion = LearnedDiffusion(width)
        self.grad_weight = nn.Parameter(torch.randn(width, width, 2) / (2 * width) ** 0.5)
        self.mlp = _mlp([3 * width, width, width], dropout)

    def forward(self, x, batch):
        xd = self.diffusion(
            x,
            batch.vertex_mass,
            evals=batch.vertex_evals,
            evecs=batch.vertex_evecs,
            offsets=batch.vertex_offsets,
        )
        cdt = torch.complex64 if x.dtype == torch.float32 else torch.complex128
        g = torch.sparse.mm(batch.vertex_gradient.to(cdt), xd.to(cdt))
        gf = torch.tanh(invariant_features(g, self.grad_weight, modulus=False))
        return x + self.mlp(torch.cat([x, xd, gf.to(x.dtype)], dim=1))


class DiffusionNetBaseline(nn.Module):
    """A DiffusionNet-style network (vertex-based), for comparison with :class:`EdgeFieldNet`.

    Needs ``batch.vertex_gradient`` (``compute_operators(..., vertex_gradient=True)``) and
    the cotangent eigenpairs in ``batch.vertex_evals/vertex_evecs``. Same parameters as
    :class:`EdgeFieldNet` (but for ``diffusion``/``use_scalars``).
    """

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        width: int = 32,
        num_blocks: int = 4,
        head: str = "global",
        dropout: float = 0.0,
    ):
        super().__init__()
        _check_common(in_channels, out_channels, width, num_blocks, head)
        self.in_channels, self.head = in_channels, head
        self.first = nn.Linear(in_channels, width)
        self.blocks = nn.ModuleList(DiffusionNetBlock(width) for _ in range(num_blocks))
        self.out = _mlp([width, width, out_channels], dropout)

    def forward(self, batch):
        _check_batch(batch, self.in_channels)
        if batch.vertex_gradient is None:
            raise ValueError(
                "DiffusionNetBaseline needs batch.vertex_gradient (compute_operators(vertex_gradient=True))"
            )
        x = self.first(batch.features)
        for block in self.blocks:
            x = block(x, batch)
        w = batch.vertex_mass.to(x.dtype)
        if self.head == "global":
            pooled = pool_global(x, w, batch.vertex_batch, batch.num_meshes)
        elif self.head == "vertex":
            pooled = x
        else:
            pooled = x[batch.faces].mean(1)
        return self.out(torch.relu(pooled))
