"""The networks of the PSB study, with every switch the study tried (the code of its saved runs).

The library's :class:`~torch_edgevf.learning.models.EdgeFieldNet` is the network the study
recommends, ``StudyEdgeFieldNet(log_features=True, divergence=False, pool="mean")`` here
(a test checks that the two are the same function with the same weights for a seed), and
:class:`~torch_edgevf.learning.models.DiffusionNet` the faithful reference. What lost in the
study lives here only, so that every row of the saved tables can be run again:

* :class:`StudyEdgeFieldNet` (and :class:`StudyEdgeFieldBlock`): ``pool="mean_std"`` (the
  mass-weighted mean and deviation of the last scalars), ``divergence`` (the divergence
  and curl of the fields in the MLPs), ``high_pass``, ``field_diffusion=False``,
  ``learn_times=False``, ``vector_dropout``, ``head_dropout``, ``stream_dropout``,
  ``readout_fields``, ``spectrum`` / ``spectrum_of``, and ``log_features`` (the logarithm
  of the inputs taken inside the network);
* :class:`StudyDiffusionNet`: DiffusionNet with ``pool``, ``log_features``,
  ``head_dropout`` and ``spectrum``;
* :func:`spectrum_features`: the scale-invariant eigenvalues of ``spectrum``;
* :class:`LogInputs`: a network that takes the logarithm of (the first channels of) its
  inputs, as ``log_features`` did, around the library's networks;
* :data:`MODELS`: the study's models by name.

The layout of the edge-field network (see the library's module for the recommended one)::

    x (V, C) --linear--> x
    block:  xd = diffuse_L(x)                        learned time per channel, vertex Laplacian
            u  = M_z^{-1} G (xd W)  [+ z A_mix]       gradients and co-gradients of mixed scalars (E, C_v)
            ud = diffuse_Lc(u)                        learned L_c heat diffusion of the fields
            u  = ud  [+ (u - ud) A_hp]                with high_pass: what the diffusion drops, mixed
            x  = x + MLP(x, xd, pool_v tanh Re(u conj(u A)), tanh div u, tanh curl u)
            z  = z + u
    logits: the mass-weighted mean and standard deviation of x, then linear (global);
            linear per vertex or per face
"""

from __future__ import annotations

import copy

import torch
from torch import nn
from variants_common import (
    _VECTOR,
    _check_common,
    _check_dropout,
    _check_edge_options,
    _check_spectrum,
    _diffuse_vertices,
    _inputs,
    _last_layer,
    _readout,
    _spectrum_layer,
    _with_spectrum,
)

from torch_edgevf.learning.layers import (
    ComplexLinear,
    Dropout,
    LearnedDiffusion,
    adjoint_on_basis,
    complex_linear,
    divergence_features,
    gradient_features,
)
from torch_edgevf.learning.models import DiffusionNet, EdgeFieldNet
from torch_edgevf.learning.models.common import check_batch, mini_mlp
from torch_edgevf.learning.models.common import mesh_slices as _mesh_slices
from torch_edgevf.learning.models.common import per_mesh as _per_mesh
from torch_edgevf.learning.models.common import project as _project
from torch_edgevf.learning.models.common import synthesize as _synthesize
from torch_edgevf.learning.models.common import vertex_invariants as _vertex_invariants
from torch_edgevf.learning.models.diffusionnet import DiffusionNetBlock

# --------------------------------------------------------------------------- edge-field network


