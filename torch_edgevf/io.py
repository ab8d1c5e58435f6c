"""Reading and writing triangle meshes and edge-based tangent fields.

Meshes
    :func:`load_mesh` reads OBJ, PLY and STL through trimesh with ``process=False``
    (trimesh neither merges, reorders, drops faces nor fixes winding) and OFF itself;
    OBJ and PLY files with faces of more than three corners are read without
    trimesh's triangulation (see below). It then does its own documented clean-up
    and records every change in a :class:`MeshReport`:

    1. a scene of several geometries is concatenated (in scene-graph order);
    2. vertices with bitwise-identical positions are merged (``merge=True``);
       files that store per-corner normals or texture coordinates come back from
       trimesh split into disconnected triangles, and STL never shares vertices;
    3. faces with a repeated vertex index are dropped, then repeated faces (same
       three vertices in any order) keeping the first;
    4. unreferenced vertices are dropped.

    Merging is exact rather than within a tolerance: seam copies of one vertex
    carry the same coordinates, while a tolerance could fuse distinct vertices.
    Positions are never rounded or moved; kept vertices stay in first-occurrence
    order (for the meshes tested this is the order of the file's ``v`` lines).
    Polygons (faces of more than three corners, of OFF, OBJ and PLY files) are
    triangulated in their planes by :func:`~torch_edgevf.mesh.repair.triangulate`
    from the file's positions and index lists (trimesh would split them into fans
    from their first corner, which is wrong for concave ones); the report names them
    and shows the face counts of the file next to the triangle counts.

    :func:`save_mesh` writes OBJ, OFF (``%.17g`` text) and PLY (binary float64)
    itself, because trimesh writes OBJ and OFF with a fixed number of decimals and
    PLY in float32; STL goes through trimesh and is float32 by definition.

Fields
    :func:`save_field` / :func:`load_field` store a mesh with a complex field on
    its edges, ``z`` of shape ``(E,)`` or ``(E, C)``, and the symmetry order ``n``.
    Edges are the unique pairs ``(i, j)``, ``i < j``, of the faces in lexicographic
    order (:func:`edges_from_faces`). ``.npz`` (``np.savez``, no pickles) is
    bit-exact; ``.txt`` is a plain interchange format::

        edgevf_field version=1 V=<V> F=<F> E=<E> C=<C> n=<n> dims=<1|2>
        x y z                      (V lines)
        a b c                      (F lines, 0-based)
        i j re_1 im_1 ... re_C im_C   (E lines, i < j)

    with floats written as ``%.17g`` (exact round trip). ``dims`` tells whether
    ``z`` was ``(E,)`` or ``(E, C)``. The edge lines of a ``.txt`` file may come in
    any order (they are matched by their endpoints); those of ``.npz`` must be in
    ours.
"""

from __future__ import annotations

import logging
import re
import zipfile
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
import torch

log = logging.getLogger(__name__)

__all__ = [
    "MeshData",
    "MeshReport",
    "FieldData",
    "load_mesh",
    "read_triangles",
    "save_mesh",
    "default_mesh",
    "save_field",
    "load_field",
    "edges_from_faces",
]

MESH_FORMATS = ("obj", "ply", "off", "stl")
FIELD_FORMAT_VERSION = 1
_FIELD_KEYS = ("verts", "faces", "edges", "z", "n", "version")
_DEFAULT_MESH = "spot_low_resolution.obj"


# ----------------------------------------------------------------------------- meshes


