"""Mesh diagnosis: every problem found, with its location, instead of the first error."""

from __future__ import annotations

from dataclasses import dataclass, field

from .._validation import as_faces, as_verts
from .geometry import face_geometry
from .topology import Topology


@dataclass
class Diagnosis:
    """Topology summary (when it could be built) and the list of problems found."""

    summary: dict | None = None
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    def __str__(self) -> str:
        lines = []
        if self.summary:
            lines += [f"{k.replace('_', ' ')}: {v}" for k, v in self.summary.items()]
        lines += ["no problems found"] if self.ok else [f"problem: {p}" for p in self.problems]
        return "\n".join(lines)


def diagnose(verts, faces) -> Diagnosis:
    """Run every check of the library on a mesh and collect the problems (never raises)."""
    out = Diagnosis()
    try:
        faces = as_faces(faces)
    except ValueError as exc:
        out.problems.append(str(exc))
        return out
    try:
        verts = as_verts(verts)
    except ValueError as exc:
        out.problems.append(str(exc))
        verts = None
    try:
        topo = Topology(faces, num_vertices=None if verts is None else verts.shape[0])
        out.summary = topo.summary()
        if topo.unreferenced_vertices.numel():
            n = topo.unreferenced_vertices.numel()
            out.problems.append(f"{n} unreferenced vertices (kept, with zero rows in vertex operators)")
    except ValueError as exc:
        out.problems.append(str(exc))
    if verts is not None:
        try:
            face_geometry(verts, faces)
        except ValueError as exc:
            out.problems.append(str(exc))
    return out
