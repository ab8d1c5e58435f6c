"""A residual block on edge fields alone (field in, field out), for tasks whose input and
output are tangent fields (see ``examples/learn_field.py``)."""

from __future__ import annotations

import torch
from torch import nn

from ..layers import ComplexLinear, InvariantReadout, LearnedDiffusion, ModReLU
from .common import mini_mlp, offsets_of

__all__ = ["EdgeDiffusionBlock"]


def _symlog(x: torch.Tensor) -> torch.Tensor:
    """``sign(x) log(1 + |x|)``: tames the heavy tails of invariant features (slivers)."""
    return torch.sign(x) * torch.log1p(x.abs())


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
        self.gate = mini_mlp([3 * width, width, width], dropout=0.0)
        self.act = ModReLU(width)
        self.out = ComplexLinear(width, width)

    def forward(self, z, batch):
        if self.diffusion.method == "spectral":
            zd = self.diffusion(
                z,
                batch.edge_mass,
                evals=batch.edge_evals,
                evecs=batch.edge_evecs,
                offsets=offsets_of(batch, "edge"),
            )
        else:
            zd = self.diffusion(z, batch.edge_mass, L=batch.connection_laplacian)
        inv = _symlog(torch.cat([self.readout(zd), z.abs()], dim=1))
        h = self.mix(torch.cat([z, zd], dim=1)) * torch.tanh(self.gate(inv)).to(z.real.dtype)
        return z + self.out(self.act(h))
