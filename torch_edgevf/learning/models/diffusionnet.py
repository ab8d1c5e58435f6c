"""DiffusionNet (Sharp et al. 2022), the vertex-based reference.

Written from "DiffusionNet: Discretization Agnostic Learning on Surfaces" and the facts of
its public code: a linear layer, blocks of learned spectral diffusion (time per channel,
clamped at ``1e-8``, initial 0), spatial gradient features ``tanh(Re(g conj(A g)))`` from a
least-squares tangent-plane vertex gradient, a per-vertex MLP with dropout and a residual,
then a linear layer per vertex and, for one output per mesh, the mass-weighted mean over
the vertices.
"""

from __future__ import annotations

import torch
from torch import nn

from ..layers import LearnedDiffusion
from ..layers.gradient import _gradient_features
from ..layers.pointwise import _invariant_products
from .common import as_mesh_batch, check_batch, check_options, diffuse_vertices, mini_mlp, readout

__all__ = ["DiffusionNetBlock", "DiffusionNet"]


class DiffusionNetBlock(nn.Module):
    """A DiffusionNet block on vertex scalars ``(V, C)``: diffusion, gradient features, MLP, residual."""

    def __init__(self, width: int, mlp=(64, 64), dropout: float = 0.5):
        super().__init__()
        self.diffusion = LearnedDiffusion(width, positivity="clamp", init_times=0.0)
        self.rotation = nn.Parameter(torch.randn(width, width, 2) / (2 * width) ** 0.5)
        self.mlp = mini_mlp([3 * width, *mlp, width], dropout)

    def forward(self, x, batch):
        xd = diffuse_vertices(self.diffusion, x, batch)
        g = _gradient_features(xd, batch.vertex_gradient)
        gf = torch.tanh(_invariant_products(g, self.rotation))
        return x + self.mlp(torch.cat([x, xd, gf], dim=1))


class DiffusionNet(nn.Module):
    """DiffusionNet (Sharp et al. 2022), the vertex-based reference (see the module docstring).

    Needs ``batch.vertex_gradient`` (``compute_operators(..., vertex_gradient=True)``) and
    the eigenpairs of the cotangent Laplacian. Defaults are those of the public code's
    network for classification: width 64, 4 blocks, MLP (64, 64), the mean readout, and
    dropout 0.5 in the MLPs, its class's default; its classification script turns the
    dropout off (``dropout=0.0``), and takes the heat kernel signatures as they are.

    Parameters
    ----------
    in_channels, out_channels, width, num_blocks, mlp, dropout, head
        As in :class:`~torch_edgevf.learning.models.EdgeFieldNet`.

    Forward
    -------
    ``forward(batch) -> (B | V | F, out_channels)`` logits; ``batch`` as in
    :class:`~torch_edgevf.learning.models.EdgeFieldNet`.
    """

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        width: int = 64,
        num_blocks: int = 4,
        mlp=(64, 64),
        dropout: float = 0.5,
        head: str = "global",
    ):
        super().__init__()
        check_options(in_channels, out_channels, width, num_blocks, head, dropout)
        self.in_channels, self.head = in_channels, head
        self.first = nn.Linear(in_channels, width)
        self.blocks = nn.ModuleList(DiffusionNetBlock(width, mlp, dropout) for _ in range(num_blocks))
        self.last = nn.Linear(width, out_channels)

    def forward(self, batch):
        batch = as_mesh_batch(batch)
        check_batch(self, batch, self.in_channels, ("vertex_gradient", "vertex_evecs", "vertex_evals"))
        x = self.first(batch.features)
        for block in self.blocks:
            x = block(x, batch)
        return readout(x, self.last, batch, self.head)