@dataclass
class MeshReport:
    """What :func:`load_mesh` read and changed.

    ``file_vertices`` / ``file_faces`` are the record counts stated by the file
    (``None`` where the format does not state them, e.g. STL); ``loaded_*`` are
    what the reader returned (trimesh, or the library's own for OFF files and OBJ and
    PLY files with polygons); the other counts are the changes made afterwards.
    """

    path: str
    format: str
    num_vertices: int = 0
    num_faces: int = 0
    file_vertices: int | None = None
    file_faces: int | None = None
    loaded_vertices: int = 0
    loaded_faces: int = 0
    geometries: int = 1
    merged_vertices: int = 0
    degenerate_faces: int = 0
    duplicate_faces: int = 0
    unreferenced_vertices: int = 0
    notes: list[str] = field(default_factory=list)
    #: faces (in the order of the file's records) with a repeated vertex index: the repeats
    #: were removed, and those left with fewer than three vertices dropped
    repeated_index_faces: list[int] = field(default_factory=list)
    #: polygons of the file (record indices) split into triangles by the reader
    triangulated_faces: list[int] = field(default_factory=list)
    #: vertices (file indices) with NaN or Inf coordinates
    nonfinite_vertices: list[int] = field(default_factory=list)

    @property
    def triangulated(self) -> bool:
        """Whether the file had polygons that were split into triangles."""
        return bool(self.triangulated_faces) or (
            self.file_faces is not None and self.loaded_faces > self.file_faces
        )

    @property
    def problems(self) -> list[str]:
        """The changes that alter the surface (not only its storage), for :func:`diagnose` and ``info``."""
        out = []
        if self.repeated_index_faces:
            out.append(
                f"{len(self.repeated_index_faces)} faces with a repeated vertex index (repeats removed;"
                " a face left with fewer than 3 vertices is dropped, which can open a hole) at faces"
                f" [{_list_some(self.repeated_index_faces)}]"
            )
        elif self.degenerate_faces:
            out.append(f"{self.degenerate_faces} faces with a repeated vertex index dropped")
        if self.duplicate_faces:
            out.append(f"{self.duplicate_faces} duplicate faces dropped")
        return out

    @property
    def dropped_faces(self) -> int:
        return self.degenerate_faces + self.duplicate_faces

    def __str__(self) -> str:
        lines = [f"{self.path} ({self.format}): {self.num_vertices} vertices, {self.num_faces} faces"]
        if self.file_vertices is not None or self.file_faces is not None:
            lines.append(f"  file states {self.file_vertices} vertices, {self.file_faces} faces")
        lines.append(
            f"  read {self.loaded_vertices} vertices, {self.loaded_faces} triangles"
            f" from {self.geometries} geometr{'y' if self.geometries == 1 else 'ies'}"
        )
        if self.triangulated_faces:
            lines.append(
                f"  triangulated polygons: {self.file_faces} faces -> {self.loaded_faces} triangles"
                f" ({len(self.triangulated_faces)} polygons split into triangles in their planes)"
            )
        elif self.triangulated:
            lines.append(
                f"  triangulated polygons: {self.file_faces} faces -> {self.loaded_faces} triangles"
                " (face order may differ from the file)"
            )
        if self.repeated_index_faces:
            lines.append(
                f"  {len(self.repeated_index_faces)} faces with a repeated vertex index, repeats removed:"
                f" file faces [{_list_some(self.repeated_index_faces)}]"
            )
        lines.append(
            f"  merged {self.merged_vertices} vertices with identical positions;"
            f" dropped {self.degenerate_faces} degenerate faces, {self.duplicate_faces} duplicate faces,"
            f" {self.unreferenced_vertices} unreferenced vertices"
        )
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


@dataclass
class MeshData:
    """A triangle mesh read from a file.

    Attributes
    ----------
    verts : (V, 3) float tensor
    faces : (F, 3) int64 tensor
    report : MeshReport
    """

    verts: torch.Tensor
    faces: torch.Tensor
    report: MeshReport

    def __iter__(self):
        """Allow ``verts, faces = load_mesh(path)``."""
        return iter((self.verts, self.faces))


