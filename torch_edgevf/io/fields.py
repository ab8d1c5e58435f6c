"""Field files: a mesh with a complex field on its edges (``.npz`` or ``.txt``)."""

from __future__ import annotations

import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from .mesh import _check_mesh

FIELD_FORMAT_VERSION = 1
_FIELD_KEYS = ("verts", "faces", "edges", "z", "n", "version")


# ----------------------------------------------------------------------------- fields


def edges_from_faces(faces) -> np.ndarray:
    """Unique undirected edges of a triangle mesh.

    Parameters
    ----------
    faces : (F, 3) integer array or tensor

    Returns
    -------
    edges : (E, 2) int64 array
        Pairs ``(i, j)`` with ``i < j`` in lexicographic order, the ordering of
        :mod:`torch_edgevf.mesh.topology`.
    """
    f = faces.detach().cpu().numpy() if isinstance(faces, torch.Tensor) else np.asarray(faces)
    pairs = np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).astype(np.int64), axis=1)
    return np.unique(pairs, axis=0)


@dataclass
class FieldData:
    """An edge field read by :func:`load_field`.

    Attributes
    ----------
    verts, faces : the mesh, ``(V, 3)`` float64 and ``(F, 3)`` int64 tensors
    edges : (E, 2) int64 tensor, ``i < j``, lexicographic order
    z : (E,) or (E, C) complex128 tensor, in the order of ``edges``
    n : int, symmetry order of the field (1: vectors, 2: lines, 4: crosses, ...)
    extra : dict of the additional arrays given to :func:`save_field` (npz only)
    """

    verts: torch.Tensor
    faces: torch.Tensor
    edges: torch.Tensor
    z: torch.Tensor
    n: int
    extra: dict = field(default_factory=dict)


def save_field(path, verts, faces, z, n: int = 1, **extra) -> None:
    """Save a mesh and a complex edge field to ``.npz`` or ``.txt``.

    Parameters
    ----------
    path : str or Path, ending in ``.npz`` or ``.txt``
    verts : (V, 3) float tensor or array
    faces : (F, 3) integer tensor or array
    z : (E,) or (E, C) complex (or real) tensor or array, one value per edge of
        :func:`edges_from_faces` ``(faces)``, stored as complex128
    n : positive int, symmetry order
    **extra : additional numeric arrays (npz only), e.g. ``singularities=...``
    """
    path = Path(path)
    where = f"cannot save field {path}"
    v, f = _check_mesh(verts, faces, where)
    edges = edges_from_faces(f)
    zz = z.detach().cpu().numpy() if isinstance(z, torch.Tensor) else np.asarray(z)
    if not (np.issubdtype(zz.dtype, np.complexfloating) or np.issubdtype(zz.dtype, np.floating)):
        raise ValueError(f"{where}: z must be complex or real, got dtype {zz.dtype}")
    zz = zz.astype(np.complex128)
    if zz.ndim not in (1, 2) or zz.shape[0] != len(edges) or 0 in zz.shape[1:]:
        raise ValueError(
            f"{where}: z must have shape (E,) or (E, C) with E = {len(edges)} edges and C >= 1, "
            f"got {zz.shape}"
        )
    n = _check_n(n, where)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        arrays = {}
        for key, value in extra.items():
            if key in _FIELD_KEYS or key in ("file", "allow_pickle"):
                raise ValueError(f"{where}: extra array name {key!r} is reserved")
            value = value.detach().cpu().numpy() if isinstance(value, torch.Tensor) else np.asarray(value)
            if value.dtype == object:
                raise ValueError(
                    f"{where}: extra array {key!r} is not numeric (object arrays would need pickle)"
                )
            arrays[key] = value
        with open(path, "wb") as fh:  # a file object stops np.savez from appending '.npz'
            np.savez(
                fh,
                allow_pickle=False,
                verts=v,
                faces=f,
                edges=edges,
                z=zz,
                n=np.int64(n),
                version=np.int64(FIELD_FORMAT_VERSION),
                **arrays,
            )
    elif suffix == ".txt":
        if extra:
            raise ValueError(f"{where}: the text format cannot store extra arrays {sorted(extra)}; use .npz")
        z2 = zz.reshape(len(edges), -1)
        parts = np.empty((len(edges), 2 * z2.shape[1]))
        parts[:, 0::2], parts[:, 1::2] = z2.real, z2.imag
        head = (
            f"edgevf_field version={FIELD_FORMAT_VERSION} V={len(v)} F={len(f)} E={len(edges)} "
            f"C={z2.shape[1]} n={n} dims={zz.ndim}\n"
        )
        edge_fmt = "%d %d " + " ".join(["%.17g"] * parts.shape[1])
        with open(path, "w", encoding="ascii") as fh:
            fh.write(head)
            np.savetxt(fh, v, fmt="%.17g %.17g %.17g")
            np.savetxt(fh, f, fmt="%d %d %d")
            for (i, j), row in zip(edges.tolist(), parts.tolist()):
                fh.write(edge_fmt % (i, j, *row) + "\n")
    else:
        raise ValueError(f"{where}: unsupported extension {path.suffix!r}, expected '.npz' or '.txt'")


