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


def _tensor(x, kind, name: str, what: str) -> torch.Tensor:
    """``x`` as a tensor: a tensor as it is, a numpy array of the dtype ``kind``
    (``np.integer`` or ``np.floating``) without a copy of its data; else ``ValueError``."""
    if isinstance(x, np.ndarray):
        if not np.issubdtype(x.dtype, kind):
            dtype = "an integer" if kind is np.integer else "a floating"
            raise ValueError(f"{name} must have {dtype} dtype, got numpy {x.dtype}")
        x = torch.from_numpy(np.ascontiguousarray(x))
    if not isinstance(x, torch.Tensor):
        raise ValueError(f"{name} must be {what} tensor, got {type(x).__name__}")
    return x


def as_faces(faces) -> torch.Tensor:
    """Return ``faces`` as a ``(F, 3)`` int64 tensor, or raise ``ValueError``.

    Accepts torch tensors and numpy arrays of any integer dtype. Floating point,
    boolean or complex arrays are rejected rather than rounded.
    """
    faces = _tensor(faces, np.integer, "faces", "a (F, 3) integer")
    if faces.is_floating_point() or faces.is_complex() or faces.dtype == torch.bool:
        raise ValueError(f"faces must have an integer dtype, got {faces.dtype}")
    if faces.dim() != 2 or faces.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {tuple(faces.shape)}")
    if faces.shape[0] == 0:
        raise ValueError("the mesh is empty: faces has no rows")
    return faces.to(torch.int64)


#: the floating dtypes of positions (half precision cannot hold the operators: areas and
#: squared lengths under- and overflow, and torch has no sparse complex32 kernels)
FLOAT_DTYPES = (torch.float32, torch.float64)


def half_precision_message(dtype, name: str = "verts") -> str:
    """The message for positions of an unsupported floating dtype (float16, bfloat16, ...)."""
    how = f"{name}.astype(numpy.float64)" if isinstance(dtype, np.dtype) else f"{name}.double()"
    return (
        f"{name} has dtype {dtype}, which is not supported (half precision cannot hold the"
        f" operators): convert it to float64 (recommended) or float32, e.g. {how}"
    )


def check_positions_dtype(verts, name: str = "verts") -> None:
    """Raise ``ValueError`` unless a floating tensor or array ``verts`` is float32 or float64."""
    dtype = verts.dtype
    if isinstance(verts, torch.Tensor):
        if verts.is_floating_point() and dtype not in FLOAT_DTYPES:
            raise ValueError(half_precision_message(dtype, name))
    elif np.issubdtype(dtype, np.floating) and dtype not in (np.float32, np.float64):
        raise ValueError(half_precision_message(dtype, name))


def check_float_dtype(dtype, name: str = "dtype") -> torch.dtype:
    """Return ``dtype`` if it is ``torch.float32`` or ``torch.float64``, else raise ``ValueError``."""
    if not (isinstance(dtype, torch.dtype) and dtype.is_floating_point):
        raise ValueError(
            f"{name} must be a floating torch dtype (torch.float32 or torch.float64), got {dtype}"
        )
    if dtype not in FLOAT_DTYPES:
        raise ValueError(f"{name} is {dtype}, which is not supported: use torch.float32 or torch.float64")
    return dtype


def as_verts(verts, dtype: torch.dtype | None = None) -> torch.Tensor:
    """Return ``verts`` as a ``(V, 3)`` floating tensor, or raise ``ValueError``.

    Numpy arrays are converted without copying the dtype away (float32 stays
    float32); integer and half precision input (float16, bfloat16) is rejected.
    ``(V, 2)`` planar input is padded with a zero third coordinate. NaN or Inf
    coordinates raise, naming the vertices. The result keeps the autograd graph of a
    tensor input.
    """
    if isinstance(verts, np.ndarray) and np.issubdtype(verts.dtype, np.floating):
        check_positions_dtype(verts)  # the numpy dtype in the message
    verts = _tensor(verts, np.floating, "verts", "a (V, 3) floating")
    if not verts.is_floating_point():
        raise ValueError(f"verts must have a floating dtype (float32 or float64), got {verts.dtype}")
    check_positions_dtype(verts)
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
    elif z.device != like.device:
        raise ValueError(
            f"{name} is on {z.device} but the mesh is on {like.device}: move one of them "
            f"(e.g. {name}.to({str(like.device)!r}))"
        )
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


# --------------------------------------------------------------------------- mesh batches


def is_mesh_batch(obj) -> bool:
    """Whether ``obj`` is a batch of meshes with ``verts_list()`` and ``faces_list()``
    (a ``pytorch3d.structures.Meshes``, or anything shaped like it)."""
    return callable(getattr(obj, "verts_list", None)) and callable(getattr(obj, "faces_list", None))


def mesh_list(meshes, faces=None) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """The ``(verts, faces)`` of each mesh of a batch with ``verts_list()`` / ``faces_list()``.

    The tensors are those of the batch (on its device); ``faces`` must be left out (the
    batch holds them). Raises ``ValueError`` for an empty batch or lists of different
    lengths.
    """
    if faces is not None:
        raise ValueError(
            f"{type(meshes).__name__} holds its faces: pass it alone, without faces (got faces too)"
        )
    verts_list, faces_list = list(meshes.verts_list()), list(meshes.faces_list())
    if len(verts_list) != len(faces_list):
        raise ValueError(
            f"{type(meshes).__name__} has {len(verts_list)} vertex lists but {len(faces_list)} face lists"
        )
    if not verts_list:
        raise ValueError(f"{type(meshes).__name__} holds no mesh")
    return list(zip(verts_list, faces_list))


def single_mesh(verts, faces, what: str):
    """``(verts, faces)`` as they are, or those of a batch of one mesh (``verts_list()`` /
    ``faces_list()``); a batch of several raises ``ValueError`` naming ``what`` takes one."""
    if not is_mesh_batch(verts):
        return verts, faces
    meshes = mesh_list(verts, faces)
    if len(meshes) != 1:
        raise ValueError(
            f"{what} takes one mesh, got a {type(verts).__name__} batch of {len(meshes)}: pass one mesh "
            f"(e.g. meshes[i]) or loop over zip(meshes.verts_list(), meshes.faces_list())"
        )
    return meshes[0]