class StudyEdgeFieldBlock(nn.Module):
    """One block of :class:`StudyEdgeFieldNet`: scalars ``(V, C)`` and edge fields ``(E, C_v)``.

    Parameters
    ----------
    width : int, scalar channels ``C``
    vector_width : int, complex channels ``C_v`` of the vector stream
    mlp : sequence of int, hidden sizes of the per-vertex MLP
    dropout : float
    vector : {"edge", "vertex", "none"}
        ``"edge"``: the edge-based gradient ``G``, ``L_c`` diffusion, divergence and curl
        (this library's operators); ``"vertex"``: the least-squares vertex gradient in
        per-vertex tangent frames instead (no field diffusion, no divergence), for
        comparison; ``"none"``: scalars only.
    learn_times : bool
        Learn the diffusion times (else ``t = 0``: projection on the eigenbasis).
    carry : bool
        Mix the fields of the previous blocks into this block's fields (``z A_mix``); off
        for the first block, which has none.
    high_pass : bool
        With ``vector="edge"``: add back what the ``L_c`` diffusion removes from the
        fields, mixed by a learned complex weight initialised at zero
        (``u = ud + (u - ud) A_hp``, ``ud`` the diffused fields). The diffusion works in
        a truncated eigenbasis, so ``u - ud`` holds the high frequencies it drops; the
        block starts as without it and learns how much of them to keep.
    vector_dropout : float
        Dropout on the vector stream's features where they enter the per-vertex MLP
        (pooled invariants, divergence and curl); ``0`` (default) draws no random numbers.
    divergence : bool
        With ``vector="edge"``: give the MLP the divergence and curl of the fields
        (``-M_v^{-1} G^* u``, default) beside their pooled invariants; ``False`` leaves them
        out (an ablation of the adjoint's way back to the scalars).
    field_diffusion : bool
        With ``vector="edge"``: diffuse the fields with ``L_c`` in its truncated eigenbasis
        (default). ``False``: the block's fields are the gradients ``M_z^{-1} G a`` (plus
        the carried fields) on the edges as they are, not diffused: every feature of the
        vector stream is then local (the divergence and curl of ``G a`` are Laplacians of
        ``a``), where the eigenbasis holds only the lowest modes of ``L_c``, whose shape
        depends on the surface's topology. No eigenpair of ``L_c`` is needed.

    Forward
    -------
    ``forward(x, z, batch, keep=None) -> (x, z)``: ``keep``, a ``(B,)`` bool tensor or
    None (all), says which meshes of the batch use the vector stream: the fields of the
    others are zero, so their scalars pass through the block as in ``vector="none"``
    (see ``stream_dropout`` of :class:`StudyEdgeFieldNet`).
    """

    def __init__(
        self,
        width: int,
        vector_width: int,
        mlp=(64, 64),
        dropout: float = 0.5,
        vector: str = "edge",
        learn_times: bool = True,
        carry: bool = True,
        high_pass: bool = False,
        vector_dropout: float = 0.0,
        divergence: bool = True,
        field_diffusion: bool = True,
    ):
        super().__init__()
        if vector not in _VECTOR:
            raise ValueError(f"vector must be one of {_VECTOR}, got {vector!r}")
        _check_edge_options(vector, divergence=divergence, field_diffusion=field_diffusion)
        if high_pass and not field_diffusion:
            raise ValueError(
                "high_pass=True needs field_diffusion=True: without the diffusion nothing is dropped"
            )
        self.vector, self.vector_width, self.divergence = vector, vector_width, divergence
        self.diffusion = LearnedDiffusion(width, positivity="clamp", init_times=0.0)
        self.diffusion.raw_times.requires_grad_(learn_times)
        extra = 0
        if vector != "none":
            self.lift = nn.Linear(width, 2 * vector_width, bias=False)
            self.mix = ComplexLinear(vector_width, vector_width) if carry else None
            self.products = nn.Parameter(
                torch.randn(vector_width, vector_width, 2) / (2 * vector_width) ** 0.5
            )
            extra = vector_width
        self.field_diffusion: LearnedDiffusion | None = None
        if vector == "edge" and field_diffusion:
            self.field_diffusion = LearnedDiffusion(vector_width, positivity="clamp", init_times=0.0)
            self.field_diffusion.raw_times.requires_grad_(learn_times)
        if vector == "edge":
            extra += 2 * vector_width if divergence else 0
        self.vector_features = extra  # channels the vector stream gives the MLP
        self.mlp = mini_mlp([2 * width + extra, *mlp, width], dropout)
        # zeros: no random numbers drawn, so a seed initialises the rest as without it
        self.high_pass = (
            nn.Parameter(torch.zeros(vector_width, vector_width, 2))
            if high_pass and vector == "edge"
            else None
        )
        # created only when used, so that a seed draws the same numbers as without it
        self.vector_dropout = Dropout(vector_dropout) if vector_dropout > 0 and vector != "none" else None

    @property
    def spectral(self) -> bool:
        """Whether the block works on the coefficients of its fields (see :meth:`forward_spectral`)."""
        return self.vector == "edge" and self.high_pass is None and self.field_diffusion is not None

    def forward(self, x, z, batch, keep=None):
        if self.spectral:
            c = None if z is None or self.mix is None else _project(z, batch)
            x, _, u = self.forward_spectral(x, c, batch, keep)
            return x, z if u is None else (u if z is None else z + u)
        xd = _diffuse_vertices(self.diffusion, x, batch)
        feats = [x, xd]
        if self.vector != "none" and keep is not None and not bool(keep.any()):
            # no mesh uses the fields: they are zero, and so are their features
            feats.append(x.new_zeros(x.shape[0], self.vector_features))
        elif self.vector != "none":
            a = torch.view_as_complex(self.lift(xd).unflatten(1, (self.vector_width, 2)).contiguous())
            if self.vector == "edge":
                u = gradient_features(a, batch.gradient, batch.edge_mass)
            else:
                u = gradient_features(a, batch.vertex_gradient)
            if z is not None and self.mix is not None:
                u = u + self.mix(z)
            if keep is not None and not bool(keep.all()):
                index = batch.edge_batch if self.vector == "edge" else batch.vertex_batch
                u = u * keep[index].to(u.real.dtype).unsqueeze(1)
            if self.field_diffusion is not None:
                ud = self.field_diffusion(
                    u,
                    batch.edge_mass,
                    evals=batch.edge_evals,
                    evecs=batch.edge_evecs,
                    offsets=batch.edge_offsets,
                )
                if self.high_pass is not None:
                    ud = ud + complex_linear(u - ud, self.high_pass)
                u = ud
            vec = [_vertex_invariants(u, self.products, batch, self.vector)]
            if self.vector == "edge" and self.divergence:
                dc = divergence_features(u, batch.gradient, batch.vertex_mass)
                vec += [torch.tanh(dc.real), torch.tanh(dc.imag)]
            feats += self._dropped(vec)
            z = u if z is None else z + u
        return x + self.mlp(torch.cat(feats, dim=1)), z

    def forward_spectral(self, x, c, batch, keep=None):
        """The block on the coefficients of the fields in the edge eigenbasis (``vector="edge"``).

        Without ``high_pass``, the block's fields are those of the ``L_c`` diffusion, so
        they lie in the span of the ``M_z``-orthonormal eigenbasis ``Phi`` of each mesh:
        ``u = Phi c`` with ``c = diag(e^{-lambda t}) (Phi^H G a + c_prev A_mix)``, the
        gradient part through ``Phi^H M_z M_z^{-1} G = (G^H Phi)^H``
        (:func:`~torch_edgevf.learning.layers.adjoint_on_basis`), and the divergence and
        curl are ``-M_v^{-1} (G^H Phi) c``. These are the numbers of :meth:`forward` up to
        rounding, without its sparse products and projections on the edges.

        Parameters
        ----------
        x : (V, C) scalars
        c : (B, k, C_v) complex tensor or None, the coefficients of the fields of the
            previous blocks (their sum)
        batch, keep : as in :meth:`forward`

        Returns
        -------
        ``(x, c_new, u)``: the new scalars, the coefficients ``(B, k, C_v)`` of this
        block's fields and the fields ``Phi c_new`` ``(E, C_v)`` (both None when no mesh
        uses the vector stream).
        """
        if not self.spectral:
            raise ValueError("forward_spectral needs vector='edge', field_diffusion=True and high_pass=False")
        xd = _diffuse_vertices(self.diffusion, x, batch)
        feats = [x, xd]
        if keep is not None and not bool(keep.any()):
            feats.append(x.new_zeros(x.shape[0], self.vector_features))
            return x + self.mlp(torch.cat(feats, dim=1)), None, None
        a = torch.view_as_complex(self.lift(xd).unflatten(1, (self.vector_width, 2)).contiguous())
        basis = adjoint_on_basis(batch.gradient, batch.edge_evecs).to(a.dtype)  # (V, k): G^H Phi
        meshes = _mesh_slices(batch.vertex_offsets)
        new = torch.stack([basis[s].mH @ a[s] for s in meshes])
        if c is not None and self.mix is not None:
            new = new + self.mix(c.flatten(0, 1)).unflatten(0, c.shape[:2])
        if keep is not None and not bool(keep.all()):
            new = new * keep.to(new.real.dtype)[:, None, None]
        assert self.field_diffusion is not None  # self.spectral
        t = self.field_diffusion.times.to(new.real.dtype)
        new = new * torch.exp(-batch.edge_evals.to(t.dtype)[:, :, None] * t)
        u = _synthesize(new, batch)
        vec = [_vertex_invariants(u, self.products, batch, "edge")]
        if self.divergence:
            dc = -_per_mesh(basis, new, meshes)
            dc = dc * batch.vertex_mass.to(dc.real.dtype).reciprocal()[:, None]
            vec += [torch.tanh(dc.real), torch.tanh(dc.imag)]
        feats += self._dropped(vec)
        return x + self.mlp(torch.cat(feats, dim=1)), new, u

    def _dropped(self, vec: list[torch.Tensor]) -> list[torch.Tensor]:
        return vec if self.vector_dropout is None else [self.vector_dropout(t) for t in vec]