def load_mesh(path, dtype: torch.dtype = torch.float64, merge: bool = True) -> MeshData:
    """Read a triangle mesh from an OBJ, PLY, OFF or STL file.

    Parameters
    ----------
    path : str or Path
    dtype : torch floating dtype of the returned vertices (the file is parsed in
        float64; a smaller dtype rounds).
    merge : merge vertices with identical positions (see the module docstring).
        Degenerate and duplicate faces and unreferenced vertices are dropped
        either way.

    Returns
    -------
    MeshData
        ``verts (V, 3)``, ``faces (F, 3)`` int64 and the :class:`MeshReport`, which is
        also logged (INFO, or WARNING when faces were dropped or polygons split).

    Raises
    ------
    ValueError
        The file is missing, has an unsupported extension, cannot be parsed, holds
        no triangles (empty, point cloud, lines), or has invalid data.
    """
    path = Path(path)
    if not (isinstance(dtype, torch.dtype) and dtype.is_floating_point):
        raise ValueError(f"dtype must be a floating torch dtype, got {dtype}")
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in MESH_FORMATS:
        raise ValueError(
            f"cannot read mesh {path}: unsupported extension {path.suffix!r}, expected one of {MESH_FORMATS}"
        )
    if not path.is_file():
        raise ValueError(f"cannot read mesh {path}: no such file")
    verts, faces, report = read_triangles(path)
    finite = np.isfinite(verts).all(1)
    if not finite.all():
        bad = np.flatnonzero(~finite).tolist()
        raise ValueError(
            f"cannot read mesh {path}: {len(bad)} vertices are not finite (NaN or Inf coordinates),"
            f" at vertices [{_list_some(bad)}] (edgevf info lists every problem; repair drops their faces)"
        )
    if faces.size and (faces.min() < 0 or faces.max() >= len(verts)):
        out = np.flatnonzero(((faces < 0) | (faces >= len(verts))).any(1)).tolist()
        raise ValueError(
            f"cannot read mesh {path}: a face index outside [0, {len(verts)}) at faces [{_list_some(out)}]"
        )

    if merge:
        verts, faces = _merge_identical(verts, faces, report)
    faces = _drop_bad_faces(faces, report)
    if len(faces) == 0:
        raise ValueError(f"cannot read mesh {path}: no faces left after dropping degenerate faces")
    verts, faces = _drop_unreferenced(verts, faces, report)
    report.num_vertices, report.num_faces = len(verts), len(faces)
    if (
        report.file_vertices is not None
        and report.file_vertices > report.num_vertices + report.unreferenced_vertices
    ):
        report.notes.append(
            f"the file has {report.file_vertices - report.num_vertices} vertex records more than the mesh:"
            " unreferenced ones (the reader skips them) or repeated positions (merged)"
        )

    level = (
        logging.WARNING if report.dropped_faces or report.triangulated or report.problems else logging.INFO
    )
    log.log(level, "%s", report)
    return MeshData(torch.from_numpy(verts).to(dtype), torch.from_numpy(faces), report)


def read_triangles(path, merge: bool = False) -> tuple[np.ndarray, np.ndarray, MeshReport]:
    """The vertices and triangles of a mesh file as they are, before any clean-up.

    Nothing is checked, merged or dropped: NaN coordinates, indices out of range,
    duplicates and non-manifold configurations come back as the file holds them (for
    :func:`~torch_edgevf.mesh.repair.repair` and ``edgevf info``). The polygons of OFF,
    OBJ and PLY files are triangulated in their planes by
    :func:`~torch_edgevf.mesh.repair.triangulate` (convex ones as fans from their first
    corner, others by ear clipping) after their repeated vertex indices are removed (both
    recorded in the report, with the file's face indices); OBJ and PLY files whose faces
    are all triangles are read by trimesh as they are. Triangle strips of PLY files are
    unrolled.

    With ``merge``, vertices with bitwise-identical finite positions are merged as by
    :func:`load_mesh` (vertices with NaN or Inf coordinates are never merged).

    Returns
    -------
    verts : (V, 3) float64 array
    faces : (T, 3) int64 array
    report : :class:`MeshReport`, ``loaded_*`` and ``nonfinite_vertices`` (file indices)
        filled in
    """
    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in MESH_FORMATS:
        raise ValueError(
            f"cannot read mesh {path}: unsupported extension {path.suffix!r}, expected one of {MESH_FORMATS}"
        )
    if not path.is_file():
        raise ValueError(f"cannot read mesh {path}: no such file")
    report = MeshReport(path=str(path), format=fmt)
    if fmt == "stl":
        _check_stl(path)
    polygons = _read_off(path) if fmt == "off" else _read_obj_polygons(path) if fmt == "obj" else None
    if polygons is None:
        try:
            loaded = _load_trimesh(path, report)
            polygons = _ply_polygons(loaded, path) if fmt == "ply" else None
            if polygons is None:
                verts, faces = _read_trimesh(path, report, loaded)
        except ValueError:
            if fmt != "ply":
                raise
            strips = _read_ply_strips(path)
            if strips is not None:
                verts, faces = strips
                report.notes.append(f"unrolled triangle strips into {len(faces)} triangles")
            else:
                polygons = _read_ply_binary_polygons(path)
                if polygons is None:
                    raise
    if polygons is not None:
        verts, polys = polygons
        faces = _triangulate_polygons(polys, verts, report, path)
    report.file_vertices, report.file_faces = _stated_counts(path, fmt)
    report.loaded_vertices, report.loaded_faces = len(verts), len(faces)
    finite = np.isfinite(verts).all(1)
    report.nonfinite_vertices = np.flatnonzero(~finite).tolist()
    if merge:
        keys = verts + 0.0
        bad = np.flatnonzero(~finite)
        keys[bad] = np.column_stack([np.full(len(bad), np.inf), bad, np.zeros(len(bad))])  # each apart
        _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
        order = np.argsort(first)
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        report.merged_vertices = len(verts) - len(first)
        inside = (faces >= 0) & (faces < len(verts))
        faces = np.where(inside, rank[inverse.reshape(-1)][np.where(inside, faces, 0)], faces)
        verts = verts[first[order]]
    report.num_vertices, report.num_faces = len(verts), len(faces)
    return verts, faces, report


