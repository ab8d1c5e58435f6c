"""Intrinsic mollification: edge lengths valid where faces have zero area."""

from __future__ import annotations

import torch

# --------------------------------------------------------------------------- soups

#: Margin of :func:`mollify_lengths` relative to the mean edge length (robust_laplacian's
#: default ``mollify_factor``).
MOLLIFY_FACTOR = 1e-5


def mollify_lengths(lengths: torch.Tensor, face_edges, factor: float = MOLLIFY_FACTOR):
    """Intrinsic mollification of edge lengths (Sharp and Crane 2020, section 4.5).

    Every length is increased by the same smallest ``epsilon >= 0`` that makes each
    triangle satisfy the triangle inequality strictly, with the margin ``delta``:

    .. math::  \\delta = \\text{factor}\\,\\bar l, \\qquad
               \\epsilon = \\max\\Big(0, \\max_{f, k}\\, \\delta - (l_{k+1} + l_{k+2} - l_k)\\Big),
               \\qquad \\tilde l = l + \\epsilon,

    so that ``l~_{k+1} + l~_{k+2} - l~_k >= delta`` in every face. Faces that already have
    the margin keep their shape up to the common shift, and ``epsilon = 0`` when no face
    is degenerate. Differentiable in ``lengths``.

    Parameters
    ----------
    lengths : (E,) floating tensor, one per edge
    face_edges : (F, 3) integer tensor or array, the edge opposite each corner
    factor : float >= 0, ``delta`` relative to the mean edge length

    Returns
    -------
    lengths : (E,) tensor ``l + epsilon``
    epsilon : scalar tensor
    faces : (K,) int64 tensor, the faces that lacked the margin
    """
    if not (isinstance(factor, (int, float)) and factor >= 0):
        raise ValueError(f"factor must be a number >= 0, got {factor!r}")
    fe = torch.as_tensor(face_edges, dtype=torch.int64, device=lengths.device)
    fl = lengths[fe]  # (F, 3)
    slack = fl.sum(1, keepdim=True) - 2 * fl  # l_{k+1} + l_{k+2} - l_k
    delta = factor * lengths.mean()
    short = (delta - slack).amax(1)
    eps = torch.clamp(short.max(), min=0.0)
    faces = torch.nonzero(short.detach() > 0).flatten()
    return lengths + eps, eps, faces