class StudyEdgeFieldNet(nn.Module):
    """The edge-field network: a scalar and a vector stream coupled through ``G`` and ``G^*``.

    See the module docstring for the layout. Needs the eigenpairs of a vertex Laplacian
    and of ``L_c`` and the gradient ``G`` in the batch (:func:`compute_operators`; with
    ``vector="vertex"`` also ``vertex_gradient=True``).

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
    vector : {"edge", "vertex", "none"}, see :class:`StudyEdgeFieldBlock`
    learn_times : bool
    high_pass : bool, see :class:`StudyEdgeFieldBlock`
    divergence : bool, see :class:`StudyEdgeFieldBlock`
    field_diffusion : bool, see :class:`StudyEdgeFieldBlock` (``False``: no eigenpair of
        ``L_c`` needed in the batch)
    vector_dropout : float, see :class:`StudyEdgeFieldBlock`
    head_dropout : float
        Dropout on what the output layer takes (the pooled mean and deviation with
        ``pool="mean_std"``, else the last scalars per vertex).
    stream_dropout : float
        In training, the probability that a mesh goes through the network without its
        vector stream (its fields zero in every block, the vector stream's features
        entering the MLPs zero; not rescaled), drawn per mesh and step, as modality
        dropout drops one input stream of a multi-stream network: the scalar stream
        learns to classify on its own and the vector stream to add to it. In
        evaluation every mesh uses both streams. A batch in which every mesh drew the
        scalar stream alone skips the vector stream's computation. ``0`` (default) draws
        no random numbers.
    pool : {"mean_std", "mean"}
        Readout of ``head="global"``: the mass-weighted mean and standard deviation of
        the last block's scalars, then a linear layer (default); or a linear layer per
        vertex, then the mass-weighted mean (DiffusionNet's readout).
    log_features : bool or int
        Take the logarithm of the input features first (for positive features whose
        scales span orders of magnitude, such as heat kernel signatures; others raise
        ``ValueError``); an integer ``k``: of the first ``k`` channels only (heat kernel
        signatures first, signed features such as ``precompute.mean_curvature_signature``
        after them).
    readout_fields : bool
        The readout also takes the fields of the vector stream (the sum of every block's
        fields): their invariant products ``tanh Re(z conj(z A))`` with a learned complex
        ``A`` (``C_v`` channels), pooled from the edges to the vertices, beside the last
        scalars. The output layer then takes ``C + C_v`` channels per vertex (twice that
        with ``pool="mean_std"``).
    spectrum : int
        With ``head="global"``: the logits also take the first ``spectrum`` eigenvalues
        of each mesh's ``L_c``, or of the operator ``spectrum_of`` names
        (:func:`spectrum_features`), through a linear layer without bias. ``0``
        (default): none.
    spectrum_of : {"connection", "laplacian"}
        Whose eigenvalues ``spectrum`` takes: ``L_c``'s (default) or the vertex
        Laplacian's.

    Forward
    -------
    ``forward(batch) -> (B | V | F, out_channels)`` logits.
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
        learn_times: bool = True,
        pool: str = "mean_std",
        log_features: bool | int = False,
        high_pass: bool = False,
        vector_dropout: float = 0.0,
        head_dropout: float = 0.0,
        stream_dropout: float = 0.0,
        readout_fields: bool = False,
        spectrum: int = 0,
        spectrum_of: str = "connection",
        divergence: bool = True,
        field_diffusion: bool = True,
    ):
        super().__init__()
        _check_common(in_channels, out_channels, width, num_blocks, head, dropout, pool, log_features)
        _check_spectrum(spectrum, head, spectrum_of)
        _check_dropout(
            vector_dropout=vector_dropout,
            head_dropout=head_dropout,
            stream_dropout=stream_dropout,
        )
        if stream_dropout > 0 and vector == "none":
            raise ValueError("stream_dropout needs a vector stream; vector='none' has none")
        if not isinstance(readout_fields, bool):
            raise ValueError(f"readout_fields must be True or False, got {readout_fields!r}")
        if readout_fields and vector == "none":
            raise ValueError("readout_fields needs a vector stream; vector='none' has none")
        self.stream_dropout = stream_dropout
        self.in_channels, self.head, self.vector = in_channels, head, vector
        self.pool, self.log_features = pool, log_features
        self.first = nn.Linear(in_channels, width)
        self.blocks = nn.ModuleList(
            StudyEdgeFieldBlock(
                width,
                vector_width,
                mlp,
                dropout,
                vector,
                learn_times,
                carry=i > 0,
                high_pass=high_pass,
                vector_dropout=vector_dropout,
                divergence=divergence,
                field_diffusion=field_diffusion,
            )
            for i in range(num_blocks)
        )
        self.last = _last_layer(width + (vector_width if readout_fields else 0), out_channels, head, pool)
        self.head_dropout = Dropout(head_dropout) if head_dropout > 0 else None
        # created last, so that a seed initialises the rest as without it
        self.field_products = (
            nn.Parameter(torch.randn(vector_width, vector_width, 2) / (2 * vector_width) ** 0.5)
            if readout_fields
            else None
        )
        self.spectrum, self.spectrum_of = _spectrum_layer(spectrum, out_channels), spectrum_of

    def _field_readout(self, z, batch, products: torch.Tensor) -> torch.Tensor:
        """The invariant products of the fields ``z`` at the vertices (zero where there are none)."""
        if z is None:  # every mesh went without its vector stream (stream_dropout)
            return batch.features.new_zeros(batch.features.shape[0], products.shape[0])
        return _vertex_invariants(z, products, batch, self.vector)

    def forward(self, batch):
        needs = {"edge": ("gradient", "edge_evecs"), "vertex": ("vertex_gradient",), "none": ()}[self.vector]
        if self.vector == "edge" and not any(block.field_diffusion is not None for block in self.blocks):
            needs = ("gradient",)
        check_batch(self, batch, self.in_channels, needs)
        x, z = self.first(_inputs(self.log_features, batch)), None
        keep = None
        if self.training and self.stream_dropout > 0:
            keep = torch.rand(batch.num_meshes, device=x.device) >= self.stream_dropout
        if all(block.spectral for block in self.blocks):
            # the fields as coefficients in the edge eigenbasis (EdgeFieldBlock.forward_spectral)
            c = None
            for block in self.blocks:
                x, new, _ = block.forward_spectral(x, c, batch, keep)
                if new is not None:
                    c = new if c is None else c + new
            z = None if c is None else _synthesize(c, batch)
        else:
            for block in self.blocks:
                x, z = block(x, z, batch, keep)
        if self.field_products is not None:
            x = torch.cat([x, self._field_readout(z, batch, self.field_products)], dim=1)
        logits = _readout(x, self.last, batch, self.head, self.pool, self.head_dropout)
        return _with_spectrum(self.spectrum, self.spectrum_of, logits, batch)


class StudyDiffusionNet(nn.Module):
    """DiffusionNet (Sharp et al. 2022), the vertex-based reference (see the module docstring).

    Needs ``batch.vertex_gradient`` (``compute_operators(..., vertex_gradient=True)``) and
    the eigenpairs of the cotangent Laplacian. Defaults are those of the public code's
    network for classification: width 64, 4 blocks, MLP (64, 64), the mean readout, raw
    features, and dropout 0.5 in the MLPs, its class's default; its classification
    script turns the dropout off (``dropout=0.0``). ``pool``, ``log_features`` and
    ``head_dropout`` are those of :class:`StudyEdgeFieldNet`, for comparisons with the same
    readout and inputs, and so are ``spectrum`` and ``spectrum_of`` (with the default
    ``"connection"``, the eigenvalues of ``L_c`` are then needed in the batch too), to
    give DiffusionNet the same global features.
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
        pool: str = "mean",
        log_features: bool | int = False,
        head_dropout: float = 0.0,
        spectrum: int = 0,
        spectrum_of: str = "connection",
    ):
        super().__init__()
        _check_common(in_channels, out_channels, width, num_blocks, head, dropout, pool, log_features)
        _check_spectrum(spectrum, head, spectrum_of)
        _check_dropout(head_dropout=head_dropout)
        self.in_channels, self.head = in_channels, head
        self.pool, self.log_features = pool, log_features
        self.first = nn.Linear(in_channels, width)
        self.blocks = nn.ModuleList(DiffusionNetBlock(width, mlp, dropout) for _ in range(num_blocks))
        self.last = _last_layer(width, out_channels, head, pool)
        self.head_dropout = Dropout(head_dropout) if head_dropout > 0 else None
        self.spectrum, self.spectrum_of = _spectrum_layer(spectrum, out_channels), spectrum_of

    def forward(self, batch):
        check_batch(self, batch, self.in_channels, ("vertex_gradient",))
        x = self.first(_inputs(self.log_features, batch))
        for block in self.blocks:
            x = block(x, batch)
        logits = _readout(x, self.last, batch, self.head, self.pool, self.head_dropout)
        return _with_spectrum(self.spectrum, self.spectrum_of, logits, batch)


