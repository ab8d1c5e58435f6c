"""n-direction fields by their representation vectors: angle-based n-th powers and roots (thesis 2.2)."""

from __future__ import annotations

import math

import torch

from .._dtypes import complex_dtype
from .._validation import check_n

__all__ = ["nth_power", "nth_root", "nth_roots"]


def _as_complex(z, name: str = "z") -> torch.Tensor:
    if not isinstance(z, torch.Tensor):
        z = torch.as_tensor(z)
    if z.is_complex():
        return z
    if z.is_floating_point():
        return z.to(complex_dtype(z.dtype))
    raise ValueError(f"{name} must be a complex or floating tensor, got {z.dtype}")


def _unit(z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(|z|, z / |z|)`` with ``z / |z| = 1`` where ``z = 0`` (gradients stay finite)."""
    r = z.abs()
    safe = torch.where(r > 0, r, torch.ones_like(r))
    return r, torch.where(r > 0, z / safe, torch.ones_like(z))


def nth_power(u, n: int) -> torch.Tensor:
    """The angle-based ``n``-th power ``z = |u| e^{i n arg(u)}`` (thesis 2.2).

    Unlike the ordinary power used by Knoeppel et al. (2013), the norm is preserved, so a
    field and its representation vector have the same magnitude.

    Parameters
    ----------
    u : complex tensor of any shape
    n : int >= 1

    Returns
    -------
    complex tensor of the same shape; ``0`` where ``u = 0``.
    """
    n = check_n(n)
    u = _as_complex(u, "u")
    r, unit = _unit(u)
    return r * unit**n


def nth_root(z, n: int) -> torch.Tensor:
    """The principal angle-based ``n``-th root ``|z| e^{i arg(z) / n}`` (thesis 2.2).

    ``nth_power(nth_root(z, n), n) == z``; the root of a representation vector is one of
    the ``n`` directions of the ``n``-direction field (:func:`nth_roots` gives all).

    Parameters
    ----------
    z : complex tensor of any shape
    n : int >= 1

    Returns
    -------
    complex tensor of the same shape, with ``arg`` in ``(-pi/n, pi/n]``.
    """
    n = check_n(n)
    z = _as_complex(z)
    return torch.polar(z.abs(), torch.angle(z) / n)


def nth_roots(z, n: int) -> torch.Tensor:
    """All ``n`` angle-based ``n``-th roots ``|z| e^{i (arg z + 2 pi k) / n}``, ``k < n``.

    Returns
    -------
    complex tensor of shape ``z.shape + (n,)``.
    """
    n = check_n(n)
    z = _as_complex(z)
    real = z.real.dtype
    k = torch.arange(n, device=z.device, dtype=real)
    phase = (torch.angle(z)[..., None] + 2 * math.pi * k) / n
    return torch.polar(z.abs()[..., None].expand(phase.shape), phase)
