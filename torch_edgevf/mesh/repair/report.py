"""The report of :func:`repair`: every change, with the input indices of the elements."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..._validation import list_some
from ..topology import Topology


@dataclass
class RepairReport:
    """Every change :func:`repair` made, with the indices of the elements (input indices).

    Attributes
    ----------
    input_vertices, input_faces : counts of the input (faces are polygons)
    num_vertices, num_faces, num_edges : counts of the repaired mesh
    triangulated_faces : input polygons with more than three corners, split into triangles
    added_triangles : how many triangles more than polygons that made
    fan_faces : polygons of those that were split into fans from their first corner because
        they have no plane (zero area) or are not simple in it (see :func:`triangulate`)
    repeated_index_faces : input faces with a repeated vertex index (the repeats removed;
        what is left of fewer than three vertices is dropped)
    nonfinite_vertices : vertices with NaN or Inf coordinates (their faces are dropped)
    coincident_vertices : ``(i, j)`` pairs, ``i < j``, of distinct referenced vertices at one
        position (within ``tol``, see
        :func:`~torch_edgevf.mesh.diagnose.find_coincident_vertices`); found always, merged
        only with ``merge_coincident=True``
    merged_vertices : ``{input vertex: the input vertex it was merged into}`` (the lowest
        index of its cluster of coincident vertices), with ``merge_coincident=True``
    collapsed_faces : input faces with a triangle that merging left with a repeated vertex
        (that triangle is dropped)
    t_junctions : ``(vertex, a, b, face)``: the input vertex ``vertex`` lies inside the
        boundary edge ``(a, b)``, ``a < b``, of input face ``face`` (see
        :func:`~torch_edgevf.mesh.diagnose.find_t_junctions`; after merging, if asked);
        found always, split only with ``split_t_junctions=True``
    split_faces : input faces whose triangle was split at T-junction vertices, with
        ``split_t_junctions=True``
    t_junction_triangles : how many triangles those splits added
    duplicate_faces : ``(face, first)`` pairs, ``face`` has the vertices of ``first``
        (any order or winding) and is dropped
    dropped_faces : ``{input face: reason}`` for every input face of which no triangle is
        left (each is also in one of the lists above)
    flipped_faces : input faces whose winding was reversed (the minority of their sheet)
    non_manifold_edges : input vertex pairs shared by more than two faces; cut, each face
        then has its own copy of the edge (a boundary edge)
    non_manifold_vertices : input vertices whose faces form several fans (bowties), split
    split_vertices : ``{input vertex: copies}`` for every vertex that was split (bowties
        and the ends of cut edges)
    unreferenced_vertices : input vertices that no kept face uses (dropped)
    flipped_caps : input faces that were zero-area caps (a corner on the opposite edge),
        re-triangulated with the face across their longest edge by an edge flip
    mollified_faces : faces of the repaired mesh without the triangle-inequality margin
        (zero-area faces, needles); their input faces are ``face_origin[mollified_faces]``
    epsilon, delta : the length added to every edge and the margin (see :func:`mollify_lengths`)
    components : per component of the repaired mesh, a dict of its counts
    """

    input_vertices: int = 0
    input_faces: int = 0
    num_vertices: int = 0
    num_faces: int = 0
    num_edges: int = 0
    triangulated_faces: list[int] = field(default_factory=list)
    added_triangles: int = 0
    fan_faces: list[int] = field(default_factory=list)
    repeated_index_faces: list[int] = field(default_factory=list)
    nonfinite_vertices: list[int] = field(default_factory=list)
    coincident_vertices: list[tuple[int, int]] = field(default_factory=list)
    merged_vertices: dict[int, int] = field(default_factory=dict)
    collapsed_faces: list[int] = field(default_factory=list)
    t_junctions: list[tuple[int, int, int, int]] = field(default_factory=list)
    split_faces: list[int] = field(default_factory=list)
    t_junction_triangles: int = 0
    duplicate_faces: list[tuple[int, int]] = field(default_factory=list)
    dropped_faces: dict[int, str] = field(default_factory=dict)
    flipped_faces: list[int] = field(default_factory=list)
    non_manifold_edges: list[tuple[int, int]] = field(default_factory=list)
    non_manifold_vertices: list[int] = field(default_factory=list)
    split_vertices: dict[int, int] = field(default_factory=dict)
    unreferenced_vertices: list[int] = field(default_factory=list)
    flipped_caps: list[int] = field(default_factory=list)
    mollified_faces: list[int] = field(default_factory=list)
    epsilon: float = 0.0
    delta: float = 0.0
    components: list[dict] = field(default_factory=list)

    @property
    def changed(self) -> bool:
        """Whether anything was changed (other than nothing)."""
        return bool(self.changes())

    @property
    def cracks(self) -> bool:
        """Whether coincident vertices or T-junctions were found (merged, split or not)."""
        return bool(self.coincident_vertices or self.t_junctions)

    def changes(self) -> dict[str, int]:
        """``{kind of change: count}`` for every kind that occurred."""
        counts = {
            "triangulated polygons": len(self.triangulated_faces),
            "polygons split into fans": len(self.fan_faces),
            "faces with repeated indices": len(self.repeated_index_faces),
            "non-finite vertices": len(self.nonfinite_vertices),
            "coincident vertices merged": len(self.merged_vertices),
            "faces collapsed by merging": len(self.collapsed_faces),
            "faces split at T-junctions": len(self.split_faces),
            "duplicate faces": len(self.duplicate_faces),
            "dropped faces": len(self.dropped_faces),
            "flipped faces": len(self.flipped_faces),
            "non-manifold edges cut": len(self.non_manifold_edges),
            "non-manifold vertices split": len(self.non_manifold_vertices),
            "vertices split": len(self.split_vertices),
            "unreferenced vertices": len(self.unreferenced_vertices),
            "zero-area caps flipped": len(self.flipped_caps),
            "mollified faces": len(self.mollified_faces),
        }
        return {k: v for k, v in counts.items() if v}

    def summary(self) -> str:
        """A readable account of the changes, with (some of) the element indices."""
        lines = [
            f"repair: {self.input_vertices} vertices, {self.input_faces} faces in; "
            f"{self.num_vertices} vertices, {self.num_faces} triangles, {self.num_edges} edges out"
        ]

        def add(items, what):
            if items:
                lines.append(f"  {what}: {len(items)} [{list_some(list(items))}]")

        add(self.triangulated_faces, f"polygons triangulated (+{self.added_triangles} triangles), faces")
        add(
            self.fan_faces,
            "polygons without a plane or not simple in it, split into fans from their first corner, faces",
        )
        add(self.repeated_index_faces, "faces with a repeated vertex index (repeats removed), faces")
        add(self.nonfinite_vertices, "vertices with NaN or Inf coordinates (their faces dropped)")
        if self.merged_vertices:
            add(
                [f"{a} -> {b}" for a, b in self.merged_vertices.items()],
                f"coincident vertices merged ({len(self.coincident_vertices)} pairs found)",
            )
        else:
            add(
                self.coincident_vertices,
                "coincident vertex pairs found, not merged "
                "(merge_coincident=True or --merge-coincident merges them)",
            )
        add(self.collapsed_faces, "faces with a triangle collapsed by the merge (dropped)")
        if self.split_faces:
            split = f"(+{self.t_junction_triangles} triangles)"
            add(
                self.split_faces, f"faces split at {len(self.t_junctions)} T-junction vertices {split}, faces"
            )
        else:
            add(
                [f"{w} in ({a}, {b}) of face {f}" for w, a, b, f in self.t_junctions],
                "T-junctions found, not split (split_t_junctions=True or --split-t-junctions splits them)",
            )
        add([f"{a} (= {b})" for a, b in self.duplicate_faces], "duplicate faces dropped")
        if self.dropped_faces:
            reasons: dict[str, list[int]] = {}
            for f, why in self.dropped_faces.items():
                reasons.setdefault(why, []).append(f)
            for why, fs in reasons.items():
                add(fs, f"faces dropped ({why})")
        add(self.flipped_faces, "faces flipped to the orientation of their sheet")
        add(self.non_manifold_edges, "non-manifold edges cut into manifold sheets, vertex pairs")
        add(self.non_manifold_vertices, "non-manifold vertices split into one vertex per fan")
        if self.split_vertices:
            extra = sum(self.split_vertices.values()) - len(self.split_vertices)
            add(list(self.split_vertices), f"vertices split (+{extra} copies)")
        add(self.unreferenced_vertices, "unreferenced vertices dropped")
        add(
            self.flipped_caps,
            "zero-area caps re-triangulated with their neighbour by an edge flip (no vertex moved), faces",
        )
        if self.mollified_faces:
            margin = f"the triangle-inequality margin {self.delta:.3g}"
            lengths = f"every edge length +{self.epsilon:.3g} (intrinsic mollification, no vertex moved)"
            add(self.mollified_faces, f"faces without {margin}: {lengths}, repaired faces")
        if len(lines) == 1:
            lines.append("  nothing to repair")
        if self.components:
            chis: dict[int, int] = {}
            for c in self.components:
                chis[c["euler"]] = chis.get(c["euler"], 0) + 1
            boundary = sum(c["boundary_edges"] for c in self.components)
            lines.append(
                f"  {len(self.components)} components, Euler characteristics "
                + ", ".join(f"{chi} (x{m})" for chi, m in sorted(chis.items(), reverse=True))
                + f"; {boundary} boundary edges"
            )
            for k, c in enumerate(self.components):
                if c["flipped"] or c["mollified"]:
                    lines.append(
                        f"  component {k}: {c['faces']} faces, Euler characteristic {c['euler']}, "
                        f"{c['boundary_edges']} boundary edges, {c['flipped']} flipped, "
                        f"{c['mollified']} mollified"
                    )
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


def _component_counts(topo: Topology, flipped: np.ndarray, mollified: np.ndarray) -> list[dict]:
    labels = topo.components.numpy()
    face_label = labels[topo.faces.numpy()[:, 0]]
    nc = topo.num_components
    faces = np.bincount(face_label, minlength=nc)
    verts = np.bincount(labels[labels >= 0], minlength=nc)
    e = topo.edges.numpy()
    edge_label = labels[e[:, 0]]
    edges = np.bincount(edge_label, minlength=nc)
    boundary = np.bincount(edge_label[topo.boundary_edges.numpy()], minlength=nc)
    flips = np.bincount(face_label[flipped], minlength=nc)
    moll = np.bincount(face_label[mollified], minlength=nc) if len(mollified) else np.zeros(nc, int)
    return [
        {
            "faces": int(faces[c]),
            "euler": int(verts[c] - edges[c] + faces[c]),
            "boundary_edges": int(boundary[c]),
            "flipped": int(flips[c]),
            "mollified": int(moll[c]),
        }
        for c in range(nc)
    ]
