"""The parts the PSB study's networks share: their option checks, how they read their
inputs (with the logarithm of ``log_features``), their readouts, and the eigenvalue
features of ``spectrum``."""

from __future__ import annotations

import math

import torch
from torch import nn

from torch_edgevf.learning.layers import (
    LearnedDiffusion,
    pool_global,
)
from torch_edgevf.learning.models.common import check_options

_VECTOR = ("edge", "vertex", "none")
_POOLS = ("mean", "mean_std")
#: added to the variance before its square root in ``pool="mean_std"`` (a finite gradient
#: for constant features)
_STD_EPS = 1e-6


def _check_common(
    in_channels, out_channels, width, num_blocks, head, dropout, pool="mean", log_features=False
) -> None:
    """The library networks' checks, and those of the study's readout options."""
    check_options(in_channels, out_channels, width, num_blocks, head, dropout)
    if pool not in _POOLS:
        raise ValueError(f"pool must be one of {_POOLS}, got {pool!r}")
    if not isinstance(log_features, (bool, int)) or not (
        isinstance(log_features, bool) or 1 <= log_features <= in_channels
    ):
        raise ValueError(
            f"log_features must be True, False or a number of channels in [1, {in_channels}], "
            f"got {log_features!r}"
        )


def _check_edge_options(vector: str, **options: bool) -> None:
    """Each option a bool; ``False`` (a change to the edge fields) only with ``vector="edge"``."""
    for name, value in options.items():
        if not isinstance(value, bool):
            raise ValueError(f"{name} must be True or False, got {value!r}")
        if not value and vector != "edge":
            raise ValueError(
                f"{name}=False needs vector='edge'; vector={vector!r} has no {name.replace('_', ' ')}"
            )


def _check_dropout(**probabilities) -> None:
    for name, p in probabilities.items():
        if isinstance(p, bool) or not isinstance(p, (int, float)) or not 0 <= p < 1:
            raise ValueError(f"{name} must be a probability in [0, 1), got {p!r}")


def _last_layer(width: int, out_channels: int, head: str, pool: str) -> nn.Linear:
    """The output layer: ``2 width`` inputs for the mean-and-deviation readout, else ``width``."""
    return nn.Linear(2 * width if head == "global" and pool == "mean_std" else width, out_channels)


def _inputs(log_features: bool | int, batch) -> torch.Tensor:
    """The features, through ``log`` when the model takes logarithms (positive features
    only): of every channel with ``log_features=True``, of the first ``k`` with ``k``."""
    f = batch.features
    if log_features is False:
        return f
    k = f.shape[1] if log_features is True else int(log_features)
    bad = ~(f[:, :k] > 0)
    if bad.any():
        v, c = (int(i) for i in bad.nonzero()[0])
        raise ValueError(
            f"log_features={log_features!r} needs positive features in the channels it takes "
            f"the logarithm of (such as heat kernel signatures), got {float(f[v, c])} at vertex {v}, "
            f"channel {c}"
        )
    return torch.cat([torch.log(f[:, :k]), f[:, k:]], dim=1) if k < f.shape[1] else torch.log(f)


def _readout(x, last: nn.Linear, batch, head: str, pool: str, drop: nn.Module | None = None) -> torch.Tensor:
    """``last`` applied per vertex, then pooled (``head="global"``), or per vertex / face.

    ``pool="mean_std"``: the mass-weighted mean and standard deviation of ``x`` over each
    mesh, concatenated, then ``last`` (which takes ``2 C`` inputs). ``drop`` (dropout) is
    applied to what ``last`` takes.
    """
    if head == "global" and pool == "mean_std":
        w = batch.vertex_mass.to(x.dtype)
        mean = pool_global(x, w, batch.vertex_batch, batch.num_meshes)
        var = pool_global((x - mean[batch.vertex_batch]) ** 2, w, batch.vertex_batch, batch.num_meshes)
        pooled = torch.cat([mean, (var + _STD_EPS).sqrt()], dim=1)
        return last(pooled if drop is None else drop(pooled))
    x = last(x if drop is None else drop(x))
    if head == "global":
        return pool_global(x, batch.vertex_mass.to(x.dtype), batch.vertex_batch, batch.num_meshes)
    if head == "vertex":
        return x
    return x[batch.faces].mean(1)


#: added to the Weyl-normalised eigenvalues before their logarithm: a zero eigenvalue (a
#: parallel field on a flat patch, a mesh's second component) gives ``log(0.01)``, not ``-inf``
_SPECTRUM_EPS = 1e-2


