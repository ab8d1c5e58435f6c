"""Augmentation of meshes for learning: random non-rigid stretches.

Networks on intrinsic inputs (heat kernel signatures) and rigid-motion invariant layers
gain nothing from random rotations; a stretch changes the intrinsic geometry itself,
as differently proportioned instances of a class do. The copies' operators are computed
like the meshes' (and cached: the same generator state gives the same copy).
"""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["random_stretch"]


def random_stretch(verts, rng: np.random.Generator, max_factor: float = 1.25, unit_sphere: bool = True):
    """The vertices stretched along random axes: ``(v - c) R diag(s) R^T``.

    ``R`` is a random rotation (uniform, from the QR decomposition of a Gaussian matrix)
    and the factors ``s`` are drawn log-uniformly in ``[1 / max_factor, max_factor]``.
    With ``unit_sphere`` the result is centred (the middle of its bounding box at the
    origin) and scaled so that its farthest vertex is at distance 1, as meshes prepared
    for learning usually are; else it keeps the centroid ``c`` at the origin.

    Parameters
    ----------
    verts : (N, 3) array or tensor; not changed (a new array or tensor of its type and
        dtype is returned)
    rng : numpy.random.Generator; the draws (3 x 3 normals, then 3 uniforms) decide the copy
    max_factor : float, at least 1
    unit_sphere : bool

    Example
    -------
    >>> import numpy as np
    >>> import torch_edgevf as ev
    >>> from torch_edgevf.learning.augment import random_stretch
    >>> v, f = ev.icosphere(2)
    >>> w = random_stretch(v, np.random.default_rng(0))
    >>> round(float(w.norm(dim=1).max()), 12)
    1.0
    """
    if not (isinstance(max_factor, (int, float)) and np.isfinite(max_factor) and max_factor >= 1):
        raise ValueError(f"max_factor must be a finite number >= 1, got {max_factor!r}")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    is_torch = isinstance(verts, torch.Tensor)
    v = verts.detach().cpu().numpy() if is_torch else np.asarray(verts)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        raise ValueError(f"verts must have shape (N, 3) with N >= 1, got {tuple(v.shape)}")
    if not np.isfinite(v).all():
        bad = int(np.flatnonzero(~np.isfinite(v).all(1))[0])
        raise ValueError(f"verts must be finite; vertex {bad} is {v[bad].tolist()}")
    dtype = v.dtype if np.issubdtype(v.dtype, np.floating) else np.float64
    v = v.astype(np.float64)
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    rot = q * np.sign(np.diag(r))
    scale = np.exp(rng.uniform(-np.log(max_factor), np.log(max_factor), 3))
    w = (v - v.mean(0)) @ rot * scale @ rot.T
    if unit_sphere:
        w -= (w.max(0) + w.min(0)) / 2
        radius = np.linalg.norm(w, axis=1).max()
        if radius > 0:
            w = w / radius
    w = w.astype(dtype)
    return torch.from_numpy(w).to(verts.device) if is_torch else w
