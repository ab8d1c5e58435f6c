"""The result of :func:`repair`: the repaired mesh, its maps to the input, field transfer."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..geometry import FaceGeometry
from ..topology import Topology
from .report import RepairReport


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
