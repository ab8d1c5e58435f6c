"""What :func:`~torch_edgevf.io.load_mesh` read and changed, and the mesh it returns."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

# ----------------------------------------------------------------------------- meshes


@dataclass
class MeshReport:
    """What :func:`load_mesh` read and changed.

    ``file_vertices`` / ``file_faces`` are the record counts stated by the file
    (``None`` where the format does not state them, e.g. STL); ``loaded_*`` are
    what the reader returned (the file's vertex records and triangles, polygons split;
    for STL, trimesh's three vertices per triangle); the other counts are the changes
    made afterwards.

    ``merged_vertices`` counts the vertices merged into another at the same position
    because the merge joined two boundary edges into one manifold edge
    (``joined_edges`` pairs); ``left_apart`` lists the vertices left apart at a position
    that another vertex also takes (file indices). ``vertex_map`` (not printed) gives, for
    every loaded vertex, its index in the returned mesh, ``-1`` when it was dropped (no
    face uses it).
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
    joined_edges: int = 0
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
    #: vertices (file indices) at a position that another vertex takes, not merged with it
    left_apart: list[int] = field(default_factory=list)
    #: (loaded vertices,) int64: the index of each vertex in the returned mesh, -1 if dropped
    vertex_map: np.ndarray | None = field(default=None, repr=False, compare=False)

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
        joined = f" (joining {self.joined_edges} pairs of boundary edges)" if self.joined_edges else ""
        lines.append(
            f"  merged {self.merged_vertices} vertices with identical positions{joined};"
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
    verts, faces : the ``(V, 3)`` float positions and the ``(F, 3)`` int64 triangles
    report : MeshReport
    vertex_map : (V_file,) int64 tensor, for every vertex record of the file its vertex in
        ``verts``, ``-1`` for a vertex no face uses (dropped); merged vertices share one
    vertex_origin : (V,) int64 tensor, for every vertex the first vertex record of the file
        it stands for (``vertex_map[vertex_origin]`` is ``arange(V)``)

    Per-vertex data of the file (labels, colours) follow the mesh as
    ``data[vertex_origin]``; values computed on the mesh go back to the file's vertices as
    ``values[vertex_map]`` where ``vertex_map >= 0``.
    """

    verts: torch.Tensor
    faces: torch.Tensor
    report: MeshReport
    vertex_map: torch.Tensor
    vertex_origin: torch.Tensor

    def __iter__(self):
        """Allow ``verts, faces = load_mesh(path)``."""
        return iter((self.verts, self.faces))


def _list_some(items, limit: int = 10) -> str:
    items = list(items)
    head = ", ".join(str(i) for i in items[:limit])
    return head if len(items) <= limit else f"{head}, ... ({len(items)} in all)"