def _triangulate_polygons(polys, verts: np.ndarray, report: MeshReport, path) -> np.ndarray:
    from .mesh.repair import triangulate

    tri, origin, tri_report = triangulate(polys, len(verts), check=False, verts=verts)
    report.triangulated_faces = tri_report.triangulated_faces
    if tri_report.fan_faces:
        report.notes.append(
            f"{len(tri_report.fan_faces)} polygons without a plane or not simple in it were split"
            f" into fans from their first corner: file faces [{_list_some(tri_report.fan_faces)}]"
        )
    report.repeated_index_faces = tri_report.repeated_index_faces
    report.degenerate_faces = len(polys) - len(np.unique(origin))
    if len(tri) == 0:
        raise ValueError(
            f"cannot read mesh {path}: no triangle faces found (every face has fewer than 3 vertices)"
        )
    return tri


def _read_off(path: Path):
    """Vertices and polygons of an ASCII OFF file, or None for another variant (binary).

    Records are read as tokens, so a record may wrap over several lines; what follows the
    last number of a record on its line (colours, normals) is skipped. ``#`` starts a
    comment. Header variants ``OFF``, ``COFF``, ``NOFF``, ``STOFF``... with the counts on
    the header line or the next.
    """
    text = path.read_bytes().decode("latin-1")
    lines = [line.split("#", 1)[0].split() for line in text.splitlines()]
    tokens = [(i, t) for i, words in enumerate(lines) for t in words]
    if (
        not tokens
        or not tokens[0][1].upper().endswith("OFF")
        or "BINARY" in {t.upper() for _, t in tokens[:3]}
    ):
        return None
    header = tokens[0][1].upper()
    pos = 1

    def number(kind):
        nonlocal pos
        if pos >= len(tokens):
            raise ValueError(f"cannot read mesh {path}: the OFF file ends inside the {kind} records")
        line, tok = tokens[pos]
        pos += 1
        return line, tok

    def skip_line(line):
        nonlocal pos
        while pos < len(tokens) and tokens[pos][0] == line:
            pos += 1

    try:
        dim = 4 if header.startswith("4") or "4OFF" in header else 3
        counts = [int(number("header")[1]) for _ in range(3)]
        nv, nf = counts[0], counts[1]
        verts = np.empty((nv, 3), dtype=np.float64)
        extras = header != "OFF"  # COFF, NOFF, STOFF...: per-vertex data after the coordinates
        for i in range(nv):
            coords = [number("vertex") for _ in range(dim)]
            verts[i] = [float(t) for _, t in coords[:3]]
            if extras:
                skip_line(coords[-1][0])
        polys = []
        for _ in range(nf):
            line, tok = number("face")
            k = int(tok)
            idx = [number("face") for _ in range(k)]
            polys.append(np.array([int(t) for _, t in idx], dtype=np.int64))
            last = idx[-1][0] if idx else line
            rest = [t for ln, t in tokens[pos : pos + 64] if ln == last]
            if rest and not _whole_records(rest):
                skip_line(last)  # a colour after the indices
    except ValueError as err:
        if "ends inside" in str(err):
            raise
        raise ValueError(f"cannot read mesh {path}: not a valid OFF file ({err})") from err
    if nf == 0:
        raise ValueError(f"cannot read mesh {path}: it is a point cloud ({nv} points, no faces)")
    return verts, polys