#: the earlier name of :class:`DiffusionNet`


def log_inputs(features: torch.Tensor, channels: bool | int) -> torch.Tensor:
    """The features with the logarithm of every channel (``True``) or of the first
    ``channels``, as ``log_features`` took them inside the network."""
    return _inputs(channels, _Features(features))


class _Features:
    def __init__(self, features):
        self.features = features


class LogInputs(nn.Module):
    """``net`` on the logarithm of (the first ``channels`` of) the batch's features.

    No parameter of its own: a seed initialises ``net`` as without it, and the pair is the
    function of ``net(..., log_features=channels)`` of the study's networks.
    """

    def __init__(self, net: nn.Module, channels: bool | int = True):
        super().__init__()
        self.net, self.channels = net, channels

    def forward(self, batch):
        logged = copy.copy(batch)
        logged.features = log_inputs(batch.features, self.channels)
        return self.net(logged)


#: eigenpairs of ``L_c`` (the edge eigenbasis of the vector stream) unless ``--k-edge``
K_EDGE = 32


def _model(network, logs: bool = False, **options):
    """A factory of ``network`` with ``options``: ``(c_in, c_out, log) -> model``; with
    ``logs`` the network reads logarithms, ``log_features=log``."""
    return lambda c_in, c_out, log: network(c_in, c_out, **({"log_features": log} if logs else {}), **options)


