"""The edge-field network: a scalar stream on the vertices and a vector stream of edge fields.

The two streams are coupled through the gradient ``G``, as DeltaConv couples gradient and
divergence::

    x (V, C) --linear--> x
    block:  xd = diffuse_L(x)                    learned time per channel, vertex Laplacian
            u  = M_z^-1 G (xd W) [+ u_prev A]    gradients and co-gradients of mixed scalars
            u  = exp(-t L_c) u                   smooth fields: learned L_c heat diffusion
                                                 in a truncated eigenbasis (local: none)
            x  = x + MLP(x, xd, pool_v tanh Re(u conj(u A)))
            u_prev = u_prev + u
    logits: a linear layer per vertex, then the mass-weighted mean over each mesh
            (head="global"), or per vertex / per face

Smooth fields (``fields="smooth"``, the default for one output per mesh) are outputs of
the ``L_c`` diffusion in a truncated eigenbasis ``Phi``, so they lie in its span: the
network carries their coefficients ``c`` (``u = Phi c``), and ``Phi^H G`` is
``(G^H Phi)^H``, computed once per mesh
(:func:`~torch_edgevf.learning.layers.adjoint_on_basis`). Local fields (``fields="local"``,
the default per vertex and per face) are the gradients on every edge, not diffused: the
boundaries of a segmentation are local, and the lowest modes of ``L_c`` cannot hold them.
The invariant products ``Re(u conj(u A))`` read the fields in a frame-free way; every
layer is gauge equivariant and its operators intrinsic, so with intrinsic input features
the outputs are invariant to rigid motions and to the numbering of the vertices.

These are the networks recommended by the repository's studies: PSB classification
(``experiments/psb_classification``, one output per mesh) and RNA segmentation
(``experiments/rna_segmentation``, per vertex); their input there is the logarithm of the
heat kernel signature (``heat_kernel_signature(..., log=True)``).
"""

from __future__ import annotations

import torch
from torch import nn

from ..layers import ComplexLinear, LearnedDiffusion, adjoint_on_basis
from ..layers.gradient import _gradient_features
from ..layers.pointwise import _complex_linear
from .common import (
    as_mesh_batch,
    check_batch,
    check_options,
    check_vector_options,
    diffuse_vertices,
    mesh_slices,
    mini_mlp,
    offsets_of,
    project,
    readout,
    synthesize,
    vertex_invariants,
)

__all__ = ["EdgeFieldBlock", "EdgeFieldNet"]