# An ``f`` record with at least four corners, and a line continued by a trailing backslash.
_OBJ_POLYGON = re.compile(rb"(?m)^[ \t]*f[ \t]+(?:[^\s#\\]+[ \t]+){3}[^\s#\\]")
_OBJ_CONTINUED = re.compile(rb"\\[ \t]*\r?\n")


def _read_obj_polygons(path: Path):
    """Positions and polygons of an OBJ file with a face of more than three corners, else None.

    trimesh splits such faces into fans from their first corner (wrong for a concave polygon)
    and, in files with texture coordinates or normals, gives every triangle its own corners,
    so the polygons cannot be recovered from what it returns; they are parsed here instead.
    Only ``v`` records (their first three numbers) and ``f`` records count. A corner of an
    ``f`` record is ``i``, ``i/t``, ``i/t/n`` or ``i//n``, with ``i`` counted from 1 or, when
    negative, back from the last ``v`` record before it; ``#`` starts a comment and a
    backslash at the end of a line continues the record on the next one. Objects and groups
    share the file's vertex list, so all faces are read in file order. Index ``0`` (not a
    valid OBJ index) becomes ``-1``, which :func:`load_mesh` rejects as out of range.
    """
    data = path.read_bytes()
    if not (_OBJ_POLYGON.search(data) or _OBJ_CONTINUED.search(data)):
        return None
    text = _OBJ_CONTINUED.sub(b" ", data).decode("utf-8", errors="replace")
    verts: list[list[float]] = []
    polys: list[np.ndarray] = []
    for line in text.splitlines():
        words = line.split("#", 1)[0].split()
        if not words or words[0] not in ("v", "f"):
            continue
        try:
            if words[0] == "v":
                if len(words) < 4:
                    raise ValueError("fewer than three coordinates")
                verts.append([float(w) for w in words[1:4]])
            else:
                n = len(verts)
                idx = [int(w.split("/", 1)[0]) for w in words[1:]]
                polys.append(np.array([i - 1 if i > 0 else n + i if i < 0 else -1 for i in idx], np.int64))
        except ValueError as err:
            raise ValueError(
                f"cannot read mesh {path}: not a valid OBJ file (record {line.strip()!r}: {err})"
            ) from err
    if max((len(p) for p in polys), default=0) <= 3:
        return None  # no polygon after all (a comment or a continued triangle): trimesh reads it
    return np.array(verts, dtype=np.float64).reshape(-1, 3), polys


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


def _whole_records(words: list[str]) -> bool:
    """Whether ``words`` are complete face records ``k i_1 .. i_k`` (not a colour)."""
    i = 0
    while i < len(words):
        if not words[i].isdigit():
            return False
        i += int(words[i]) + 1
    return i == len(words)


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


def _list_some(items, limit: int = 10) -> str:
    items = list(items)
    head = ", ".join(str(i) for i in items[:limit])
    return head if len(items) <= limit else f"{head}, ... ({len(items)} in all)"


def default_mesh(dtype: torch.dtype = torch.float64) -> MeshData:
    """Spot the cow (Keenan Crane, public domain), shipped with the package.

    Returns
    -------
    MeshData
        829 vertices, 1654 faces, closed genus-0 manifold.
    """
    ref = resources.files(__package__ or "torch_edgevf").joinpath("assets").joinpath(_DEFAULT_MESH)
    with resources.as_file(ref) as path:
        return load_mesh(path, dtype=dtype)


