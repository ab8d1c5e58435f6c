"""Input checks shared by every public entry point.

Each check raises :class:`ValueError` with a message that names the problem and
where it is (vertex, face or edge indices, at most ``_MAX_LISTED`` of them).
Inputs are never modified: conversions return new tensors.
"""

from __future__ import annotations

import numpy as np
import torch

from ._dtypes import complex_dtype

_MAX_LISTED = 10


def list_some(items) -> str:
    """Format at most ``_MAX_LISTED`` items of a sequence for an error message."""
    items = list(items)
    shown = ", ".join(str(x) for x in items[:_MAX_LISTED])
    if len(items) > _MAX_LISTED:
        shown += f", ... ({len(items)} in all)"
    return shown


def faces_out_of_range(faces, num_vertices: int) -> list[int]:
    """Rows of ``faces`` (an ``(F, k)`` array or tensor) with a vertex index outside ``[0, num_vertices)``."""
    if isinstance(faces, torch.Tensor):
        return torch.nonzero(((faces < 0) | (faces >= num_vertices)).any(dim=1)).flatten().tolist()
    faces = np.asarray(faces)
    return np.flatnonzero(((faces < 0) | (faces >= num_vertices)).any(axis=1)).tolist()


def face_range_message(bad, num_vertices: int) -> str:
    """The message for the faces ``bad`` (indices) that have vertex indices out of range."""
    return f"faces have vertex indices outside [0, {num_vertices}) at faces [{list_some(bad)}]"


def check_face_range(faces, num_vertices: int) -> None:
    """Raise ``ValueError`` naming the faces with a vertex index outside ``[0, num_vertices)``."""
    bad = faces_out_of_range(faces, num_vertices)
    if bad:
        raise ValueError(face_range_message(bad, num_vertices))


def as_faces(faces) -> torch.Tensor:
    """Return ``faces`` as a ``(F, 3)`` int64 tensor, or raise ``ValueError``.

    Accepts torch tensors and numpy arrays of any integer dtype. Floating point,
    boolean or complex arrays are rejected rather than rounded.
    """
    if isinstance(faces, np.ndarray):
        if not np.issubdtype(faces.dtype, np.integer):
            raise ValueError(f"faces must have an integer dtype, got numpy {faces.dtype}")
        faces = torch.from_numpy(np.ascontiguousarray(faces))
    if not isinstance(faces, torch.Tensor):
        raise ValueError(f"faces must be a (F, 3) integer tensor, got {type(faces).__name__}")
    if faces.is_floating_point() or faces.is_complex() or faces.dtype == torch.bool:
        raise ValueError(f"faces must have an integer dtype, got {faces.dtype}")
    if faces.dim() != 2 or faces.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {tuple(faces.shape)}")
    if faces.shape[0] == 0:
        raise ValueError("the mesh is empty: faces has no rows")
    return faces.to(torch.int64)


def as_verts(verts, dtype: torch.dtype | None = None) -> torch.Tensor:
    """Return ``verts`` as a ``(V, 3)`` floating tensor, or raise ``ValueError``.

    Numpy arrays are converted without copying the dtype away (float32 stays
    float32); integer input is rejected. ``(V, 2)`` planar input is padded with
    a zero third coordinate. NaN or Inf coordinates raise, naming the vertices.
    The result keeps the autograd graph of a tensor input.
    """
    if isinstance(verts, np.ndarray):
        if not np.issubdtype(verts.dtype, np.floating):
            raise ValueError(f"verts must have a floating dtype, got numpy {verts.dtype}")
        verts = torch.from_numpy(np.ascontiguousarray(verts))
    if not isinstance(verts, torch.Tensor):
        raise ValueError(f"verts must be a (V, 3) floating tensor, got {type(verts).__name__}")
    if not verts.is_floating_point():
        raise ValueError(f"verts must have a floating dtype (float32 or float64), got {verts.dtype}")
    if dtype is not None:
        verts = verts.to(dtype)
    if verts.dim() != 2 or verts.shape[1] not in (2, 3):
        raise ValueError(f"verts must have shape (V, 3) or (V, 2), got {tuple(verts.shape)}")
    if verts.shape[0] == 0:
        raise ValueError("the mesh is empty: verts has no rows")
    finite = torch.isfinite(verts.detach()).all(dim=1)
    if not bool(finite.all()):
        bad = torch.nonzero(~finite).flatten().tolist()
        raise ValueError(f"verts has NaN or Inf coordinates at vertices [{list_some(bad)}]")
    if verts.shape[1] == 2:
        verts = torch.cat([verts, verts.new_zeros(verts.shape[0], 1)], dim=1)
    return verts


def check_n(n, minimum: int = 1) -> int:
    """Return the symmetry order ``n`` as an int, or raise ``ValueError``."""
    if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < minimum:
        raise ValueError(f"n must be an integer >= {minimum}, got {n!r}")
    return int(n)


def check_vertex_count(verts: torch.Tensor, num_vertices: int) -> None:
    """Raise if the vertex array does not match the topology's vertex count."""
    if verts.shape[0] != num_vertices:
        raise ValueError(
            f"verts has {verts.shape[0]} rows but the topology was built for {num_vertices} vertices"
        )


def as_edge_field(z, topo, like: torch.Tensor, name: str = "z") -> torch.Tensor:
    """Check and convert an edge field ``(E,)`` or ``(E, C)`` to the complex dtype of ``like``.

    ``topo`` is anything with ``num_edges`` (a :class:`~torch_edgevf.mesh.topology.Topology`).
    """
    if not isinstance(z, torch.Tensor):
        z = torch.as_tensor(z)
    if z.dim() not in (1, 2) or z.shape[0] != topo.num_edges:
        raise ValueError(
            f"{name} must have shape (E,) or (E, C) with E = {topo.num_edges} edges, got {tuple(z.shape)}"
        )
    if not (z.is_complex() or z.is_floating_point()):
        raise ValueError(f"{name} must be a floating or complex tensor, got {z.dtype}")
    target = complex_dtype(like.dtype)
    if z.is_complex() and z.dtype != target:
        raise ValueError(f"{name} has dtype {z.dtype} but the mesh is {like.dtype}: expected {target}")
    if not torch.isfinite(z.detach()).all():
        bad = torch.nonzero(~torch.isfinite(z.detach()).reshape(z.shape[0], -1).all(1)).flatten().tolist()
        raise ValueError(f"{name} has NaN or Inf values at edges {bad[:10]}")
    return z.to(device=like.device, dtype=target)
