"""The readers of PLY files: the common layouts vectorised; polygons, mixed list lengths and
triangle strips."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..mesh.repair.polygons import Polygons
from .numbers import parse_numbers, tokens_per_line

_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}


def _read_ply(path: Path):
    """Positions, faces and the vertex and face counts of a PLY file in a common layout, or None.

    The common layouts: a ``vertex`` element first, of scalar properties with ``x, y, z``,
    then a ``face`` element whose only property is the list ``vertex_indices`` (or
    ``vertex_index``); binary with every list as long as the first, or ASCII with one
    record a line. Elements after ``face`` are not read. The faces are an ``(F, 3)`` array
    for triangles, else an ``(F, k)`` array or :class:`Polygons`. None for
    any other layout, or a file shorter than its header says: the general readers take it.
    """
    data = path.read_bytes()
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        return None
    body = data.find(b"\n", end) + 1
    if body == 0:
        return None
    header = _ply_header(data[:end].decode("latin-1"))
    if header is None:
        return None
    fmt, elements = header
    if len(elements) < 2 or elements[0][0] != "vertex" or elements[1][0] != "face":
        return None
    (_, nv, vprops), (_, nf, fprops) = elements[0], elements[1]
    names = [p[0] for p in vprops]
    if any(len(p) != 2 for p in vprops) or not {"x", "y", "z"} <= set(names) or nf == 0:
        return None
    if len(fprops) != 1 or len(fprops[0]) != 3 or fprops[0][0] not in ("vertex_indices", "vertex_index"):
        return None
    _, count_type, index_type = fprops[0]
    if fmt == "ascii":
        return _read_ply_ascii(data[body:].decode("latin-1"), nv, nf, names)
    order = "<" if fmt == "binary_little_endian" else ">"
    vdtype = np.dtype([(name, order + t) for name, t in vprops])
    start = body + nv * vdtype.itemsize
    ctype, itype = np.dtype(order + count_type), np.dtype(order + index_type)
    if start + ctype.itemsize > len(data):
        return None
    if names == ["x", "y", "z"] and len({t for _, t in vprops}) == 1:
        coords = np.frombuffer(data, np.dtype(order + vprops[0][1]), count=3 * nv, offset=body)
        verts = coords.reshape(nv, 3).astype(np.float64)
    else:
        rows = np.frombuffer(data, vdtype, count=nv, offset=body)
        verts = np.column_stack([rows[c].astype(np.float64) for c in "xyz"])
    k = int(np.frombuffer(data, ctype, count=1, offset=start)[0])
    fdtype = np.dtype([("k", ctype), ("index", itype, (k,))])
    if k < 1 or start + nf * fdtype.itemsize > len(data):
        return None
    records = np.frombuffer(data, fdtype, count=nf, offset=start)
    if (records["k"] != k).any():
        return None  # lists of several lengths: read row by row
    return verts, records["index"].astype(np.int64), nv, nf


def _ply_header(text: str):
    """``(format, [(name, count, properties)])`` of a PLY header, or None if unusual.

    A property is ``(name, type)`` or, for a list, ``(name, count_type, item_type)``, with
    numpy type codes without byte order.
    """
    fmt = None
    elements: list = []
    for line in text.splitlines()[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        try:
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                elements.append((words[1], int(words[2]), []))
            elif words[0] == "property" and elements:
                if words[1] == "list":
                    elements[-1][2].append((words[4], _PLY_TYPES[words[2]], _PLY_TYPES[words[3]]))
                else:
                    elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
            else:
                return None
        except (IndexError, KeyError, ValueError):
            return None
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        return None
    if any(n < 0 for _, n, _ in elements):
        return None
    return fmt, elements


def _read_ply_ascii(body: str, nv: int, nf: int, names: list[str]):
    lines = body.split("\n", nv + nf)
    if len(lines) < nv + nf:
        return None
    p = len(names)
    values = parse_numbers("\n".join(lines[:nv]), np.float64)
    if values is None or len(values) != nv * p:
        return None
    values = values.reshape(nv, p)
    verts = np.ascontiguousarray(values[:, [names.index(c) for c in "xyz"]])
    joined = "\n".join(lines[nv : nv + nf])
    flat = parse_numbers(joined, np.int64)
    if flat is None:
        return None
    counts = tokens_per_line(joined, nf)
    if (counts < 1).any():
        return None
    first = np.cumsum(counts) - counts
    if (flat[first] != counts - 1).any():
        return None
    if (counts == 4).all():
        return verts, flat.reshape(nf, 4)[:, 1:], nv, nf
    keep = np.ones(len(flat), dtype=bool)
    keep[first] = False  # the corner counts
    return verts, Polygons(flat[keep], counts - 1), nv, nf


def _ply_polygons(loaded, path: Path):
    """Positions and polygons of a PLY file that trimesh read, if a face has more than three corners.

    trimesh splits such faces into fans from their first corner, but keeps the parsed
    elements in ``metadata["_ply_raw"]``: the ``vertex`` element's ``x, y, z`` and the
    ``face`` element's ``vertex_indices`` (or ``vertex_index``) lists are taken from there.
    Its binary reader takes every list to be as long as the first; when the stored lengths
    say otherwise (the sizes happened to add up) the file is read again by
    :func:`_read_ply_binary_polygons`. None for a file of triangles (trimesh's result stands).
    """
    raw = getattr(loaded, "metadata", {}).get("_ply_raw")
    if not isinstance(raw, dict) or "vertex" not in raw or "face" not in raw:
        return None
    data = raw["face"].get("data")
    names = (
        list(data)
        if isinstance(data, dict)
        else list(getattr(getattr(data, "dtype", None), "names", None) or [])
    )
    name = next(
        (n for n in ("vertex_indices", "vertex_index") if n in names), names[0] if len(names) == 1 else None
    )
    if name is None:
        return None
    lists = data[name]
    if isinstance(lists, np.ndarray) and lists.dtype.names == ("f0", "f1"):  # binary: (count, indices)
        counts, lists = lists["f0"], lists["f1"]
        if lists.ndim != 2 or (counts != lists.shape[1]).any():
            return _read_ply_binary_polygons(path)
    polys: np.ndarray | list[np.ndarray]
    if isinstance(lists, np.ndarray) and lists.dtype != object:
        if lists.ndim != 2 or lists.shape[1] <= 3:
            return None
        polys = lists.astype(np.int64)
    else:
        polys = [np.asarray(p, dtype=np.int64).reshape(-1) for p in lists]
        if max((len(p) for p in polys), default=0) <= 3:
            return None
    vdata = raw["vertex"]["data"]
    verts = np.column_stack([np.asarray(vdata[c], dtype=np.float64).reshape(-1) for c in "xyz"])
    return verts, polys


def _read_ply_binary_polygons(path: Path):
    """Positions and polygons of a binary PLY file, read row by row, or None.

    trimesh's binary reader takes every list of an element to be as long as the first, so it
    rejects (or misreads) a file that mixes, say, triangles and quads; here the rows of
    elements with list properties are read one at a time. Elements after ``vertex`` and
    ``face`` are not read. None for an ASCII file, a file without ``vertex`` (with ``x, y,
    z``) or ``face`` elements, or one shorter than its header says.
    """
    from trimesh.exchange import ply

    try:
        with open(path, "rb") as fh:
            elements, is_ascii, _ = ply._parse_header(fh)
            body = fh.read()
    except (ValueError, KeyError, IndexError, TypeError, UnicodeDecodeError):
        return None
    if is_ascii or "vertex" not in elements or "face" not in elements:
        return None
    verts = polys = None
    pos = 0
    try:
        for name, element in elements.items():
            # trimesh's header types: "<f4" for a scalar, "<u1, ($LIST,)<i4" for a list
            props = [
                (p, [np.dtype(t) for t in dt.split(", ($LIST,)")]) for p, dt in element["properties"].items()
            ]
            n = int(element["length"])
            if all(len(t) == 1 for _, t in props):
                dtype = np.dtype([(p, t[0]) for p, t in props])
                rows = np.frombuffer(body, dtype, count=n, offset=pos)
                pos += n * dtype.itemsize
                if name == "vertex":
                    verts = np.column_stack([rows[c].astype(np.float64) for c in "xyz"])
            elif name == "vertex":
                return None
            else:
                lists = [p for p, t in props if len(t) == 2]
                want = next((p for p in ("vertex_indices", "vertex_index") if p in lists), lists[0])
                found = []
                for _ in range(n):
                    for p, t in props:
                        if len(t) == 1:
                            pos += t[0].itemsize
                            continue
                        count, item = t
                        k = int.from_bytes(
                            body[pos : pos + count.itemsize],
                            "big" if count.str[0] == ">" else "little",
                            signed=count.kind == "i",
                        )
                        pos += count.itemsize
                        if k < 0 or pos + k * item.itemsize > len(body):
                            return None
                        if p == want and name == "face":
                            found.append(np.frombuffer(body, item, count=k, offset=pos).astype(np.int64))
                        pos += k * item.itemsize
                if pos > len(body):
                    return None
                if name == "face":
                    polys = found
            if verts is not None and polys is not None:
                return verts, polys
    except (ValueError, KeyError, TypeError):
        return None
    return None


def _read_ply_strips(path: Path):
    """Vertices and the triangles of the ``tristrips`` element of a PLY file, or None.

    Strips restart at ``-1``; triangle ``k`` of a strip is ``(s_k, s_k+1, s_k+2)`` with every
    other one reversed to keep the winding; the degenerate triangles that join strips are
    left out.
    """
    from trimesh.exchange import ply

    try:
        with open(path, "rb") as fh:
            elements, is_ascii, _ = ply._parse_header(fh)
            if "tristrips" not in elements or "vertex" not in elements:
                return None
            (ply._ply_ascii if is_ascii else ply._ply_binary)(elements, fh)
    except (ValueError, KeyError, IndexError, TypeError, AttributeError):
        return None
    vdata = elements["vertex"]["data"]
    verts = np.column_stack([np.asarray(vdata[c], dtype=np.float64).reshape(-1) for c in "xyz"])
    sdata = elements["tristrips"]["data"]
    strips = sdata.get("vertex_indices", next(iter(sdata.values()))) if isinstance(sdata, dict) else sdata
    tris = []
    for strip in strips:
        s = np.asarray(strip, dtype=np.int64).reshape(-1)
        for run in np.split(s, np.flatnonzero(s < 0)):
            run = run[run >= 0]
            for k in range(len(run) - 2):
                t = run[k : k + 3] if k % 2 == 0 else run[[k + 1, k, k + 2]]
                if len(set(t.tolist())) == 3:
                    tris.append(t)
    if not tris:
        return None
    return verts, np.array(tris, dtype=np.int64)
