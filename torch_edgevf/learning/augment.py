"""Augmentation of meshes for learning: random non-rigid stretches and smooth warps.

Networks on intrinsic inputs (heat kernel signatures) and rigid-motion invariant layers
gain nothing from random rotations; a stretch changes the intrinsic geometry itself,
as differently proportioned instances of a class do, and a warp changes it differently
from place to place (one part of a shape thicker or longer than another). The copies'
operators are computed like the meshes' (and cached: the same generator state gives the
same copy).
"""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["random_stretch", "random_warp"]


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
    v, dtype, is_torch = _vertices(verts)
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    rot = q * np.sign(np.diag(r))
    scale = np.exp(rng.uniform(-np.log(max_factor), np.log(max_factor), 3))
    w = (v - v.mean(0)) @ rot * scale @ rot.T
    if unit_sphere:
        w = _to_unit_sphere(w)
    return _like(w, verts, dtype, is_torch)


def random_warp(
    verts,
    rng: np.random.Generator,
    strain: float = 0.3,
    waves: int = 3,
    wavelength: float = 2.0,
    unit_sphere: bool = True,
):
    """The vertices moved by a smooth random warp: ``x + a sum_j u_j sin(w_j . x + p_j)``.

    Each of the ``waves`` terms is a plane wave of the given ``wavelength`` along a random
    direction ``w_j / |w_j|``, displacing along a random unit vector ``u_j`` with a random
    phase ``p_j``. The amplitude ``a`` is such that the Jacobian of the warp differs from
    the identity by at most ``strain`` (in the spectral norm) everywhere, so that for
    ``strain < 1`` the warp is one to one: lengths change by at most that factor, more in
    some places than in others. With the default wavelength, twice the radius of a mesh
    scaled to the unit sphere, a wave changes proportions between the parts of a shape.
    With ``unit_sphere`` the result is centred and scaled so that its farthest vertex is
    at distance 1 (see :func:`random_stretch`).

    Parameters
    ----------
    verts, unit_sphere : as for :func:`random_stretch`
    rng : numpy.random.Generator; the draws (waves x 3 normals for the directions, as
        many for the displacements, then the phases) decide the warp
    strain : float in [0, 1); waves : int, at least 1; wavelength : float, positive

    Example
    -------
    >>> from torch_edgevf import icosphere
    >>> v = icosphere(2)[0]
    >>> w = random_warp(v, np.random.default_rng(0), strain=0.2)
    >>> bool(((w - v).norm(dim=1) > 0.01).any()), round(float(w.norm(dim=1).max()), 12)
    (True, 1.0)
    """
    if not (isinstance(strain, (int, float)) and 0 <= strain < 1):
        raise ValueError(f"strain must be a number in [0, 1), got {strain!r}")
    if not (isinstance(waves, int) and not isinstance(waves, bool) and waves >= 1):
        raise ValueError(f"waves must be an integer >= 1, got {waves!r}")
    if not (isinstance(wavelength, (int, float)) and np.isfinite(wavelength) and wavelength > 0):
        raise ValueError(f"wavelength must be a finite positive number, got {wavelength!r}")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    v, dtype, is_torch = _vertices(verts)
    k = 2 * np.pi / wavelength
    directions = _unit_rows(rng.standard_normal((waves, 3)))
    displacements = _unit_rows(rng.standard_normal((waves, 3)))
    phases = rng.uniform(0, 2 * np.pi, waves)
    # Jacobian - I = a k sum_j cos(.) u_j d_j^T, of spectral norm at most a k waves
    amplitude = strain / (k * waves)
    w = v + amplitude * np.sin(k * v @ directions.T + phases) @ displacements
    if unit_sphere:
        w = _to_unit_sphere(w)
    return _like(w, verts, dtype, is_torch)


def _unit_rows(a: np.ndarray) -> np.ndarray:
    return a / np.linalg.norm(a, axis=1, keepdims=True)


def _vertices(verts):
    """``verts`` as a float64 array, checked, with the dtype to return and whether a tensor."""
    is_torch = isinstance(verts, torch.Tensor)
    v = verts.detach().cpu().numpy() if is_torch else np.asarray(verts)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        raise ValueError(f"verts must have shape (N, 3) with N >= 1, got {tuple(v.shape)}")
    if not np.isfinite(v).all():
        bad = int(np.flatnonzero(~np.isfinite(v).all(1))[0])
        raise ValueError(f"verts must be finite; vertex {bad} is {v[bad].tolist()}")
    dtype = v.dtype if np.issubdtype(v.dtype, np.floating) else np.float64
    return v.astype(np.float64), dtype, is_torch


def _to_unit_sphere(w: np.ndarray) -> np.ndarray:
    """Centred (the middle of the bounding box at the origin), the farthest vertex at distance 1."""
    w = w - (w.max(0) + w.min(0)) / 2
    radius = np.linalg.norm(w, axis=1).max()
    return w / radius if radius > 0 else w


def _like(w: np.ndarray, verts, dtype, is_torch: bool):
    w = w.astype(dtype)
    return torch.from_numpy(w).to(verts.device) if is_torch else w