def load_field(path) -> FieldData:
    """Load a field written by :func:`save_field` and check it.

    Raises
    ------
    ValueError
        Missing file, unknown extension or version, wrong shapes or dtypes, face
        indices out of range, or stored edges that differ from the edges of the
        faces.
    """
    path = Path(path)
    where = f"cannot load field {path}"
    if not path.is_file():
        raise ValueError(f"{where}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".npz":
        v, f, edges, z, n, extra = _read_npz(path, where)
    elif suffix == ".txt":
        v, f, edges, z, n, extra = _read_txt(path, where)
    else:
        raise ValueError(f"{where}: unsupported extension {path.suffix!r}, expected '.npz' or '.txt'")
    v, f = _check_mesh(v, f, where)
    expected = edges_from_faces(f)
    if edges.shape != expected.shape or not np.array_equal(edges, expected):
        raise ValueError(
            f"{where}: the stored edges ({len(edges)}) do not match the {len(expected)} edges of the faces"
            " (unique pairs i < j in lexicographic order); the file is corrupted or was written for"
            " other faces"
        )
    if z.ndim not in (1, 2) or z.shape[0] != len(edges):
        raise ValueError(f"{where}: z must have shape (E,) or (E, C) with E = {len(edges)}, got {z.shape}")
    return FieldData(
        verts=torch.from_numpy(v),
        faces=torch.from_numpy(f),
        edges=torch.from_numpy(edges),
        z=torch.from_numpy(z),
        n=_check_n(n, where),
        extra={k: torch.from_numpy(a) if a.dtype.kind in "biufc" else a for k, a in extra.items()},
    )


def _check_n(n, where: str) -> int:
    if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"{where}: n must be a positive integer, got {n!r}")
    return int(n)


def _read_npz(path: Path, where: str):
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as err:
        raise ValueError(f"{where}: not a readable .npz file ({err})") from err
    missing = [k for k in _FIELD_KEYS if k not in arrays]
    if missing:
        raise ValueError(f"{where}: missing arrays {missing}; not a field file written by save_field")
    version = int(arrays.pop("version"))
    if version != FIELD_FORMAT_VERSION:
        raise ValueError(
            f"{where}: format version {version} is not supported (expected {FIELD_FORMAT_VERSION})"
        )
    z = arrays.pop("z")
    edges = arrays.pop("edges")
    if z.dtype != np.complex128:
        raise ValueError(f"{where}: z must be complex128, got {z.dtype}")
    if edges.ndim != 2 or edges.shape[1] != 2 or not np.issubdtype(edges.dtype, np.integer):
        raise ValueError(
            f"{where}: edges must be an (E, 2) integer array, got shape {edges.shape}, dtype {edges.dtype}"
        )
    n = arrays.pop("n")
    if n.shape != () or not np.issubdtype(n.dtype, np.integer):
        raise ValueError(f"{where}: n must be an integer scalar, got shape {n.shape}, dtype {n.dtype}")
    v, f = arrays.pop("verts"), arrays.pop("faces")
    return v, f, edges.astype(np.int64), z, n[()], arrays


_HEADER = re.compile(r"^edgevf_field((?:\s+\w+=\d+)+)\s*$")


def _read_txt(path: Path, where: str):
    with open(path, encoding="ascii", errors="replace") as fh:
        lines = [line for line in fh.read().splitlines() if line.strip()]
    match = _HEADER.match(lines[0]) if lines else None
    if match is None:
        raise ValueError(
            f"{where}: the first line must be 'edgevf_field version=1 V=.. F=.. E=.. C=.. n=.. dims=..'"
        )
    head = {k: int(val) for k, val in re.findall(r"(\w+)=(\d+)", match.group(1))}
    missing = [k for k in ("version", "V", "F", "E", "C", "n", "dims") if k not in head]
    if missing:
        raise ValueError(f"{where}: header lacks {missing}")
    if head["version"] != FIELD_FORMAT_VERSION:
        raise ValueError(
            f"{where}: format version {head['version']} is not supported (expected {FIELD_FORMAT_VERSION})"
        )
    nv, nf, ne, nc = head["V"], head["F"], head["E"], head["C"]
    if head["dims"] not in (1, 2) or nc < 1 or (head["dims"] == 1 and nc != 1):
        raise ValueError(f"{where}: invalid header dims={head['dims']} C={nc}")
    if len(lines) != 1 + nv + nf + ne:
        raise ValueError(
            f"{where}: header announces {nv} + {nf} + {ne} data lines, the file has {len(lines) - 1}"
        )

    def block(start, count, cols, dtype, what):
        rows = lines[start : start + count]
        try:
            arr = np.array(" ".join(rows).split(), dtype=dtype)
        except ValueError as err:
            raise ValueError(f"{where}: cannot parse the {what} lines ({err})") from err
        if arr.size != count * cols:
            raise ValueError(f"{where}: each of the {count} {what} lines must have {cols} numbers")
        return arr.reshape(count, cols)

    v = block(1, nv, 3, np.float64, "vertex")
    f = block(1 + nv, nf, 3, np.int64, "face")
    e = block(1 + nv + nf, ne, 2 + 2 * nc, np.float64, "edge")
    edges = e[:, :2].astype(np.int64)
    if not np.array_equal(edges, e[:, :2]) or np.any(edges[:, 0] >= edges[:, 1]):
        raise ValueError(f"{where}: edge endpoints must be integers i < j")
    order = np.lexsort((edges[:, 1], edges[:, 0]))  # accept edge lines in any order
    edges, e = edges[order], e[order]
    z = np.empty((ne, nc), dtype=np.complex128)
    z.real, z.imag = e[:, 2::2], e[:, 3::2]  # not re + 1j * im, which turns -0.0 into 0.0
    return v, f, edges, (z[:, 0] if head["dims"] == 1 else z), head["n"], {}
