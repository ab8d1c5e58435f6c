"""OBJ, PLY and STL files through trimesh (unprocessed), scenes concatenated."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .report import MeshReport


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