#: per operator of :func:`spectrum_features`: the batch's eigenvalues, the index of the
#: first one read, Weyl's constant (``lambda_i ~ c i / A``), its name and the option of
#: :func:`compute_operators` that sets how many there are
_SPECTRA = {
    "connection": ("edge_evals", 0, 2 * math.pi, "L_c", "k_edge"),
    "laplacian": ("vertex_evals", 1, 4 * math.pi, "the vertex Laplacian", "k_vertex"),
}
#: the operators whose eigenvalues :func:`spectrum_features` reads
SPECTRUM_OPERATORS = tuple(_SPECTRA)


def _check_spectrum(spectrum, head: str, spectrum_of: str) -> None:
    if isinstance(spectrum, bool) or not isinstance(spectrum, int) or spectrum < 0:
        raise ValueError(f"spectrum must be an int >= 0, got {spectrum!r}")
    if spectrum and head != "global":
        raise ValueError(f"spectrum needs head='global' (one output per mesh), got head={head!r}")
    if spectrum_of not in SPECTRUM_OPERATORS:
        raise ValueError(f"spectrum_of must be one of {SPECTRUM_OPERATORS}, got {spectrum_of!r}")


def spectrum_features(batch, count: int, operator: str = "connection") -> torch.Tensor:
    """The first ``count`` eigenvalues of an operator of each mesh as scale-invariant features.

    ``operator="connection"`` (default): those of ``L_c``,
    ``log(eps + A lambda_i / (2 pi (i + 1)))`` for ``i < count``, with ``A`` the mesh's
    area and ``eps = 0.01``. Weyl's law for a line bundle on a surface,
    ``lambda_i ~ 2 pi i / A``, makes these numbers of order one; how a mesh's spectrum
    departs from the law is what they carry. ``operator="laplacian"``: those of the
    vertex Laplacian after the first (the constant mode),
    ``log(eps + A lambda_i / (4 pi i))`` for ``1 <= i <= count`` (Weyl's law for
    functions, ``lambda_i ~ 4 pi i / A``). Eigenvalues do not change with rigid motions or
    a renumbering of the vertices, and ``A lambda_i`` not with the scale. Those of ``L_c``
    also depend on how the surface turns a tangent vector around (its holonomy), which
    the Laplace-Beltrami eigenpairs, and the heat kernel signatures made from them, do
    not see.

    Parameters
    ----------
    batch : :class:`MeshBatch` with ``edge_evals`` ``(B, k)`` (or ``vertex_evals`` for
        ``"laplacian"``), ``vertex_mass`` and ``vertex_batch``
    count : int, at most ``k`` (``k - 1`` for ``"laplacian"``)
    operator : {"connection", "laplacian"}

    Returns
    -------
    ``(B, count)`` tensor in the dtype of ``batch.vertex_mass``.
    """
    if operator not in SPECTRUM_OPERATORS:
        raise ValueError(f"operator must be one of {SPECTRUM_OPERATORS}, got {operator!r}")
    attribute, first, weyl, name, option = _SPECTRA[operator]
    evals, mass = getattr(batch, attribute), batch.vertex_mass
    if first + count > evals.shape[1]:
        raise ValueError(
            f"spectrum={count} needs at least {first + count} eigenpairs of {name}, the batch has "
            f"{evals.shape[1]} (compute_operators(..., {option}={first + count}))"
        )
    area = mass.new_zeros(batch.num_meshes).index_add_(0, batch.vertex_batch, mass)
    law = weyl * torch.arange(1, count + 1, dtype=mass.dtype, device=mass.device)
    return torch.log(_SPECTRUM_EPS + evals[:, first : first + count].to(mass.dtype) * area[:, None] / law)


def _spectrum_layer(count: int, out_channels: int) -> nn.Linear | None:
    """The linear layer of the ``spectrum`` readout (created last in a model, so that a seed
    initialises the rest of it as without one)."""
    return nn.Linear(count, out_channels, bias=False) if count else None


def _with_spectrum(layer: nn.Linear | None, operator: str, logits: torch.Tensor, batch) -> torch.Tensor:
    """``logits`` plus ``layer`` of the :func:`spectrum_features` of ``operator`` (if a layer)."""
    if layer is None:
        return logits
    return logits + layer(spectrum_features(batch, layer.in_features, operator).to(logits.dtype))


def _diffuse_vertices(diffusion: LearnedDiffusion, x, batch) -> torch.Tensor:
    return diffusion(
        x, batch.vertex_mass, evals=batch.vertex_evals, evecs=batch.vertex_evecs, offsets=batch.vertex_offsets
    )