def save_mesh(path, verts, faces) -> None:
    """Write a triangle mesh to an OBJ, PLY, OFF or STL file (chosen by extension).

    OBJ and OFF are written as text with ``%.17g`` and PLY as binary float64, so
    they round-trip float64 positions exactly; STL stores float32 and one copy of
    each vertex per triangle (:func:`load_mesh` merges them back).

    Parameters
    ----------
    path : str or Path
    verts : (V, 3) tensor or array
    faces : (F, 3) integer tensor or array
    """
    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in MESH_FORMATS:
        raise ValueError(
            f"cannot save mesh {path}: unsupported extension {path.suffix!r}, expected one of {MESH_FORMATS}"
        )
    v, f = _check_mesh(verts, faces, f"cannot save mesh {path}")
    if fmt == "obj":
        _write_text(path, "", [("v %.17g %.17g %.17g", v), ("f %d %d %d", f + 1)])
    elif fmt == "off":
        _write_text(path, f"OFF\n{len(v)} {len(f)} 0\n", [("%.17g %.17g %.17g", v), ("3 %d %d %d", f)])
    elif fmt == "ply":
        header = (
            "ply\nformat binary_little_endian 1.0\n"
            f"element vertex {len(v)}\nproperty double x\nproperty double y\nproperty double z\n"
            f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
        )
        packed = np.empty(len(f), dtype=[("n", "u1"), ("idx", "<i4", (3,))])
        packed["n"], packed["idx"] = 3, f
        with open(path, "wb") as fh:
            fh.write(header.encode("ascii"))
            fh.write(v.astype("<f8").tobytes())
            fh.write(packed.tobytes())
    else:
        import trimesh

        trimesh.Trimesh(v, f, process=False).export(path, file_type="stl")


def _write_text(path: Path, header: str, blocks) -> None:
    with open(path, "w", encoding="ascii") as fh:
        fh.write(header)
        for fmt, arr in blocks:
            np.savetxt(fh, arr, fmt=fmt)


def _load_trimesh(path: Path, report: MeshReport):
    """What ``trimesh.load`` returns for the file, unprocessed; its errors as ``ValueError``."""
    import trimesh

    try:
        return trimesh.load(path, process=False)
    except (
        ValueError,
        IndexError,
        KeyError,
        TypeError,
        NameError,
        OSError,
        UnicodeDecodeError,
        EOFError,
    ) as err:
        raise ValueError(
            f"cannot read mesh {path}: the {report.format.upper()} parser failed "
            f"({type(err).__name__}: {err})"
        ) from err


