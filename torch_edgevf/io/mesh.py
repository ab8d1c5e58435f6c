"""Mesh files: :func:`load_mesh`, :func:`read_triangles`, :func:`save_mesh` and the shipped mesh."""

from __future__ import annotations

import logging
import re
from importlib import resources
from pathlib import Path

import numpy as np
import torch

from .._validation import check_float_dtype, check_positions_dtype, single_mesh
from .merge import face_keys, has_repeats, join_cracks
from .obj import _read_obj
from .off import _read_off
from .ply import _ply_polygons, _read_ply, _read_ply_binary_polygons, _read_ply_strips
from .report import MeshData, MeshReport, _list_some
from .trimesh_reader import _check_stl, _load_trimesh, _read_trimesh

log = logging.getLogger(__name__)


MESH_FORMATS = ("obj", "ply", "off", "stl")
_DEFAULT_MESH = "spot_low_resolution.obj"


def load_mesh(path, dtype: torch.dtype = torch.float64, merge: bool = True) -> MeshData:
    """Read a triangle mesh from an OBJ, PLY, OFF or STL file.

    Parameters
    ----------
    path : str or Path
    dtype : torch dtype of the returned vertices, ``torch.float64`` or ``torch.float32``
        (the file is parsed in float64; float32 rounds)
    merge : merge vertices at identical positions where the merge joins two boundary
        edges into one manifold edge (a crack of zero width; see the module docstring).
        Degenerate and duplicate faces and unreferenced vertices are dropped either way.

    Returns
    -------
    MeshData
        ``verts (V, 3)``, ``faces (F, 3)`` int64, the :class:`MeshReport` (also logged:
        INFO, or WARNING when faces were dropped or polygons split), and the maps between
        the file's vertices and the mesh's: ``vertex_map`` (for every vertex record of the
        file, its vertex in the mesh, ``-1`` if dropped) and ``vertex_origin`` (for every
        vertex of the mesh, the first vertex record of the file that it stands for).

    Raises
    ------
    ValueError
        The file is missing, has an unsupported extension, cannot be parsed, holds
        no triangles (empty, point cloud, lines), or has invalid data; ``dtype`` is not
        float32 or float64.
    """
    path = Path(path)
    check_float_dtype(dtype, "load_mesh: dtype")
    verts, faces, report = read_triangles(path)  # checks the extension and the file
    if report.nonfinite_vertices:
        bad = report.nonfinite_vertices
        raise ValueError(
            f"cannot read mesh {path}: {len(bad)} vertices are not finite (NaN or Inf coordinates),"
            f" at vertices [{_list_some(bad)}] (edgevf info lists every problem; repair drops their faces)"
        )
    if faces.size and (faces.min() < 0 or faces.max() >= len(verts)):
        out = np.flatnonzero(((faces < 0) | (faces >= len(verts))).any(1)).tolist()
        raise ValueError(
            f"cannot read mesh {path}: a face index outside [0, {len(verts)}) at faces [{_list_some(out)}]"
        )
    faces = _drop_bad_faces(faces, report)
    if len(faces) == 0:
        raise ValueError(f"cannot read mesh {path}: no faces left after dropping degenerate faces")
    used = np.zeros(len(verts), dtype=bool)
    used[faces] = True
    merged_to = None
    if merge:
        result = join_cracks(verts, faces, used, finite=True)
        _record_merge(result, report)
        if result.merged_vertices:
            merged_to = result.merged_to
    verts, faces, vertex_map, origin = _drop_unreferenced(verts, faces, report, used, merged_to)
    report.num_vertices, report.num_faces = len(verts), len(faces)
    stated = report.file_vertices
    if stated is not None and stated > report.loaded_vertices:
        report.notes.append(
            f"the file states {stated} vertices but holds {report.loaded_vertices} vertex records"
        )

    level = (
        logging.WARNING if report.dropped_faces or report.triangulated or report.problems else logging.INFO
    )
    if log.isEnabledFor(level):
        log.log(level, "%s", report)
    return MeshData(
        torch.from_numpy(verts).to(dtype),
        torch.from_numpy(faces),
        report,
        vertex_map=torch.from_numpy(vertex_map),
        vertex_origin=torch.from_numpy(origin),
    )