class EdgeFieldBlock(nn.Module):
    """One block of :class:`EdgeFieldNet`: scalars ``(V, C)`` and edge fields ``(E, C_v)``.

    Parameters
    ----------
    width : int, scalar channels ``C``
    vector_width : int, complex channels ``C_v`` of the vector stream
    mlp : sequence of int, hidden sizes of the per-vertex MLP
    dropout : float, in the MLP
    vector : {"edge", "vertex", "none"}
        ``"edge"``: the edge-based gradient ``G`` and the ``L_c`` diffusion (this
        library's operators); ``"vertex"``: DiffusionNet's least-squares vertex gradient
        in per-vertex tangent frames instead (no field diffusion); ``"none"``: scalars only.
    carry : bool
        Mix the fields of the previous blocks into this block's fields (``c_prev A``); off
        for the first block, which has none.
    fields : {"smooth", "local"}
        With ``vector="edge"``: the block's fields diffused by ``L_c`` in its truncated
        eigenbasis (``"smooth"``), or the gradients ``M_z^{-1} G (xd W)`` (plus the carried
        fields) on every edge as they are (``"local"``: no eigenpair of ``L_c`` needed).

    Forward
    -------
    ``forward(x, z, batch) -> (x, z)``: the scalars and the sum of the blocks' fields so
    far, on the edges (``vector="edge"``) or the vertices; :meth:`forward_spectral` the
    same with the fields as eigenbasis coefficients (what :class:`EdgeFieldNet` runs).
    """

    def __init__(
        self,
        width: int,
        vector_width: int,
        mlp=(64, 64),
        dropout: float = 0.5,
        vector: str = "edge",
        carry: bool = True,
        fields: str = "smooth",
    ):
        super().__init__()
        check_vector_options(vector, fields)
        self.vector, self.vector_width, self.fields = vector, vector_width, fields
        self.diffusion = LearnedDiffusion(width, positivity="clamp", init_times=0.0)
        extra = 0
        if vector != "none":
            self.lift = nn.Linear(width, 2 * vector_width, bias=False)
            self.mix = ComplexLinear(vector_width, vector_width) if carry else None
            self.products = nn.Parameter(
                torch.randn(vector_width, vector_width, 2) / (2 * vector_width) ** 0.5
            )
            extra = vector_width
        self.field_diffusion: LearnedDiffusion | None = None
        if vector == "edge" and fields == "smooth":
            self.field_diffusion = LearnedDiffusion(vector_width, positivity="clamp", init_times=0.0)
        self.mlp = mini_mlp([2 * width + extra, *mlp, width], dropout)

    def _lifted(self, xd: torch.Tensor) -> torch.Tensor:
        """The complex scalars ``xd W`` whose gradients are the block's new fields."""
        return torch.view_as_complex(self.lift(xd).unflatten(1, (self.vector_width, 2)).contiguous())

    def forward(self, x, z, batch):
        if self.field_diffusion is not None:
            c = None if z is None or self.mix is None else project(z, batch)
            x, _, u = self.forward_spectral(x, c, batch)
            return x, u if z is None else z + u
        xd = diffuse_vertices(self.diffusion, x, batch)
        feats = [x, xd]
        if self.vector != "none":
            if self.vector == "edge":  # local fields: M_z^-1 G a on every edge
                u = _gradient_features(self._lifted(xd), batch.gradient, batch.edge_mass)
            else:
                u = _gradient_features(self._lifted(xd), batch.vertex_gradient)
            if z is not None and self.mix is not None:
                u = u + _complex_linear(z, self.mix.weight)
            feats.append(vertex_invariants(u, self.products, batch, self.vector))
            z = u if z is None else z + u
        return x + self.mlp(torch.cat(feats, dim=1)), z

    def forward_spectral(self, x, c, batch):
        """The block on the coefficients of the fields in the edge eigenbasis (``vector="edge"``).

        The block's fields lie in the span of the ``M_z``-orthonormal eigenbasis ``Phi`` of
        each mesh: ``u = Phi c`` with ``c = diag(e^{-lambda t}) (Phi^H G a + c_prev A)``,
        the gradient part through ``Phi^H M_z M_z^{-1} G = (G^H Phi)^H``. These are the
        numbers of the formula on the edges up to rounding, without its sparse products.

        Parameters
        ----------
        x : (V, C) scalars
        c : (B, k, C_v) complex tensor or None, the coefficients of the fields of the
            previous blocks (their sum)
        batch : :class:`~torch_edgevf.learning.batching.MeshBatch`

        Returns
        -------
        ``(x, c_new, u)``: the new scalars, the coefficients ``(B, k, C_v)`` of this
        block's fields and the fields ``Phi c_new`` ``(E, C_v)``.
        """
        if self.field_diffusion is None:
            raise ValueError(
                f"forward_spectral needs vector='edge' and fields='smooth', got "
                f"vector={self.vector!r}, fields={self.fields!r}"
            )
        xd = diffuse_vertices(self.diffusion, x, batch)
        a = self._lifted(xd)
        basis = adjoint_on_basis(batch.gradient, batch.edge_evecs).to(a.dtype)  # (V, k): G^H Phi
        new = torch.stack([basis[s].mH @ a[s] for s in mesh_slices(offsets_of(batch, "vertex"))])
        if c is not None and self.mix is not None:
            new = new + _complex_linear(c.flatten(0, 1), self.mix.weight).unflatten(0, c.shape[:2])
        t = self.field_diffusion.times.to(new.real.dtype)
        new = new * torch.exp(-batch.edge_evals.to(t.dtype)[:, :, None] * t)
        u = synthesize(new, batch)
        feats = [x, xd, vertex_invariants(u, self.products, batch, "edge")]
        return x + self.mlp(torch.cat(feats, dim=1)), new, u