def _read_trimesh(path: Path, report: MeshReport, loaded=None) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (float64) and triangles (int64) of every mesh in the file (or ``loaded``), unprocessed."""
    import trimesh

    if loaded is None:
        loaded = _load_trimesh(path, report)
    parts: list[tuple[trimesh.Trimesh, np.ndarray | None]]
    if isinstance(loaded, trimesh.Trimesh):
        parts = [(loaded, None)]
    elif isinstance(loaded, trimesh.Scene):
        parts, others = [], 0
        for node in loaded.graph.nodes_geometry:
            node_transform, name = loaded.graph[node]
            geom = loaded.geometry[name]
            if isinstance(geom, trimesh.Trimesh):
                parts.append((geom, node_transform))
            else:
                others += 1
        if others:
            report.notes.append(f"ignored {others} non-mesh geometries (points or lines)")
    elif isinstance(loaded, trimesh.PointCloud):
        raise ValueError(
            f"cannot read mesh {path}: it is a point cloud ({len(loaded.vertices)} points, no faces)"
        )
    else:
        raise ValueError(f"cannot read mesh {path}: it holds a {type(loaded).__name__}, not a triangle mesh")

    parts = [(g, t) for g, t in parts if len(g.faces)]
    if not parts:
        raise ValueError(
            f"cannot read mesh {path}: no triangle faces found "
            f"(the file is empty or not a valid {report.format.upper()} mesh)"
        )
    report.geometries = len(parts)
    verts, faces, offset = [], [], 0
    for geom, transform in parts:
        v = np.asarray(geom.vertices, dtype=np.float64)
        f = np.asarray(geom.faces, dtype=np.int64)
        if transform is not None and not np.array_equal(transform, np.eye(4)):
            v = v @ transform[:3, :3].T + transform[:3, 3]
            report.notes.append("applied a scene transform to a geometry")
            if np.linalg.det(transform[:3, :3]) < 0:
                f = f[:, ::-1]
                report.notes.append(
                    "a transform was a reflection: reversed that geometry's faces to keep its winding"
                )
        verts.append(v)
        faces.append(f + offset)
        offset += len(v)
    if len(parts) > 1:
        report.notes.append(f"concatenated {len(parts)} geometries; face order may differ from the file")
    return np.concatenate(verts), np.ascontiguousarray(np.concatenate(faces))


def _check_stl(path: Path) -> None:
    """Reject a file that is neither a complete binary STL nor text starting with ``solid``.

    (trimesh would try to decode such bytes as text and fail with unrelated errors.)
    """
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(84)
    count = int.from_bytes(head[80:84], "little") if len(head) == 84 else -1
    if size != 84 + 50 * count and not head.lstrip().lower().startswith(b"solid"):
        raise ValueError(
            f"cannot read mesh {path}: not an STL file (binary STL with {count} triangles needs"
            f" {84 + 50 * count} bytes, the file has {size}; ASCII STL starts with 'solid')"
        )


def _stated_counts(path: Path, fmt: str) -> tuple[int | None, int | None]:
    """Vertex and face record counts the file states (best effort, ``None`` if unknown)."""
    if fmt == "obj":
        data = path.read_bytes()
        return len(re.findall(rb"(?m)^[ \t]*v[ \t]", data)), len(re.findall(rb"(?m)^[ \t]*f[ \t]", data))
    with open(path, "rb") as fh:
        head = fh.read(1 << 16).decode("latin-1")
    if fmt == "ply":
        head = head.split("end_header", 1)[0]
        counts = {k: int(c) for k, c in re.findall(r"(?m)^element\s+(\w+)\s+(\d+)", head)}
        return counts.get("vertex"), counts.get("face")
    if fmt == "off":
        tokens = " ".join(line.split("#", 1)[0] for line in head.splitlines()).split()
        if len(tokens) >= 3 and tokens[0].endswith("OFF") and tokens[1].isdigit() and tokens[2].isdigit():
            return int(tokens[1]), int(tokens[2])
    return None, None


def _merge_identical(verts: np.ndarray, faces: np.ndarray, report: MeshReport):
    """Merge vertices with bitwise-equal positions (``-0.0 == 0.0``), first occurrence first."""
    _, first, inverse = np.unique(verts + 0.0, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    report.merged_vertices = len(verts) - len(first)
    return verts[first[order]], rank[inverse.reshape(-1)][faces]


def _drop_bad_faces(faces: np.ndarray, report: MeshReport) -> np.ndarray:
    """Drop faces with a repeated index, then repeated vertex triples (keep the first)."""
    ok = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])
    report.degenerate_faces += int((~ok).sum())
    if not ok.all() and not report.repeated_index_faces:
        report.repeated_index_faces = np.flatnonzero(~ok).tolist()
    faces = faces[ok]
    _, first = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    report.duplicate_faces = len(faces) - len(first)
    if report.duplicate_faces:
        faces = faces[np.sort(first)]
    return faces


def _drop_unreferenced(verts: np.ndarray, faces: np.ndarray, report: MeshReport):
    used = np.zeros(len(verts), dtype=bool)
    used[faces] = True
    report.unreferenced_vertices = int((~used).sum())
    if report.unreferenced_vertices == 0:
        return verts, faces
    new_index = np.cumsum(used) - 1
    return verts[used], new_index[faces]


def _check_mesh(verts, faces, where: str) -> tuple[np.ndarray, np.ndarray]:
    """``verts`` as (V, 3) float64 and ``faces`` as (F, 3) int64 numpy arrays, or ``ValueError``."""
    v = verts.detach().cpu().numpy() if isinstance(verts, torch.Tensor) else np.asarray(verts)
    f = faces.detach().cpu().numpy() if isinstance(faces, torch.Tensor) else np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or not np.issubdtype(v.dtype, np.floating):
        raise ValueError(
            f"{where}: verts must be a (V, 3) float array, got shape {v.shape} and dtype {v.dtype}"
        )
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise ValueError(
            f"{where}: faces must be a (F, 3) integer array, got shape {f.shape} and dtype {f.dtype}"
        )
    if len(f) == 0:
        raise ValueError(f"{where}: the mesh has no faces")
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError(f"{where}: face indices must lie in [0, {len(v)}), got [{f.min()}, {f.max()}]")
    return np.ascontiguousarray(v, dtype=np.float64), np.ascontiguousarray(f, dtype=np.int64)


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
    verts : (V, 3) float64 tensor
    faces : (F, 3) int64 tensor
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
