"""The OBJ reader: ``v`` and ``f`` records, parsed in a few vectorised steps.

trimesh's reader splits a vertex into one copy per texture coordinate or normal, and a
face of more than three corners into a fan from its first corner (wrong for a concave
polygon); this one keeps the file's vertex records, in their order, and its polygons.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..mesh.repair.polygons import Polygons
from .numbers import line_starts, parse_numbers, per_line, token_starts

_CONTINUED = re.compile(rb"\\[ \t]*\r?\n")
_COMMENT = re.compile(rb"#[^\n]*")
_INDENT = re.compile(rb"(?m)^ +")
_AFTER_SLASH = re.compile(rb"/\S*")
_V, _F, _L, _SPACE, _SLASH = ord("v"), ord("f"), ord("l"), ord(" "), ord("/")


def _read_obj(path: Path):
    """Positions, faces and the counts of ``v`` and ``f`` records of an OBJ file.

    Only ``v`` records (their first three numbers) and ``f`` records count. A corner of an
    ``f`` record is ``i``, ``i/t``, ``i/t/n`` or ``i//n``, with ``i`` counted from 1 or, when
    negative, back from the last ``v`` record before it; ``#`` starts a comment and a
    backslash at the end of a line continues the record on the next one. Objects, groups
    and materials share the file's vertex list, so all faces are read in file order. Index
    ``0`` (not a valid OBJ index) becomes ``-1``, which :func:`load_mesh` rejects as out of
    range. The faces are an ``(F, 3)`` array when all are triangles, else :class:`Polygons`
    (polygons, and faces of fewer than three corners, which are dropped later).

    Raises ``ValueError`` for a record that cannot be parsed, a file without ``f`` records
    (a point cloud, lines, or no mesh at all).
    """
    data = path.read_bytes()
    if b"\\" in data:
        data = _CONTINUED.sub(b" ", data)
    if b"#" in data:
        data = _COMMENT.sub(b"", data)
    if b"\t" in data:
        data = data.replace(b"\t", b" ")
    if data.startswith(b" ") or b"\n " in data:
        data = _INDENT.sub(b"", data)
    b = np.frombuffer(data, dtype=np.uint8)
    starts = line_starts(b)
    pad = np.concatenate((b, [10, 10]))  # the first two bytes of every line, even a short last one
    first, second = pad[starts], pad[starts + 1]
    is_v = (first == _V) & (second == _SPACE)
    is_f = (first == _F) & (second == _SPACE)
    v_lines, f_lines = np.flatnonzero(is_v), np.flatnonzero(is_f)
    nv, nf = len(v_lines), len(f_lines)
    verts = _positions(path, data, starts, v_lines)
    if nf == 0:
        if ((first == _L) & (second == _SPACE)).any():
            raise ValueError(f"cannot read mesh {path}: it holds lines (l records), no faces")
        if nv:
            raise ValueError(f"cannot read mesh {path}: it is a point cloud ({nv} points, no faces)")
        raise ValueError(
            f"cannot read mesh {path}: no triangle faces found (the file is empty or not a valid OBJ mesh)"
        )
    block = _records(data, starts, f_lines)
    index, counts = _corner_indices(block, nf)
    if index is None:
        bad = next(
            line
            for line in block.split(b"\n")
            if parse_numbers(_AFTER_SLASH.sub(b"", line[2:]), np.int64) is None
        )
        raise ValueError(f"cannot read mesh {path}: not a valid OBJ file (record {bad.decode('latin-1')!r})")
    base = np.zeros(1, dtype=np.int64)
    if (index < 0).any():  # negative: back from the last ``v`` record before the face
        base = np.repeat(np.searchsorted(v_lines, f_lines), counts)
    index = np.where(index > 0, index - 1, np.where(index < 0, base + index, -1))
    if (counts == 3).all():
        return verts, index.reshape(nf, 3), nv, nf
    return verts, Polygons(index, counts), nv, nf


def _records(data: bytes, starts: np.ndarray, lines: np.ndarray) -> bytes:
    """The lines ``lines`` (indices into ``starts``) of ``data``, joined by newlines.

    Consecutive lines are taken as one slice (the common layout: a block of ``v`` records,
    then one of ``f`` records), so the cost is one slice per run of lines.
    """
    if not len(lines):
        return b""
    ends = np.concatenate((starts[1:] - 1, [len(data)]))
    run = np.flatnonzero(np.diff(lines) != 1)
    first = np.concatenate(([lines[0]], lines[run + 1]))
    last = np.concatenate((lines[run], [lines[-1]]))
    return b"\n".join(data[s:e] for s, e in zip(starts[first].tolist(), ends[last].tolist()))


def _corner_indices(block: bytes, nf: int):
    """The vertex index of every corner of the ``f`` records ``block`` (flat) and the corners
    per record; ``(None, None)`` if a record cannot be parsed.

    The slashes are read as separators (``i/t/n`` gives three numbers, ``i//n`` two), and the
    vertex index is the first number of each corner when every corner of the file has the
    same form (checked per line by the counts of corners, slashes and numbers); other
    files go through a slower pass that cuts each corner at its first slash.
    """
    b = np.frombuffer(block, dtype=np.uint8)
    starts = line_starts(b)
    corners = per_line(token_starts(b), starts) - 1  # the keyword ``f`` is a token
    if b"/" in block:
        slashes = per_line(b == _SLASH, starts)
        flat = parse_numbers(block.replace(b"/", b" ").replace(b"f ", b"  "), np.int64)
        if flat is not None and len(corners) == nf and corners.min() > 0:
            numbers = per_line(token_starts(np.frombuffer(block.replace(b"/", b" "), np.uint8)), starts) - 1
            per_corner, slash_per_corner = numbers[0] // corners[0], slashes[0] // corners[0]
            if (numbers == per_corner * corners).all() and (slashes == slash_per_corner * corners).all():
                return flat[::per_corner].copy(), corners
        block = _AFTER_SLASH.sub(b"", block)
        b = np.frombuffer(block, dtype=np.uint8)
        starts = line_starts(b)
        corners = per_line(token_starts(b), starts) - 1
    flat = parse_numbers(block.replace(b"f ", b"  "), np.int64)
    if flat is None or len(corners) != nf or len(flat) != corners.sum():
        return None, None
    return flat, corners


def _positions(path: Path, data: bytes, starts: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """(V, 3) float64: the first three numbers of each ``v`` record."""
    nv = len(lines)
    if nv == 0:
        return np.zeros((0, 3), dtype=np.float64)
    block = _records(data, starts, lines)
    values = parse_numbers(block.replace(b"v ", b"  "), np.float64)
    b = np.frombuffer(block, dtype=np.uint8)
    counts = per_line(token_starts(b), line_starts(b)) - 1
    if values is None or len(counts) != nv or (counts < 3).any() or len(values) != counts.sum():
        for line in block.split(b"\n"):
            words = line.split()[1:]
            if len(words) < 3 or parse_numbers(b" ".join(words), np.float64) is None:
                why = "fewer than three coordinates" if len(words) < 3 else "not a number"
                raise ValueError(
                    f"cannot read mesh {path}: not a valid OBJ file"
                    f" (record {line.decode('latin-1').strip()!r}: {why})"
                )
        raise ValueError(f"cannot read mesh {path}: not a valid OBJ file (its v records)")
    if len(values) == 3 * nv:
        return values.reshape(nv, 3)
    first = np.cumsum(counts) - counts
    return values[first[:, None] + np.arange(3)]