class EdgeFieldNet(nn.Module):
    """The edge-field network (see the module docstring): the recommended network.

    Needs in the batch the eigenpairs of a vertex Laplacian and, with ``vector="edge"``,
    the gradient ``G`` and (with ``fields="smooth"``) the eigenpairs of ``L_c``
    (:func:`compute_operators`; with ``fields="local"`` ``k_edge=0`` spares them; with
    ``vector="vertex"`` the vertex gradient, ``vertex_gradient=True``). Positive features
    whose scales span orders of magnitude, such as heat kernel signatures, are best given
    as their logarithm (``heat_kernel_signature(..., log=True)``).

    Parameters
    ----------
    in_channels : int, vertex feature channels
    out_channels : int, classes (or outputs)
    width : int, scalar channels
    vector_width : int, complex channels of the vector stream
    num_blocks : int
    mlp : sequence of int, hidden sizes of each block's per-vertex MLP
    dropout : float, in the MLPs
    head : {"global", "vertex", "face"}
        One output per mesh (the mass-weighted mean of per-vertex logits), per vertex, or
        per face (the mean over its corners).
    vector : {"edge", "vertex", "none"}
        The vector stream: edge fields with ``G`` and ``L_c`` (default); DiffusionNet's
        vertex gradients in their place; none (scalars only). The last two are the
        ablations a study of the edge fields needs.
    fields : {"smooth", "local"} or None
        With ``vector="edge"``: each block's fields diffused by ``L_c`` in its truncated
        eigenbasis, a learned time per channel (``"smooth"``), or the gradients
        ``M_z^{-1} G`` of the block's mixed scalars on every edge as they are
        (``"local"``): every feature of the vector stream then depends on a neighbourhood
        of the edge, where the eigenbasis keeps only the lowest modes of ``L_c``. The
        default (None) is the recommended one for the head: ``"smooth"`` for one output per
        mesh (``head="global"``, shape classification), ``"local"`` per vertex or face
        (segmentation); with ``vector`` other than ``"edge"``, ``"smooth"`` (unused).

    Forward
    -------
    ``forward(batch) -> (B | V | F, out_channels)`` logits; ``batch`` a
    :class:`~torch_edgevf.learning.batching.MeshBatch` or a PyG batch of
    ``torch_edgevf.pyg.OperatorData``.
    """

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        width: int = 64,
        vector_width: int = 16,
        num_blocks: int = 3,
        mlp=(64, 64),
        dropout: float = 0.5,
        head: str = "global",
        vector: str = "edge",
        fields: str | None = None,
    ):
        super().__init__()
        check_options(in_channels, out_channels, width, num_blocks, head, dropout)
        if fields is None:
            fields = "local" if vector == "edge" and head != "global" else "smooth"
        check_vector_options(vector, fields)
        if not isinstance(vector_width, int) or isinstance(vector_width, bool) or vector_width < 1:
            raise ValueError(f"vector_width must be a positive integer, got {vector_width!r}")
        self.in_channels, self.head, self.vector, self.fields = in_channels, head, vector, fields
        self.first = nn.Linear(in_channels, width)
        self.blocks = nn.ModuleList(
            EdgeFieldBlock(width, vector_width, mlp, dropout, vector, carry=i > 0, fields=fields)
            for i in range(num_blocks)
        )
        self.last = nn.Linear(width, out_channels)
        self._needs = {
            "edge": ("gradient", "edge_mass") + (("edge_evecs", "edge_evals") if fields == "smooth" else ()),
            "vertex": ("vertex_gradient",),
            "none": (),
        }[vector]

    def forward(self, batch):
        batch = as_mesh_batch(batch)
        check_batch(self, batch, self.in_channels, ("vertex_evecs", "vertex_evals", *self._needs))
        smooth = self.vector == "edge" and self.fields == "smooth"  # fields in the L_c eigenbasis
        if smooth and batch.edge_evecs.shape[-1] == 0:
            raise ValueError(
                "fields='smooth' needs the eigenpairs of L_c, and the batch holds none "
                "(compute_operators(k_edge=0)): compute them (k_edge >= 1) or use fields='local'"
            )
        x = self.first(batch.features)
        if smooth:
            c = None  # the fields as coefficients in the edge eigenbasis
            for block in self.blocks:
                x, new, _ = block.forward_spectral(x, c, batch)
                c = new if c is None else c + new
        else:
            z = None
            for block in self.blocks:
                x, z = block(x, z, batch)
        return readout(x, self.last, batch, self.head)
