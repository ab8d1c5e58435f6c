"""Mesh repair: triangle soups made into meshes the operators accept, every change reported.

:func:`repair` takes vertex positions and polygons as they come from a file and returns a
:class:`RepairResult`: a manifold, consistently oriented triangle mesh, maps from its
vertices and faces to the input ones, edge lengths that are valid even where faces have
zero area (intrinsic mollification), and a :class:`RepairReport` that names every
element that was changed. No vertex is ever moved; the input is never modified.

Zero-width cracks (coincident vertices, where a vertex was split at one position, and
T-junctions; see :mod:`~torch_edgevf.mesh.diagnose`) are valid boundaries to the
topology: :func:`repair` always reports them and closes them only when asked
(``merge_coincident=True``, ``split_t_junctions=True``), since either changes the
topology the input describes.

:func:`repair_degenerate_faces` is the older, extrinsic alternative for closed manifold
meshes: it removes zero-area faces by edge collapse.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import torch
from scipy.sparse.csgraph import breadth_first_order, connected_components

from .._validation import face_range_message, list_some
from .diagnose import COINCIDENT_TOL, _check_tol, _coincident_pairs, _t_junctions
from .geometry import FaceGeometry
from .topology import Topology

log = logging.getLogger(__name__)

__all__ = [
    "RepairReport",
    "RepairResult",
    "MappedEdgeField",
    "repair",
    "mollify_lengths",
    "triangulate",
    "find_degenerate_faces",
    "repair_degenerate_faces",
]


def find_degenerate_faces(verts, faces) -> np.ndarray:
    """Indices of the faces that the operators reject as zero-area (same criterion, float64)."""
    v = np.asarray(verts, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    p = v[f]
    e = p[:, [2, 0, 1]] - p[:, [1, 2, 0]]
    lmax = np.linalg.norm(e, axis=2).max(1)
    double_area = np.linalg.norm(np.cross(e[:, 0], e[:, 1]), axis=1)
    return np.nonzero(double_area <= 8 * np.finfo(np.float64).eps * lmax * lmax)[0]


def repair_degenerate_faces(verts, faces) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int]]:
    """Repair zero-area faces of a closed manifold mesh by collapsing one of their short edges.

    Procedure, for each zero-area face in turn: its edges, shortest first, are tried as
    an edge collapse ``u -> w``, both directions for each edge. A collapse moves no
    vertex: ``u`` is removed, every face using ``u`` uses ``w`` instead, and the
    two faces sharing the edge ``uw`` (the degenerate face and its neighbour) are
    deleted. A collapse is accepted only if the link condition holds (``u`` and ``w``
    share exactly two neighbours), no face becomes degenerate and the result is still a
    valid :class:`~torch_edgevf.mesh.topology.Topology` (manifold, oriented); otherwise the
    next edge is tried, and ``ValueError`` is raised when none works. The Euler
    characteristic is unchanged (one vertex, three edges and two faces fewer).

    Returns
    -------
    verts : (V', 3) array, the kept vertices (a copy)
    faces : (F', 3) int64 array, reindexed
    kept : (V',) int64 array, original index of each kept vertex (to carry per-vertex data)
    repaired : list of the original indices of the repaired faces
    """
    v = np.asarray(verts)
    f = np.array(faces, dtype=np.int64)
    orig_face = np.arange(len(f))
    kept = np.arange(len(v))
    repaired = []
    while True:
        bad = find_degenerate_faces(v, f)
        if len(bad) == 0:
            break
        t = int(bad[0])
        original = int(orig_face[t])
        p = v[f[t]].astype(np.float64)
        lengths = np.linalg.norm(p[[2, 0, 1]] - p[[1, 2, 0]], axis=1)  # opposite each corner
        done = False
        for k in np.argsort(lengths):  # edge opposite corner k: (f[t, k+1], f[t, k+2])
            e0, e1 = int(f[t, (k + 1) % 3]), int(f[t, (k + 2) % 3])
            for u, w in ((e0, e1), (e1, e0)):
                g = _collapse(v, f, u, w)
                if g is not None:
                    f = g[0]
                    orig_face = orig_face[g[1]]
                    done = True
                    break
            if done:
                break
        if not done:
            raise ValueError(f"cannot repair the zero-area face {original}: no valid edge collapse")
        repaired.append(original)
    used = np.unique(f)
    remap = np.full(len(v), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return np.array(v[used]), remap[f], kept[used], repaired


def _collapse(v: np.ndarray, f: np.ndarray, u: int, w: int):
    """Faces after collapsing vertex ``u`` into ``w`` (positions unchanged), or None if invalid."""

    def neighbours(x):
        rows = f[(f == x).any(1)]
        return set(rows.ravel().tolist()) - {x}

    if len(neighbours(u) & neighbours(w)) != 2:
        return None
    keep = ~((f == u).any(1) & (f == w).any(1))
    g = np.where(f == u, w, f)[keep]
    if len(find_degenerate_faces(v, g)):
        return None
    try:
        Topology(torch.from_numpy(g), num_vertices=len(v))
    except ValueError:
        return None
    return g, np.nonzero(keep)[0]


# --------------------------------------------------------------------------- soups

#: Margin of :func:`mollify_lengths` relative to the mean edge length (robust_laplacian's
#: default ``mollify_factor``).
MOLLIFY_FACTOR = 1e-5


def mollify_lengths(lengths: torch.Tensor, face_edges, factor: float = MOLLIFY_FACTOR):
    """Intrinsic mollification of edge lengths (Sharp and Crane 2020, section 4.5).

    Every length is increased by the same smallest ``epsilon >= 0`` that makes each
    triangle satisfy the triangle inequality strictly, with the margin ``delta``:

    .. math::  \\delta = \\text{factor}\\,\\bar l, \\qquad
               \\epsilon = \\max\\Big(0, \\max_{f, k}\\, \\delta - (l_{k+1} + l_{k+2} - l_k)\\Big),
               \\qquad \\tilde l = l + \\epsilon,

    so that ``l~_{k+1} + l~_{k+2} - l~_k >= delta`` in every face. Faces that already have
    the margin keep their shape up to the common shift, and ``epsilon = 0`` when no face
    is degenerate. Differentiable in ``lengths``.

    Parameters
    ----------
    lengths : (E,) floating tensor, one per edge
    face_edges : (F, 3) integer tensor or array, the edge opposite each corner
    factor : float >= 0, ``delta`` relative to the mean edge length

    Returns
    -------
    lengths : (E,) tensor ``l + epsilon``
    epsilon : scalar tensor
    faces : (K,) int64 tensor, the faces that lacked the margin
    """
    if not (isinstance(factor, (int, float)) and factor >= 0):
        raise ValueError(f"factor must be a number >= 0, got {factor!r}")
    fe = torch.as_tensor(face_edges, dtype=torch.int64, device=lengths.device)
    fl = lengths[fe]  # (F, 3)
    slack = fl.sum(1, keepdim=True) - 2 * fl  # l_{k+1} + l_{k+2} - l_k
    delta = factor * lengths.mean()
    short = (delta - slack).amax(1)
    eps = torch.clamp(short.max(), min=0.0)
    faces = torch.nonzero(short.detach() > 0).flatten()
    return lengths + eps, eps, faces


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
            add(
                self.split_faces,
                f"faces split at {len(self.t_junctions)} T-junction vertices "
                f"(+{self.t_junction_triangles} triangles), faces",
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
        if self.mollified_faces:
            add(
                self.mollified_faces,
                f"faces without the triangle-inequality margin {self.delta:.3g}: every edge length "
                f"+{self.epsilon:.3g} (intrinsic mollification, no vertex moved), repaired faces",
            )
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


@dataclass
class MappedEdgeField:
    """An edge field of a repaired mesh, expressed on the input mesh (:meth:`RepairResult.map_edge_field`).

    Attributes
    ----------
    edges : (E_in, 2) int64 tensor, the input edges (sides of the input polygons) ``i < j``
    values : (E_in,) or (E_in, C) complex tensor, in the frame of the input edge (from ``i``
        to ``j``); NaN where the edge was cut (several images) or has none (dropped faces)
    cut : (E_in,) bool tensor, edges with several images: read ``face_values`` there
    face_values : (F', 3) or (F', 3, C) complex tensor, the value of the edge opposite each
        corner of each repaired face, in the frame of the input edge between the input
        vertices of its ends (``vertex_origin``); the face comes from input face
        ``face_origin``
    """

    edges: torch.Tensor
    values: torch.Tensor
    cut: torch.Tensor
    face_values: torch.Tensor


@dataclass
class RepairResult:
    """A repaired mesh, how it relates to the input, and the report (:func:`repair`).

    Attributes
    ----------
    verts : (V', 3) tensor, positions of the repaired vertices (copies of input positions)
    faces : (F', 3) int64 tensor, counter-clockwise triangles, manifold and consistently
        oriented per component
    vertex_origin : (V',) int64 tensor, the input vertex of each vertex (several for a split
        one; for merged coincident vertices, the one they were merged into)
    face_origin : (F',) int64 tensor, the input face of each triangle
    flipped : (F',) bool tensor, triangles whose winding is reversed from the input's
    topology : :class:`Topology` of ``faces``
    edge_lengths : (E',) tensor in the order of ``topology.edges``: the lengths of the
        positions, mollified where faces lacked the margin (then ``epsilon > 0``)
    epsilon : float, the length added to every edge (0 when no face needed it)
    report : :class:`RepairReport`
    input_edges : (E_in, 2) int64 tensor, the sides of the input polygons ``i < j``
    num_input_faces, num_input_vertices : counts of the input
    merged_to : (V_in,) int64 tensor, the input vertex each input vertex was merged into
        (itself unless ``merge_coincident`` merged it); ``merged_to[vertex_origin]`` is
        ``vertex_origin``

    Use ``(result.verts, result.topology)`` for the operators when ``epsilon == 0``, and
    ``(result.geometry, result.topology)`` otherwise (always valid): the operators, field
    design and singularities accept a :class:`FaceGeometry` in place of positions.
    """

    verts: torch.Tensor
    faces: torch.Tensor
    vertex_origin: torch.Tensor
    face_origin: torch.Tensor
    flipped: torch.Tensor
    topology: Topology
    edge_lengths: torch.Tensor
    epsilon: float
    report: RepairReport
    input_edges: torch.Tensor
    num_input_faces: int
    num_input_vertices: int
    merged_to: torch.Tensor | None = None

    def _merged_to(self) -> np.ndarray:
        if self.merged_to is None:
            return np.arange(self.num_input_vertices)
        return self.merged_to.numpy()

    @property
    def mollified(self) -> bool:
        """Whether the lengths differ from those of the positions (use :attr:`geometry`)."""
        return self.epsilon > 0

    @property
    def geometry(self) -> FaceGeometry:
        """The intrinsic :class:`FaceGeometry` of :attr:`edge_lengths` (finite, valid faces)."""
        return FaceGeometry.from_lengths(
            self.edge_lengths[self.topology.face_edges.to(self.edge_lengths.device)]
        )

    def geometry_from_lengths(self, lengths: torch.Tensor) -> FaceGeometry:
        """:class:`FaceGeometry` of other (E',) edge lengths, e.g. ones that require grad."""
        return FaceGeometry.from_lengths(lengths[self.topology.face_edges.to(lengths.device)])

    def map_edge_field(self, z, n: int = 1) -> MappedEdgeField:
        """Express an edge field of the repaired mesh on the input mesh.

        The repaired edge ``(a, b)``, ``a < b``, is the input edge between
        ``vertex_origin[a]`` and ``vertex_origin[b]``; its frame runs from ``a`` to ``b``,
        that of the input edge from the lower to the higher input index. Where the two
        disagree the direction reverses, which multiplies the representation vector of an
        ``n``-direction field by ``(-1)^n``. Angles stay measured about the normal of the
        repaired (consistently oriented) surface; on a face of :attr:`flipped`, the input
        winding measures them the other way (take the conjugate).

        An input edge with exactly one image gets its value in ``values``; an edge cut into
        several (non-manifold edges, edges at split vertices) gets NaN there and has one
        value per face in ``face_values``. Diagonals added by triangulating polygons or
        splitting faces at T-junctions are not input edges and appear only in
        ``face_values``; an input edge split at a T-junction vertex has no image (NaN).
        Where coincident vertices were merged, the input edges of both sides of the
        closed crack take the value of the one repaired edge between them.

        Parameters
        ----------
        z : (E',) or (E', C) complex tensor on the repaired mesh
        n : int >= 1, the symmetry order of the field

        Returns
        -------
        :class:`MappedEdgeField`
        """
        topo = self.topology
        z = torch.as_tensor(z)
        if z.dim() not in (1, 2) or z.shape[0] != topo.num_edges:
            raise ValueError(
                f"z must have shape (E,) or (E, C) with E = {topo.num_edges}, got {tuple(z.shape)}"
            )
        if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 1:
            raise ValueError(f"n must be an integer >= 1, got {n!r}")
        if not z.is_complex():
            z = z.to(torch.complex128 if z.dtype == torch.float64 else torch.complex64)
        vo = self.vertex_origin.numpy()
        e = topo.edges.numpy()
        oa, ob = vo[e[:, 0]], vo[e[:, 1]]
        odd = -1.0 if n % 2 else 1.0
        sign = torch.where(torch.from_numpy(oa > ob).to(z.device), odd, 1.0).to(z.real.dtype)
        zin = z * (sign if z.dim() == 1 else sign[:, None])
        nv = max(self.num_input_vertices, 1)
        keys = np.minimum(oa, ob) * nv + np.maximum(oa, ob)
        order = np.argsort(keys, kind="stable")
        sorted_keys = keys[order]
        inp = self.input_edges.numpy().reshape(-1, 2)
        rep = self._merged_to()
        ra, rb = rep[inp[:, 0]], rep[inp[:, 1]]  # the input edge runs from ra to rb
        in_keys = np.minimum(ra, rb) * nv + np.maximum(ra, rb)
        first = np.searchsorted(sorted_keys, in_keys, side="left")
        images = np.searchsorted(sorted_keys, in_keys, side="right") - first
        images[ra == rb] = 0  # an edge collapsed by merging
        single = np.flatnonzero(images == 1)
        j = order[first[single]]  # the repaired edge of each
        flip = torch.from_numpy(oa[j] != ra[single]).to(z.device)
        shape = (len(in_keys),) + tuple(z.shape[1:])
        values = torch.full(shape, complex("nan"), dtype=z.dtype, device=z.device)
        s_edge = torch.where(flip, odd, 1.0).to(z.real.dtype)
        zj = z[torch.from_numpy(j).to(z.device)]
        values[torch.from_numpy(single).to(z.device)] = zj * (s_edge if z.dim() == 1 else s_edge[:, None])
        fe = topo.face_edges.to(z.device)
        return MappedEdgeField(
            edges=self.input_edges.clone(),
            values=values,
            cut=torch.from_numpy(images > 1),
            face_values=zin[fe],
        )

    def map_face_values(self, x) -> torch.Tensor:
        """Per-face values of the repaired mesh on the input faces: (F_in,) or (F_in, C).

        The mean over the triangles of each input face (one triangle unless a polygon was
        triangulated); NaN for the dropped faces of ``report.dropped_faces``.
        """
        x = torch.as_tensor(x)
        if x.shape[0] != self.topology.num_faces:
            raise ValueError(f"x must have {self.topology.num_faces} rows (faces), got {tuple(x.shape)}")
        dtype = x.dtype if (x.is_floating_point() or x.is_complex()) else torch.float64
        x = x.to(dtype)
        shape = (self.num_input_faces,) + tuple(x.shape[1:])
        origin = self.face_origin.to(x.device)
        total = torch.zeros(shape, dtype=dtype, device=x.device).index_add(0, origin, x)
        count = torch.zeros(self.num_input_faces, dtype=x.real.dtype, device=x.device).index_add(
            0, origin, torch.ones(origin.shape[0], dtype=x.real.dtype, device=x.device)
        )
        count = count if x.dim() == 1 else count[:, None]
        return torch.where(count > 0, total / torch.where(count > 0, count, 1.0), float("nan"))

    def map_vertex_values(self, x) -> torch.Tensor:
        """Per-vertex values of the repaired mesh on the input vertices: (V_in,) or (V_in, C).

        The mean over the copies of a split vertex; a merged coincident vertex takes the
        value of the vertex it was merged into; NaN for dropped vertices.
        """
        x = torch.as_tensor(x)
        if x.shape[0] != self.topology.num_vertices:
            raise ValueError(
                f"x must have {self.topology.num_vertices} rows (vertices), got {tuple(x.shape)}"
            )
        dtype = x.dtype if (x.is_floating_point() or x.is_complex()) else torch.float64
        x = x.to(dtype)
        origin = self.vertex_origin.to(x.device)
        shape = (self.num_input_vertices,) + tuple(x.shape[1:])
        total = torch.zeros(shape, dtype=dtype, device=x.device).index_add(0, origin, x)
        count = torch.zeros(self.num_input_vertices, dtype=x.real.dtype, device=x.device).index_add(
            0, origin, torch.ones(origin.shape[0], dtype=x.real.dtype, device=x.device)
        )
        count = count if x.dim() == 1 else count[:, None]
        out = torch.where(count > 0, total / torch.where(count > 0, count, 1.0), float("nan"))
        if self.merged_to is not None:
            out = out[self.merged_to.to(x.device)]
        return out


def repair(
    verts,
    faces,
    mollify_factor: float = MOLLIFY_FACTOR,
    *,
    merge_coincident: bool = False,
    split_t_junctions: bool = False,
    tol: float = COINCIDENT_TOL,
) -> RepairResult:
    """Turn a triangle (or polygon) soup into a mesh the operators accept, reporting every change.

    In order, on copies (the input is never modified and no vertex is moved):

    1. repeated vertex indices are removed from each face (what has fewer than three
       vertices left is dropped), and polygons are triangulated in their best-fit planes
       (:func:`triangulate`): convex ones as fans from their first corner, others by ear
       clipping, so that every triangle keeps the polygon's orientation; a polygon with
       zero area or crossing sides is split into a fan and named in ``fan_faces``;
    2. faces using a vertex with NaN or Inf coordinates are dropped;
    3. coincident vertices (distinct referenced vertices within ``tol`` times the
       bounding-box diagonal, :func:`~torch_edgevf.mesh.diagnose.find_coincident_vertices`)
       are reported; with ``merge_coincident`` each cluster of them is merged into its
       lowest index, which closes a zero-width crack (triangles left with a repeated
       vertex are dropped);
    4. duplicate faces (the same three vertices, in any order) are dropped, the first kept;
    5. T-junctions (a boundary vertex inside a boundary edge of another face,
       :func:`~torch_edgevf.mesh.diagnose.find_t_junctions`) are reported; with
       ``split_t_junctions`` the triangle of that edge is split at each such vertex, a fan
       from its opposite corner with the winding kept, so that both sides of the crack
       share the pieces of the edge;
    6. edges shared by more than two faces (non-manifold) are cut: each of those faces
       keeps its own copy of the edge, a boundary edge;
    7. each sheet (faces connected through manifold edges) is oriented consistently by
       flipping the minority of its faces; a sheet that cannot be oriented (a Moebius
       strip) raises ``ValueError``;
    8. vertices whose faces then form several fans (bowties, ends of cut edges) are split,
       one copy per fan; unreferenced vertices are dropped;
    9. zero-area and needle faces are handled by intrinsic mollification
       (:func:`mollify_lengths`): the edge lengths, not the positions, are changed.

    Parameters
    ----------
    verts : (V, 3) float tensor or array
    faces : (F, 3) or (F, k) integer tensor or array, or a sequence of index sequences
        (polygons of any sizes)
    mollify_factor : float >= 0, the margin of the triangle inequality relative to the
        mean edge length
    merge_coincident : bool, merge coincident vertices (default: report them only, since
        merging changes the topology); ``vertex_origin`` then names the vertex each
        cluster was merged into and ``merged_to`` maps every input vertex to it
    split_t_junctions : bool, split faces at T-junction vertices (default: report only)
    tol : float in [0, 1), the tolerance of both crack checks relative to the
        bounding-box diagonal of the referenced vertices (0: bitwise-equal positions)

    Returns
    -------
    :class:`RepairResult`

    Raises
    ------
    ValueError
        Wrong shapes or dtypes, indices out of range, nothing left, a non-orientable
        sheet (naming its faces), or a bad option.
    """
    for name, flag in (("merge_coincident", merge_coincident), ("split_t_junctions", split_t_junctions)):
        if not isinstance(flag, (bool, np.bool_)):
            raise ValueError(f"{name} must be True or False, got {flag!r}")
    tol = _check_tol(tol)
    v, out_dtype = _positions(verts)
    nv = v.shape[0]
    tri, origin, report, polys, sides = _triangulate(faces, nv, v=v)
    report.input_vertices = nv
    report.input_faces = len(polys)
    dropped_tri: dict[str, np.ndarray] = {}

    def drop(mask: np.ndarray, why: str):
        nonlocal tri, origin
        if mask.any():
            dropped_tri[why] = np.concatenate([dropped_tri.get(why, np.zeros(0, np.int64)), origin[mask]])
            tri, origin = tri[~mask], origin[~mask]

    finite = np.isfinite(v).all(1)
    if not finite.all():
        report.nonfinite_vertices = np.flatnonzero(~finite).tolist()
        drop((~finite[tri]).any(1), "a vertex with NaN or Inf coordinates")
    pairs = _coincident_pairs(v, tri, tol)
    report.coincident_vertices = [(int(a), int(b)) for a, b in pairs]
    merged_to = np.arange(nv)
    if merge_coincident and len(pairs):
        merged_to = _merge_clusters(pairs, nv)
        moved = np.flatnonzero(merged_to != np.arange(nv))
        report.merged_vertices = {int(i): int(merged_to[i]) for i in moved}
        tri = merged_to[tri]
        collapsed = (tri[:, 0] == tri[:, 1]) | (tri[:, 1] == tri[:, 2]) | (tri[:, 2] == tri[:, 0])
        report.collapsed_faces = np.unique(origin[collapsed]).tolist()
        drop(collapsed, "collapsed by merging coincident vertices")
    # duplicates, the first occurrence kept
    if len(tri):
        _, first, inverse = np.unique(np.sort(tri, axis=1), axis=0, return_index=True, return_inverse=True)
        inverse = inverse.reshape(-1)
        dup = first[inverse] != np.arange(len(tri))
        if dup.any():
            report.duplicate_faces = [
                (int(a), int(b)) for a, b in zip(origin[dup], origin[first[inverse[dup]]]) if a != b
            ]
            drop(dup, "duplicate of another face")
    present = np.zeros(report.input_faces, dtype=bool)
    present[origin] = True
    for why, fs in dropped_tri.items():
        for f in np.unique(fs).tolist():
            if not present[f] and f not in report.dropped_faces:
                report.dropped_faces[f] = why
    for f in np.flatnonzero(~present).tolist():
        report.dropped_faces.setdefault(
            f, "repeated vertex indices" if len(polys[f]) >= 3 else "fewer than 3 vertices"
        )
    if len(tri) == 0:
        raise ValueError("repair: no faces left (all were dropped: " + report.summary() + ")")

    junctions = _t_junctions(v, tri, tol)
    w, t, k, _ = junctions
    a, b = tri[t, (k + 1) % 3], tri[t, (k + 2) % 3]
    report.t_junctions = [
        (int(x), int(p), int(q), int(f))
        for x, p, q, f in zip(w, np.minimum(a, b), np.maximum(a, b), origin[t])
    ]
    if split_t_junctions and len(w):
        tri, origin = _split_at_t_junctions(v, tri, origin, tol, junctions, report)

    tri, flipped = _orient(tri, origin, nv, report)
    new_faces, vertex_origin = _split_vertices(tri, nv, report)
    used = np.zeros(nv, dtype=bool)
    used[tri.ravel()] = True
    used[list(report.merged_vertices)] = True  # merged, not unreferenced
    report.unreferenced_vertices = np.flatnonzero(~used).tolist()
    try:
        topo = Topology(torch.from_numpy(new_faces), num_vertices=len(vertex_origin))
    except ValueError as err:  # not expected: every check above makes a valid topology
        raise ValueError(f"repair could not make a manifold mesh: {err}") from err

    new_verts = torch.from_numpy(v[vertex_origin]).to(out_dtype)
    e = topo.edges
    lengths = torch.linalg.vector_norm(new_verts[e[:, 1]] - new_verts[e[:, 0]], dim=-1)
    lengths, eps, moll = mollify_lengths(lengths, topo.face_edges, mollify_factor)
    report.epsilon = float(eps)
    report.delta = (
        float(mollify_factor * lengths.mean())
        if report.epsilon == 0
        else float(mollify_factor * (lengths - eps).mean())
    )
    report.mollified_faces = moll.tolist()
    report.num_vertices, report.num_faces, report.num_edges = (
        topo.num_vertices,
        topo.num_faces,
        topo.num_edges,
    )
    report.components = _component_counts(topo, flipped, moll.numpy())

    result = RepairResult(
        verts=new_verts,
        faces=topo.faces,
        vertex_origin=torch.from_numpy(vertex_origin),
        face_origin=torch.from_numpy(origin.copy()),
        flipped=torch.from_numpy(flipped),
        topology=topo,
        edge_lengths=lengths,
        epsilon=report.epsilon,
        report=report,
        input_edges=torch.from_numpy(sides),
        num_input_faces=report.input_faces,
        num_input_vertices=nv,
        merged_to=torch.from_numpy(merged_to),
    )
    if report.changed or report.cracks:
        log.info("%s", report)
    return result


def _merge_clusters(pairs: np.ndarray, nv: int) -> np.ndarray:
    """(V,) map of each vertex to the lowest index of its cluster (pairs joined transitively)."""
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(nv, nv))
    _, labels = connected_components(graph, directed=False)
    lowest = np.full(labels.max() + 1, nv, dtype=np.int64)
    np.minimum.at(lowest, labels, np.arange(nv))
    return lowest[labels]


def _split_at_t_junctions(v, tri, origin, tol, junctions, report: RepairReport, max_rounds: int = 8):
    """Split triangles at their T-junction vertices until none is left; fill the report.

    Each round splits every triangle along one of its edges (the first with T-junction
    vertices): the triangle ``(a, b, c)`` whose edge ``a -> b`` holds the vertices
    ``w_1, ..., w_m`` (in order from ``a``) becomes the fan ``(a, w_1, c), (w_1, w_2, c),
    ..., (w_m, b, c)`` with the same winding. The other two edges are edges of the new
    triangles, so the next round (a fresh search) finds their T-junctions again.
    """
    split: list[np.ndarray] = []
    before = len(tri)
    w, t, k, _ = junctions
    for _round in range(max_rounds):
        if not len(w):
            break
        # rows are sorted by triangle, corner, position: keep the first corner of each triangle
        first_k = np.full(len(tri), 3)
        np.minimum.at(first_k, t, k)
        sel = k == first_k[t]
        w, t, k = w[sel], t[sel], k[sel]
        start = np.r_[True, t[1:] != t[:-1]]
        end = np.r_[t[1:] != t[:-1], True]
        a, b, c = tri[t, (k + 1) % 3], tri[t, (k + 2) % 3], tri[t, k]
        prev = np.where(start, a, np.r_[0, w[:-1]])
        fans = np.concatenate([np.stack([prev, w, c], 1), np.stack([w[end], b[end], c[end]], 1)])
        fan_origin = np.concatenate([origin[t], origin[t[end]]])
        split.append(origin[t[end]])
        keep = np.ones(len(tri), dtype=bool)
        keep[t] = False
        tri = np.concatenate([tri[keep], fans])
        origin = np.concatenate([origin[keep], fan_origin])
        order = np.argsort(origin, kind="stable")  # triangles in the order of their faces
        tri, origin = tri[order], origin[order]
        w, t, k, _ = _t_junctions(v, tri, tol)
    else:
        if len(w):  # not expected: each round removes the T-junctions of one edge per face
            raise ValueError(
                f"repair: T-junctions left after {max_rounds} rounds of splitting, at input faces "
                f"[{list_some(np.unique(origin[t]).tolist())}]"
            )
    report.split_faces = np.unique(np.concatenate(split)).tolist() if split else []
    report.t_junction_triangles = int(len(tri) - before)
    return np.ascontiguousarray(tri), origin


def _positions(verts) -> tuple[np.ndarray, torch.dtype]:
    if isinstance(verts, torch.Tensor):
        if not verts.is_floating_point():
            raise ValueError(f"verts must have a floating dtype, got {verts.dtype}")
        dtype = verts.dtype
        v = verts.detach().cpu().numpy().astype(np.float64)
    else:
        arr = np.asarray(verts)
        if not np.issubdtype(arr.dtype, np.floating):
            raise ValueError(f"verts must have a floating dtype, got {arr.dtype}")
        dtype = torch.float32 if arr.dtype == np.float32 else torch.float64
        v = arr.astype(np.float64)  # a copy
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
        raise ValueError(f"verts must have shape (V, 3) with V >= 1, got {tuple(v.shape)}")
    return v, dtype


def triangulate(
    faces, num_vertices: int, check: bool = True, *, verts=None
) -> tuple[np.ndarray, np.ndarray, RepairReport]:
    """Triangulation of polygons after removing their repeated vertex indices.

    The first step of :func:`repair`, also used by the file readers. Triangles keep
    their faces' corners and winding; no vertex is added.

    Without positions, a polygon of ``k > 3`` corners is split into the fan of ``k - 2``
    triangles from its first corner, which is valid for convex polygons only. With
    ``verts``, each polygon is triangulated in its best-fit plane (through the mean of its
    corners, normal to its Newell normal, the vector area): a strictly convex polygon keeps
    the fan, any other one is triangulated by ear clipping, which cuts off, in turn, the
    best-shaped corner that turns as the polygon does and whose triangle with its two
    neighbours holds no other corner. Every triangle then has positive area in the plane
    (its normal agrees with the polygon's), the ``k - 2`` triangles cover the polygon once
    and its sides are sides of the triangles. A polygon without a plane (zero area:
    collinear corners) or that is not simple in its plane (sides that cross or touch,
    a side doubling back) keeps the fan and is named in ``report.fan_faces``. Polygons
    with an index outside ``[0, num_vertices)`` or a non-finite corner keep the fan
    unreported (:func:`repair` drops them), and so does a polygon that still repeats a
    vertex once its consecutive repeats are removed (pinched), without the fan's
    triangles that repeat it.

    Parameters
    ----------
    faces : (F, k) integer array or tensor, or a sequence of index sequences
    num_vertices : int
    check : raise ``ValueError`` for indices outside ``[0, num_vertices)``
    verts : (num_vertices, 3) float array or tensor, optional
        The vertex positions; without them polygons are split into fans.

    Returns
    -------
    triangles : (T, 3) int64 array
    origin : (T,) int64 array, the face of each triangle
    report : :class:`RepairReport` with ``triangulated_faces``, ``added_triangles``,
        ``fan_faces`` and ``repeated_index_faces`` filled in
    """
    v = None
    if verts is not None:
        v = verts.detach().cpu().numpy() if isinstance(verts, torch.Tensor) else np.asarray(verts)
        if v.shape != (num_vertices, 3) or not np.issubdtype(v.dtype, np.floating):
            raise ValueError(
                f"verts must be a ({num_vertices}, 3) float array, got shape {v.shape}, dtype {v.dtype}"
            )
        v = v.astype(np.float64)
    tri, origin, report, _, _ = _triangulate(faces, num_vertices, check, v)
    return tri, origin, report


#: Tolerance of the plane tests of :func:`triangulate` relative to the squared extent of
#: a polygon: smaller doubled areas count as zero (collinear corners, straight turns).
PLANE_TOL = 1e-12


def _fan(k: int) -> np.ndarray:
    """(k - 2, 3) corners of the fan of a k-gon from its first corner."""
    j = np.arange(1, k - 1)
    return np.stack([np.zeros_like(j), j, j + 1], 1)


def _cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _plane_coordinates(p: np.ndarray):
    """Polygons (n, k, 3) in their best-fit planes: (n, k, 2) coordinates, (n,) tolerance, (n,) flat.

    The plane passes through the mean of the corners, normal to the Newell normal (the
    vector area); its axes ``(u, w)`` have ``u x w`` along the normal, so that every polygon
    has positive signed area in its coordinates. ``tol`` is :data:`PLANE_TOL` times the
    squared extent of the polygon; ``flat`` marks the polygons whose doubled area is not
    above it (no plane).
    """
    c = p - p.mean(1, keepdims=True)
    normal = np.cross(c, np.roll(c, -1, axis=1)).sum(1)  # twice the vector area
    size = np.linalg.norm(normal, axis=1)
    tol = PLANE_TOL * (c.max(1) - c.min(1)).max(1) ** 2
    flat = ~(size > tol)
    unit = np.where(flat[:, None], [0.0, 0.0, 1.0], normal / np.where(flat, 1.0, size)[:, None])
    axis = np.eye(3)[np.argmin(np.abs(unit), axis=1)]  # the axis least aligned with the normal
    u = np.cross(unit, axis)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(unit, u)
    xy = np.stack([np.einsum("nkd,nd->nk", c, u), np.einsum("nkd,nd->nk", c, w)], -1)
    return xy, tol, flat


def _turns(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cross and dot products of the sides into and out of each corner of polygons (..., k, 2)."""
    side = np.roll(xy, -1, axis=-2) - xy  # from corner i to corner i + 1
    into = np.roll(side, 1, axis=-2)
    return _cross2(into, side), (into * side).sum(-1)


def _self_intersecting(xy: np.ndarray, tol: np.ndarray) -> np.ndarray:
    """(n,) whether two sides of each polygon (n, k, 2) meet other than adjacent ones at their corner."""
    n, k, _ = xy.shape
    turn, dot = _turns(xy)
    out = ((np.abs(turn) <= tol[:, None]) & (dot < 0)).any(1)  # a side doubling back on the last
    side = np.roll(xy, -1, axis=1) - xy
    i, j = np.triu_indices(k, 2)
    keep = j - i < k - 1  # sides 0 and k - 1 are adjacent
    i, j = i[keep], j[keep]
    step = max(1, (1 << 20) // max(n, 1))
    eps = tol[:, None]
    for s in range(0, len(i), step):
        a, b = i[s : s + step], j[s : s + step]
        pa, da, pb, db = xy[:, a], side[:, a], xy[:, b], side[:, b]

        def sign(x):
            return np.where(np.abs(x) <= eps, 0, np.sign(x))

        o1, o2 = sign(_cross2(da, pb - pa)), sign(_cross2(da, pb + db - pa))
        o3, o4 = sign(_cross2(db, pa - pb)), sign(_cross2(db, pa + da - pb))
        on_line = ((o1 == 0) & (o2 == 0)) | ((o3 == 0) & (o4 == 0))
        crossing = ~on_line & (o1 * o2 <= 0) & (o3 * o4 <= 0)
        # sides along one line meet where their extents along it overlap
        t = np.where((da * da).sum(-1, keepdims=True) >= (db * db).sum(-1, keepdims=True), da, db)
        s0, s1 = (pa * t).sum(-1), ((pa + da) * t).sum(-1)
        r0, r1 = (pb * t).sum(-1), ((pb + db) * t).sum(-1)
        overlap = np.maximum(np.minimum(s0, s1), np.minimum(r0, r1)) <= (
            np.minimum(np.maximum(s0, s1), np.maximum(r0, r1)) + eps
        )
        out |= (crossing | (on_line & overlap)).any(1)
    return out


def _ear_clip(xy: np.ndarray, tol: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ear clipping of polygons (n, k, 2) of positive signed area: (n, k - 2, 3) corners, (n,) done.

    An ear is a corner that turns left by more than ``tol`` and whose closed triangle with
    its two neighbours holds no other remaining corner (so none lies on the new side);
    each step cuts off the ear of the best shape (doubled area over the sum of the squared
    sides), in all polygons at once. ``done`` is False for a polygon that is not simple
    (its turns do not add up to one counter-clockwise revolution, or two sides meet) or
    that is left without an ear; its corners are then meaningless.
    """
    n, k, _ = xy.shape
    turn, dot = _turns(xy)
    done = np.abs(np.arctan2(turn, dot).sum(1) - 2 * np.pi) <= np.pi
    done[done] = ~_self_intersecting(xy[done], tol[done])
    corner = np.arange(k)
    prv = np.broadcast_to(np.roll(corner, 1), (n, k)).copy()
    nxt = np.broadcast_to(np.roll(corner, -1), (n, k)).copy()
    alive = np.ones((n, k), dtype=bool)

    def scores(r: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Shape of the ear at corner ``b`` of polygon ``r`` (arrays), -1 where it is no ear."""
        a, c = prv[r, b], nxt[r, b]
        pa, pb, pc = xy[r, a], xy[r, b], xy[r, c]
        ab, bc, ca = pb - pa, pc - pb, pa - pc
        area = _cross2(ab, bc)
        q, eps = xy[r], -tol[r][:, None]
        inside = (
            (_cross2(ab[:, None], q - pa[:, None]) >= eps)
            & (_cross2(bc[:, None], q - pb[:, None]) >= eps)
            & (_cross2(ca[:, None], q - pc[:, None]) >= eps)
        )
        own = (corner == a[:, None]) | (corner == b[:, None]) | (corner == c[:, None])
        ear = (area > tol[r]) & ~(inside & alive[r] & ~own).any(1)
        size = (ab**2).sum(1) + (bc**2).sum(1) + (ca**2).sum(1)
        return np.where(ear, area / np.where(size > 0, size, 1.0), -1.0)

    def all_scores(rows: np.ndarray) -> np.ndarray:
        if not len(rows):
            return np.zeros((0, k))
        r, b = np.repeat(rows, k), np.tile(corner, len(rows))
        step = max(1, (1 << 20) // k)
        s = np.concatenate([scores(r[m : m + step], b[m : m + step]) for m in range(0, len(r), step)])
        return np.where(alive[rows], s.reshape(len(rows), k), -np.inf)

    out = np.zeros((n, k - 2, 3), dtype=np.int64)
    score = np.full((n, k), -np.inf)
    live = np.flatnonzero(done)
    score[live] = all_scores(live)
    for step in range(k - 3):
        b = score[live].argmax(1)
        stuck = score[live, b] < 0
        if stuck.any():  # clipping may have freed an ear away from the cut: look again
            score[live[stuck]] = all_scores(live[stuck])
            b[stuck] = score[live[stuck]].argmax(1)
            lost = score[live, b] < 0
            done[live[lost]] = False
            live, b = live[~lost], b[~lost]
        a, c = prv[live, b], nxt[live, b]
        out[live, step] = np.stack([a, b, c], 1)
        alive[live, b] = False
        score[live, b] = -np.inf
        nxt[live, a], prv[live, c] = c, a
        score[np.r_[live, live], np.r_[a, c]] = scores(np.r_[live, live], np.r_[a, c])
    b = alive[live].argmax(1)
    out[live, k - 3] = np.stack([prv[live, b], b, nxt[live, b]], 1)
    return out, done


def _split_polygons(block: np.ndarray, v: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of polygons (n, k), k > 3, as in :func:`triangulate`: (n, k - 2, 3), rows fanned.

    The second output lists the rows that have positions but kept the fan for lack of a
    plane or of a simple outline.
    """
    n, k = block.shape
    tri = block[:, _fan(k)]
    if v is None:
        return tri, np.zeros(0, np.int64)
    placed = np.asarray(((block >= 0) & (block < len(v))).all(1))
    placed[placed] = np.isfinite(v[block[placed]]).all((1, 2))
    rows = np.flatnonzero(placed)
    if not len(rows):
        return tri, np.zeros(0, np.int64)
    xy, tol, flat = _plane_coordinates(v[block[rows]])
    turn, dot = _turns(xy)
    convex = ~flat & (turn > tol[:, None]).all(1) & (np.arctan2(turn, dot).sum(1) < 3 * np.pi)
    clip = np.flatnonzero(~convex & ~flat)
    corners, done = _ear_clip(xy[clip], tol[clip])
    ok = rows[clip[done]]
    tri[ok] = block[ok][np.arange(len(ok))[:, None, None], corners[done]]
    fanned = np.union1d(rows[flat], rows[clip[~done]])
    return tri, fanned.astype(np.int64)


def _triangulate(faces, nv: int, check: bool = True, v: np.ndarray | None = None):
    """Triangles of the polygons, without repeated indices: (T, 3), origin (T,), report, polygons, sides.

    ``v``: float64 positions (nv, 3), or None for fans (see :func:`triangulate`).
    """
    report = RepairReport()
    if isinstance(faces, torch.Tensor):
        faces = faces.detach().cpu().numpy()
    if isinstance(faces, np.ndarray):
        if faces.ndim != 2 or (faces.size and not np.issubdtype(faces.dtype, np.integer)):
            raise ValueError(
                f"faces must be an (F, k) integer array, got shape {faces.shape}, dtype {faces.dtype}"
            )
        polys: Sequence = list(faces.astype(np.int64))
    else:
        try:
            polys = [np.asarray(p) for p in faces]
        except TypeError as err:
            raise ValueError(
                f"faces must be an (F, k) array or a sequence of index sequences: {err}"
            ) from err
        for i, p in enumerate(polys):
            if p.ndim != 1 or (p.size and not np.issubdtype(p.dtype, np.integer)):
                raise ValueError(f"face {i} is not a sequence of integer vertex indices: {p!r}")
        polys = [p.astype(np.int64) for p in polys]
    if not polys:
        raise ValueError("the mesh is empty: faces has no rows")
    sizes = np.array([len(p) for p in polys])
    flat = np.concatenate(polys) if sizes.sum() else np.zeros(0, np.int64)
    bad = (flat < 0) | (flat >= nv)
    if check and bad.any():
        owner = np.repeat(np.arange(len(polys)), sizes)
        raise ValueError(face_range_message(np.unique(owner[bad]).tolist(), nv))
    tris, origins, sides = [], [], []
    uniform = isinstance(faces, np.ndarray)
    for k in np.unique(sizes):
        if k < 3:
            continue
        rows = np.flatnonzero(sizes == k)
        block = faces.astype(np.int64) if uniform else np.stack([polys[int(i)] for i in rows])
        srt = np.sort(block, axis=1)
        repeated = (srt[:, 1:] == srt[:, :-1]).any(1)
        clean, crow = block[~repeated], rows[~repeated]
        if k > 3:
            report.triangulated_faces += crow.tolist()
            split, fanned = _split_polygons(clean, v)
            tris.append(split.reshape(-1, 3))
            origins.append(np.repeat(crow, k - 2))
            report.fan_faces += crow[fanned].tolist()
        else:
            tris.append(clean)
            origins.append(crow)
        sides += [clean[:, [j, (j + 1) % k]] for j in range(k)]
        for i in rows[repeated].tolist():
            report.repeated_index_faces.append(i)
            p = polys[i]
            keep = [p[0]] + [p[m] for m in range(1, len(p)) if p[m] != p[m - 1]]
            while len(keep) > 1 and keep[-1] == keep[0]:
                keep.pop()
            if len(keep) > 3:
                report.triangulated_faces.append(i)
            if len(keep) > 1:
                sides.append(np.array([[keep[m], keep[(m + 1) % len(keep)]] for m in range(len(keep))]))
            if len(keep) > 3 and len(set(keep)) == len(keep):
                split, fanned = _split_polygons(np.array([keep], dtype=np.int64), v)
                tris.append(split.reshape(-1, 3))
                origins.append(np.full(len(keep) - 2, i))
                if len(fanned):
                    report.fan_faces.append(i)
                continue
            for j in range(1, len(keep) - 1):
                t = (keep[0], keep[j], keep[j + 1])
                if len(set(t)) == 3:  # a non-consecutive repeat leaves a degenerate fan triangle
                    tris.append(np.array([t], dtype=np.int64))
                    origins.append(np.array([i]))
    report.repeated_index_faces.sort()
    report.triangulated_faces.sort()
    report.fan_faces.sort()
    if tris:
        tri, origin = np.concatenate(tris), np.concatenate(origins)
        order = np.argsort(origin, kind="stable")  # triangles in the order of their faces
        tri, origin = tri[order], origin[order]
    else:
        tri, origin = np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    report.added_triangles = int(len(tri) - len(np.unique(origin)))
    pairs = np.concatenate(sides).reshape(-1, 2) if sides else np.zeros((0, 2), np.int64)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    sides_out = np.unique(np.sort(pairs, axis=1), axis=0).astype(np.int64)
    return np.ascontiguousarray(tri), origin.astype(np.int64), report, polys, sides_out


def _edge_groups(tri: np.ndarray, nv: int):
    """Half-edges (3 f + k, opposite corner k) grouped by undirected edge."""
    src, dst = tri[:, [1, 2, 0]].ravel(), tri[:, [2, 0, 1]].ravel()
    keys = np.minimum(src, dst) * nv + np.maximum(src, dst)
    uniq, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    order = np.argsort(inverse, kind="stable")
    start = np.cumsum(counts) - counts
    return src, dst, uniq, counts, order, start


def _orient(tri: np.ndarray, origin: np.ndarray, nv: int, report: RepairReport):
    """Cut non-manifold edges (report them) and orient each sheet by flipping its minority."""
    nt = len(tri)
    src, dst, uniq, counts, order, start = _edge_groups(tri, nv)
    many = counts > 2
    report.non_manifold_edges = [(int(k // nv), int(k % nv)) for k in uniq[many]]
    two = np.flatnonzero(counts == 2)
    h1, h2 = order[start[two]], order[start[two] + 1]
    f1, f2 = h1 // 3, h2 // 3
    same = src[h1] == src[h2]  # both faces run the edge the same way: one must flip
    # a virtual root joined to every face makes one breadth-first search orient all sheets
    graph = sp.coo_matrix((np.ones(len(two)), (f1, f2)), shape=(nt, nt)).tocsr()
    ncomp, labels = connected_components(graph, directed=False)
    roots = np.unique(labels, return_index=True)[1]
    rows = np.concatenate([f1, f2, np.full(len(roots), nt)])
    cols = np.concatenate([f2, f1, roots])
    full = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(nt + 1, nt + 1)).tocsr()
    bfs, pred = breadth_first_order(full, nt, directed=True, return_predecessors=True)
    # parity of each face relative to its predecessor, then along the tree by pointer doubling
    pair_keys = np.concatenate([f1 * (nt + 1) + f2, f2 * (nt + 1) + f1])
    pair_same = np.concatenate([same, same])
    srt = np.argsort(pair_keys)
    pair_keys, pair_same = pair_keys[srt], pair_same[srt]
    p = pred[:nt].astype(np.int64)
    tree = p < nt
    step = np.zeros(nt, dtype=bool)
    q = np.searchsorted(pair_keys, np.arange(nt)[tree] * (nt + 1) + p[tree])
    step[tree] = pair_same[q]
    parity, jump = step.copy(), np.where(tree, p, -1)
    while (jump >= 0).any():
        live = jump >= 0
        parity[live] ^= parity[jump[live]]
        nxt = np.full(nt, -1)
        nxt[live] = jump[jump[live]]
        jump = nxt
    conflict = (parity[f1] ^ parity[f2]) != same
    if conflict.any():
        comp = np.unique(labels[f1[conflict]])
        faces_bad = np.flatnonzero(np.isin(labels, comp))
        edges_bad = [(int(k // nv), int(k % nv)) for k in uniq[two[conflict]]]
        raise ValueError(
            f"repair: {len(comp)} sheet(s) cannot be oriented (non-orientable, like a Moebius strip): "
            f"input faces [{list_some(np.unique(origin[faces_bad]).tolist())}], "
            f"where the orientation conflicts across edges [{list_some(edges_bad)}]"
        )
    size = np.bincount(labels, minlength=ncomp)
    odd = np.bincount(labels, weights=parity, minlength=ncomp)
    flip = parity ^ (2 * odd > size)[labels]
    tri = tri.copy()
    tri[flip] = tri[flip][:, [0, 2, 1]]
    report.flipped_faces = np.unique(origin[flip]).tolist()
    del bfs
    return tri, flip


def _split_vertices(tri: np.ndarray, nv: int, report: RepairReport):
    """One vertex per fan: corners joined across manifold (two-face) edges; returns faces and origins."""
    nt = len(tri)
    src, dst, uniq, counts, order, start = _edge_groups(tri, nv)
    two = np.flatnonzero(counts == 2)
    h1, h2 = order[start[two]], order[start[two] + 1]
    f1, f2 = h1 // 3, h2 // 3
    k1, k2 = h1 % 3, h2 % 3
    # in face f the half-edge opposite corner k runs from corner k+1 to corner k+2; after
    # orientation the other face runs it backwards, from its corner k'+2 to k'+1
    a1, b1 = 3 * f1 + (k1 + 1) % 3, 3 * f1 + (k1 + 2) % 3
    a2, b2 = 3 * f2 + (k2 + 2) % 3, 3 * f2 + (k2 + 1) % 3
    corner_vertex = tri.ravel()
    ok = (corner_vertex[a1] == corner_vertex[a2]) & (corner_vertex[b1] == corner_vertex[b2])
    rows = np.concatenate([a1[ok], b1[ok]])
    cols = np.concatenate([a2[ok], b2[ok]])
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(3 * nt, 3 * nt))
    _, labels = connected_components(graph, directed=False)
    first = np.full(labels.max() + 1, 3 * nt, dtype=np.int64)
    np.minimum.at(first, labels, np.arange(3 * nt))
    group_vertex = corner_vertex[first]
    order_groups = np.lexsort((first, group_vertex))
    new_index = np.empty_like(order_groups)
    new_index[order_groups] = np.arange(len(order_groups))
    faces = new_index[labels].reshape(nt, 3)
    vertex_origin = group_vertex[order_groups]
    copies = np.bincount(vertex_origin, minlength=nv)
    split = np.flatnonzero(copies > 1)
    report.split_vertices = {int(i): int(copies[i]) for i in split}
    on_cut = np.zeros(nv, dtype=bool)
    for a, b in report.non_manifold_edges:
        on_cut[a] = on_cut[b] = True
    report.non_manifold_vertices = [int(i) for i in split if not on_cut[i]]
    return faces.astype(np.int64), vertex_origin.astype(np.int64)


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