def _library(network, **options):
    """A factory of the library's ``network`` with ``options`` on the logarithm of the inputs."""
    return lambda c_in, c_out, log: LogInputs(network(c_in, c_out, **options), log)


def _library_raw(network, **options):
    """A factory of the library's ``network`` with ``options`` on the inputs as they are."""
    return lambda c_in, c_out, log: network(c_in, c_out, **options)


#: the study's models by name, each built from its input and output channels and, for the networks
#: that read logarithms, ``log``: True (every channel, the HKS) or the number of HKS
#: channels before signed ones (``--input hks+curvature``): the code of the saved runs
STUDY_MODELS = {
    # the previous recommendation: log-HKS in, mean and deviation out
    "edgefieldnet": _model(StudyEdgeFieldNet, logs=True),
    "diffusionnet": _model(StudyDiffusionNet),
    # DiffusionNet without dropout, as its public classification script builds it
    "diffusionnet-nodropout": _model(StudyDiffusionNet, dropout=0.0),
    # DiffusionNet with the edge-field network's input and readout (a fairness check)
    "diffusionnet-logstd": _model(StudyDiffusionNet, logs=True, pool="mean_std"),
    # ablations of the edge-field network
    "edgefieldnet-scalar": _model(StudyEdgeFieldNet, logs=True, vector="none"),
    "edgefieldnet-vertexvec": _model(StudyEdgeFieldNet, logs=True, vector="vertex"),
    "edgefieldnet-fixedtime": _model(StudyEdgeFieldNet, logs=True, learn_times=False),
    # DiffusionNet's readout (a linear layer per vertex, the mean of the logits), and its
    # ablations
    "edgefieldnet-meanpool": _model(StudyEdgeFieldNet, logs=True, pool="mean"),
    "edgefieldnet-meanpool-scalar": _model(StudyEdgeFieldNet, logs=True, pool="mean", vector="none"),
    "edgefieldnet-meanpool-vertexvec": _model(StudyEdgeFieldNet, logs=True, pool="mean", vector="vertex"),
    "edgefieldnet-meanpool-fixedtime": _model(StudyEdgeFieldNet, logs=True, pool="mean", learn_times=False),
    # the fields' high frequencies (what the L_c diffusion removes) added back, learned
    "edgefieldnet-highpass": _model(StudyEdgeFieldNet, logs=True, high_pass=True),
    "edgefieldnet-nodiv": _model(StudyEdgeFieldNet, logs=True, divergence=False),
    # the fields not diffused: the gradients on the edges as they are, every feature local
    "edgefieldnet-local": _model(StudyEdgeFieldNet, logs=True, field_diffusion=False),
    # both: the fields not diffused and DiffusionNet's readout
    "edgefieldnet-local-meanpool": _model(StudyEdgeFieldNet, logs=True, field_diffusion=False, pool="mean"),
    # DiffusionNet's readout without the divergence and curl of the fields
    "edgefieldnet-nodiv-meanpool": _model(StudyEdgeFieldNet, logs=True, divergence=False, pool="mean"),
    "edgefieldnet-nodiv-meanpool-fixedtime": _model(
        StudyEdgeFieldNet, logs=True, divergence=False, pool="mean", learn_times=False
    ),
    # dropout on the pooled readout / on the vector stream's features entering the MLPs
    "edgefieldnet-headdrop": _model(StudyEdgeFieldNet, logs=True, head_dropout=0.5),
    "edgefieldnet-vecdrop": _model(StudyEdgeFieldNet, logs=True, vector_dropout=0.5),
    # the vector stream dropped as a whole for half of the training steps (modality dropout)
    "edgefieldnet-streamdrop": _model(StudyEdgeFieldNet, logs=True, stream_dropout=0.5),
    # 8 complex channels in the vector stream in place of 16
    "edgefieldnet-vec8": _model(StudyEdgeFieldNet, logs=True, vector_width=8),
    # 8 complex channels and 4 blocks: DiffusionNet's depth at the cost of 3 full blocks
    "edgefieldnet-vec8-4blocks": _model(StudyEdgeFieldNet, logs=True, vector_width=8, num_blocks=4),
    # the accumulated fields' invariants pooled beside the last scalars in the readout
    "edgefieldnet-fieldread": _model(StudyEdgeFieldNet, logs=True, readout_fields=True),
    # no dropout in the MLPs (as DiffusionNet's public classification script has it)
    "edgefieldnet-nodropout": _model(StudyEdgeFieldNet, logs=True, dropout=0.0),
    # no dropout and 8 complex channels: the two cheapest changes to the step together
    "edgefieldnet-vec8-nodropout": _model(StudyEdgeFieldNet, logs=True, vector_width=8, dropout=0.0),
    # the logits also take the first 32 eigenvalues of L_c (spectrum_features)
    "edgefieldnet-spectrum": _model(StudyEdgeFieldNet, logs=True, spectrum=K_EDGE),
    # the faithful DiffusionNet given the same eigenvalues (the control of the one above)
    "diffusionnet-nodropout-spectrum": _model(StudyDiffusionNet, dropout=0.0, spectrum=K_EDGE),
    # its control: the first 32 eigenvalues of the vertex Laplacian in place of those of L_c
    "diffusionnet-nodropout-lbspectrum": _model(
        StudyDiffusionNet, dropout=0.0, spectrum=K_EDGE, spectrum_of="laplacian"
    ),
    # raw HKS in, mean of per-vertex logits out (DiffusionNet's input and readout)
    "edgefieldnet-rawmean": _model(StudyEdgeFieldNet, pool="mean"),
}

#: the models that are the library's networks: the recommended network
#: (``edgefieldnet-nodiv-meanpool``), its two ablations of the vector stream and the
#: DiffusionNets, each the same function as the study's network of that name, with the same
#: weights for a seed (tested)
LIBRARY_MODELS = {
    "diffusionnet": _library_raw(DiffusionNet),
    "diffusionnet-nodropout": _library_raw(DiffusionNet, dropout=0.0),
    "edgefieldnet-meanpool-scalar": _library(EdgeFieldNet, vector="none"),
    "edgefieldnet-meanpool-vertexvec": _library(EdgeFieldNet, vector="vertex"),
    "edgefieldnet-nodiv-meanpool": _library(EdgeFieldNet),
}
#: the models the study runs by name: the library's networks where they are the study's
MODELS = {**STUDY_MODELS, **LIBRARY_MODELS}
