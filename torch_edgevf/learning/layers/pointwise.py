"""Layers per edge and channel: complex linear maps, ModReLU and invariant readouts."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from ..._device import check_devices
from ..._dtypes import real_dtype
from .sparse import _check_features

# --------------------------------------------------------------------------- pointwise layers


def complex_linear(z, weight) -> torch.Tensor:
    """``z W`` with a complex ``(C_in, C_out)`` weight: commutes with ``z -> e^{i theta} z``.

    Parameters
    ----------
    z : (N, C_in) complex tensor
    weight : (C_in, C_out) complex tensor, or (C_in, C_out, 2) real (real and imaginary parts)
    """
    z = _check_features(z, complex_only=True)
    check_devices(z=z, weight=weight)
    if weight.dim() == 3 and weight.shape[-1] == 2 and not weight.is_complex():
        weight = torch.view_as_complex(weight.contiguous())
    if weight.dim() != 2 or weight.shape[0] != z.shape[1]:
        raise ValueError(f"weight must have shape ({z.shape[1]}, C_out), got {tuple(weight.shape)}")
    return z @ weight.to(z.dtype)


def _complex_linear(z, weight) -> torch.Tensor:
    """:func:`complex_linear` on valid inputs: ``z`` complex ``(N, C_in)``, ``weight`` real
    ``(C_in, C_out, 2)``."""
    return z @ torch.view_as_complex(weight.contiguous()).to(z.dtype)


class ComplexLinear(nn.Module):
    """Rotation-equivariant linear map of channels, complex weights and no bias.

    The weight is stored as a real ``(C_in, C_out, 2)`` parameter (real and imaginary
    parts), so optimisers and ``DistributedDataParallel`` see real tensors only. A bias
    would break equivariance; put one on the modulus with :class:`ModReLU`.

    Initialisation: real and imaginary parts ``N(0, 1 / (2 C_in))``, so that
    ``E|zW|^2 = E|z|^2`` per channel.
    """

    def __init__(self, in_channels: int, out_channels: int):
        super().__init__()
        for name, c in (("in_channels", in_channels), ("out_channels", out_channels)):
            if not isinstance(c, int) or c < 1:
                raise ValueError(f"{name} must be a positive integer, got {c!r}")
        self.in_channels, self.out_channels = in_channels, out_channels
        self.weight = nn.Parameter(torch.randn(in_channels, out_channels, 2) / math.sqrt(2 * in_channels))

    def forward(self, z):
        return complex_linear(z, self.weight)

    def extra_repr(self) -> str:
        return f"{self.in_channels}, {self.out_channels}"


def modulus_relu(z, bias, eps: float | None = None) -> torch.Tensor:
    r"""``z relu(|z| + b) / |z|``: a ReLU on the modulus that keeps the phase.

    Gauge equivariant. At ``z = 0`` the output is ``0``; the denominator is clamped at
    ``eps`` (default ``1e-6`` in single, ``1e-12`` in double precision) so that values
    and gradients stay finite. For ``b > 0`` the map is
    discontinuous at ``0`` (every nonzero ``z`` gets modulus at least ``b``), as for
    any ModReLU; the learned biases usually become negative (a dead zone).

    Parameters
    ----------
    z : (N, C) complex tensor
    bias : (C,) real tensor
    """
    z = _check_features(z, complex_only=True)
    if not isinstance(bias, torch.Tensor) or bias.shape not in ((z.shape[1],), ()) or bias.is_complex():
        raise ValueError(f"bias must be a real ({z.shape[1]},) tensor")
    check_devices(z=z, bias=bias)
    rdt = real_dtype(z.dtype)
    if eps is None:
        eps = 1e-6 if rdt == torch.float32 else 1e-12
    r = z.abs()
    scale = F.relu(r + bias.to(rdt)) / r.clamp_min(eps)
    return z * scale


class ModReLU(nn.Module):
    """Module form of :func:`modulus_relu` with a learned bias per channel (init ``bias``)."""

    def __init__(self, channels: int, bias: float = 0.0):
        super().__init__()
        self.bias = nn.Parameter(torch.full((channels,), float(bias)))

    def forward(self, z):
        return modulus_relu(z, self.bias)


def invariant_features(z, weight=None, modulus: bool = True) -> torch.Tensor:
    r"""Real, gauge-invariant features of complex edge features.

    ``|z|`` (``(N, C)``, if ``modulus``) and, given a complex ``(C, C)`` weight ``A``,
    the products :math:`\mathrm{Re}(z \cdot \overline{z A})` between channels (``(N, C)``;
    the gradient features of DiffusionNet, here per edge). Both are unchanged by
    ``z -> e^{i theta} z``. Concatenated along channels.

    Parameters
    ----------
    z : (N, C) complex tensor
    weight : (C, C) complex tensor, or (C, C, 2) real, optional
    modulus : bool

    Returns
    -------
    (N, C) or (N, 2C) real tensor.
    """
    z = _check_features(z, complex_only=True)
    if weight is None and not modulus:
        raise ValueError("invariant_features needs modulus=True or a weight")
    parts = []
    if modulus:
        parts.append(z.abs())
    if weight is not None:
        w = complex_linear(z, weight)
        if w.shape[1] != z.shape[1]:
            raise ValueError(f"weight must be ({z.shape[1]}, {z.shape[1]}), got C_out = {w.shape[1]}")
        parts.append((z * w.conj()).real)
    return parts[0] if len(parts) == 1 else torch.cat(parts, dim=1)


def _invariant_products(z, weight) -> torch.Tensor:
    """``Re(z conj(z A))`` of :func:`invariant_features` (``modulus=False``) on valid inputs:
    ``z`` complex ``(N, C)``, ``weight`` real ``(C, C, 2)``."""
    return (z * _complex_linear(z, weight).conj()).real


class InvariantReadout(nn.Module):
    """Module form of :func:`invariant_features` (learned ``(C, C)`` complex weight).

    Output ``(N, 2C)`` (modulus and products), or ``(N, C)`` with ``products=False``.
    """

    def __init__(self, channels: int, products: bool = True, modulus: bool = True):
        super().__init__()
        self.modulus = modulus
        self.weight = (
            nn.Parameter(torch.randn(channels, channels, 2) / math.sqrt(2 * channels)) if products else None
        )
        self.out_channels = channels * (int(modulus) + int(products))

    def forward(self, z):
        return invariant_features(z, self.weight, modulus=self.modulus)