def read_triangles(path, merge: bool = False) -> tuple[np.ndarray, np.ndarray, MeshReport]:
    """The vertices and triangles of a mesh file as they are, before any clean-up.

    Nothing is checked, merged or dropped: NaN coordinates, indices out of range,
    duplicates and non-manifold configurations come back as the file holds them (for
    :func:`~torch_edgevf.mesh.repair.repair` and ``edgevf info``), and the vertices are
    the file's vertex records, in order (for STL, through trimesh: three per triangle).
    The polygons of OFF, OBJ and PLY files are triangulated in their planes by
    :func:`~torch_edgevf.mesh.repair.triangulate` (convex ones as fans from their first
    corner, others by ear clipping) after their repeated vertex indices are removed (both
    recorded in the report, with the file's face indices); files whose faces are all
    triangles are read as they are. Triangle strips of PLY files are unrolled.

    With ``merge``, vertices at identical finite positions are merged where the merge
    joins a surface, as by :func:`load_mesh` (among the faces with indices in range and
    three distinct vertices); ``report.vertex_map`` then gives the returned vertex of
    every vertex record.

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
    verts, faces = _read_file(path, fmt, report)
    if not (isinstance(faces, np.ndarray) and faces.ndim == 2 and faces.shape[1] == 3):
        faces = _triangulate_polygons(faces, verts, report, path)
    report.loaded_vertices, report.loaded_faces = len(verts), len(faces)
    finite = None
    if not np.isfinite(verts.sum()):  # NaN and Inf reach the sum (as does an overflow: checked)
        finite = np.isfinite(verts).all(1)
        report.nonfinite_vertices = np.flatnonzero(~finite).tolist()
    if merge:
        inside = ((faces >= 0) & (faces < len(verts))).all(1)
        ok = np.flatnonzero(inside)
        if finite is not None:
            ok = ok[finite[faces[ok]].all(1)]
        valid = faces[ok]
        distinct = (valid[:, 0] != valid[:, 1]) & (valid[:, 1] != valid[:, 2]) & (valid[:, 2] != valid[:, 0])
        valid = valid[distinct]
        if len(valid):
            _, first = np.unique(face_keys(valid, len(verts)), return_index=True)
            valid = valid[np.sort(first)]
        result = join_cracks(verts, valid)
        _record_merge(result, report)
        merged_to = result.merged_to
        keep = merged_to == np.arange(len(verts))
        new_index = np.cumsum(keep) - 1
        report.vertex_map = new_index[merged_to]
        faces = np.where(inside[:, None], report.vertex_map[np.where(inside[:, None], faces, 0)], faces)
        verts = verts[keep]
    report.num_vertices, report.num_faces = len(verts), len(faces)
    return verts, faces, report


def _read_file(path: Path, fmt: str, report: MeshReport):
    """Positions and faces (triangles, or polygons to triangulate) of a file; fills the stated counts."""
    if fmt == "stl":
        _check_stl(path)
    elif fmt == "off":
        read = _read_off(path)
        if read is not None:
            report.file_vertices, report.file_faces = len(read[0]), len(read[1])
            return read
    elif fmt == "obj":
        verts, faces, report.file_vertices, report.file_faces = _read_obj(path)
        return verts, faces
    else:
        read = _read_ply(path)
        if read is not None:
            verts, faces, report.file_vertices, report.file_faces = read
            return verts, faces
        report.file_vertices, report.file_faces = _ply_counts(path)
    try:
        loaded = _load_trimesh(path, report)
        polygons = _ply_polygons(loaded, path) if fmt == "ply" else None
        if polygons is not None:
            return polygons
        return _read_trimesh(path, report, loaded)
    except ValueError:
        if fmt != "ply":
            raise
        strips = _read_ply_strips(path)
        if strips is not None:
            report.notes.append(f"unrolled triangle strips into {len(strips[1])} triangles")
            return strips
        polygons = _read_ply_binary_polygons(path)
        if polygons is None:
            raise
        return polygons


def _triangulate_polygons(polys, verts: np.ndarray, report: MeshReport, path) -> np.ndarray:
    from ..mesh.repair import triangulate

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


def default_mesh(dtype: torch.dtype = torch.float64) -> MeshData:
    """Spot the cow (Keenan Crane, public domain), shipped with the package.

    Returns
    -------
    MeshData
        829 vertices, 1654 faces, closed genus-0 manifold.
    """
    ref = resources.files("torch_edgevf").joinpath("assets").joinpath(_DEFAULT_MESH)
    with resources.as_file(ref) as path:
        return load_mesh(path, dtype=dtype)


def save_mesh(path, verts, faces=None) -> None:
    """Write a triangle mesh to an OBJ, PLY, OFF or STL file (chosen by extension).

    OBJ and OFF are written as text with ``%.17g`` and PLY as binary float64, so
    they round-trip float64 positions exactly; STL stores float32 and one copy of
    each vertex per triangle (:func:`load_mesh` merges them back).

    Parameters
    ----------
    path : str or Path
    verts : (V, 3) tensor or array, or a batch of one mesh with ``verts_list()`` and
        ``faces_list()`` (a ``pytorch3d.structures.Meshes``; ``faces`` left out)
    faces : (F, 3) integer tensor or array
    """
    path = Path(path)
    verts, faces = single_mesh(verts, faces, "save_mesh")
    if faces is None:
        raise ValueError(f"cannot save mesh {path}: faces are needed with verts")
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


def _ply_counts(path: Path) -> tuple[int | None, int | None]:
    """The vertex and face counts a PLY header states (``None`` if unknown)."""
    with open(path, "rb") as fh:
        head = fh.read(1 << 16).decode("latin-1").split("end_header", 1)[0]
    counts = {k: int(c) for k, c in re.findall(r"(?m)^element\s+(\w+)\s+(\d+)", head)}
    return counts.get("vertex"), counts.get("face")


def _record_merge(result, report: MeshReport) -> None:
    report.merged_vertices = result.merged_vertices
    report.joined_edges = result.joined_edges
    report.left_apart = result.left_apart
    if result.left_apart:
        why = ["no boundary edge of theirs meets another at the same positions (surfaces touching)"]
        if result.ambiguous_edges:
            why.append(f"{result.ambiguous_edges} boundary edges lie three or more at one pair of positions")
        if result.undone_joins:
            why.append(
                f"{result.undone_joins} joins would make a non-manifold edge or a collapsed or duplicate face"
            )
        report.notes.append(
            f"left {len(result.left_apart)} vertices apart at positions that other vertices also take"
            f" ({'; or '.join(why)}): file vertices [{_list_some(result.left_apart)}]"
        )


def _drop_bad_faces(faces: np.ndarray, report: MeshReport) -> np.ndarray:
    """Drop faces with a repeated index, then repeated vertex triples (keep the first)."""
    a, b, c = np.ascontiguousarray(faces.T)
    ok = (a != b) & (b != c) & (c != a)
    if not ok.all():
        report.degenerate_faces += int((~ok).sum())
        if not report.repeated_index_faces:
            report.repeated_index_faces = np.flatnonzero(~ok).tolist()
        faces = faces[ok]
    keys = face_keys(faces, int(faces.max()) + 1 if len(faces) else 0)
    if keys.dtype.kind == "V" or has_repeats(keys):
        _, first = np.unique(keys, return_index=True)
        report.duplicate_faces = len(faces) - len(first)
        if report.duplicate_faces:
            faces = faces[np.sort(first)]
    return faces


def _drop_unreferenced(verts, faces, report: MeshReport, used: np.ndarray, merged_to=None):
    """The kept vertices and the faces renumbered, with the maps file vertex -> mesh vertex
    (``-1``: dropped) and mesh vertex -> first file vertex.

    ``used`` marks the vertices of ``faces``; ``merged_to`` maps each to the lowest index
    of the vertices merged with it (None: no merge).
    """
    nv = len(verts)
    report.unreferenced_vertices = int(nv - used.sum())
    if merged_to is None and report.unreferenced_vertices == 0:
        identity = np.arange(nv, dtype=np.int64)
        report.vertex_map = identity
        return verts, faces, identity, identity.copy()
    keep = used if merged_to is None else used & (merged_to == np.arange(nv))
    new_index = np.cumsum(keep) - 1
    target = new_index if merged_to is None else new_index[merged_to]
    faces = target[faces]
    if report.unreferenced_vertices:
        target[~used] = -1
    report.vertex_map = target
    return verts[keep], faces, target, np.flatnonzero(keep)


def _check_mesh(verts, faces, where: str) -> tuple[np.ndarray, np.ndarray]:
    """``verts`` as (V, 3) float64 and ``faces`` as (F, 3) int64 numpy arrays, or ``ValueError``."""
    if isinstance(verts, torch.Tensor) and verts.is_floating_point() or isinstance(verts, np.ndarray):
        try:
            check_positions_dtype(verts)
        except ValueError as err:
            raise ValueError(f"{where}: {err}") from None
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
