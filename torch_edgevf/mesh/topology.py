"""Mesh connectivity, computed once from the faces alone.

Conventions (thesis, section 2.2 and figure 2.2):

* a face ``f = (f0, f1, f2)`` is counter-clockwise; its corner ``k`` is the vertex ``f[k]``;
* the edge *opposite* corner ``k`` joins ``f[k+1]`` and ``f[k+2]`` (indices mod 3);
* edges are stored as ``(i, j)`` with ``i < j``, sorted lexicographically; the frame of an
  edge points from ``i`` to ``j``;
* the orientation sign ``delta[f, k]`` is ``+1`` when the face's counter-clockwise order runs
  from the lower to the higher index along the edge opposite corner ``k``, else ``-1``;
* ``edge_faces[e, 0]`` is the face in which edge ``e`` runs ``i -> j`` (sign ``+1``) and
  ``edge_faces[e, 1]`` the face in which it runs ``j -> i``; ``-1`` marks a missing face
  (a boundary edge has exactly one of the two).

Unreferenced vertices (rows of ``verts`` that no face uses) are allowed: they keep their
index, are listed in :attr:`Topology.unreferenced_vertices`, get zero rows and columns in
vertex operators and a component label of ``-1``, and do not count in the Euler
characteristic. Use :func:`remove_unreferenced_vertices` to drop them.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cached_property
from typing import Literal, TypeVar

import numpy as np
import scipy.sparse as sp
import torch
from scipy.sparse.csgraph import connected_components

from .._validation import as_faces, list_some

__all__ = ["Topology", "remove_unreferenced_vertices", "unique_pairs", "DerivedKey"]

_T = TypeVar("_T")

#: The keys of :meth:`Topology.cached`: data derived from the faces alone by the layers
#: above, built on first use and kept for the life of the topology.
#:
#: ===========================  ============================================================
#: key                          value
#: ===========================  ============================================================
#: ``"pattern.EE"``             :class:`~torch_edgevf.operators.patterns.EdgePairPattern`
#: ``"pattern.EV"``             :class:`~torch_edgevf.operators.patterns.EdgeVertexPattern`
#: ``"pattern.VV"``             :class:`~torch_edgevf.operators.patterns.VertexPairPattern`
#: ``"pattern.FE"``             :class:`~torch_edgevf.operators.patterns.Pattern`
#: ``"plan.laplace_beltrami"``  dict of index tensors (``operators.kernels.laplace_beltrami_plan``)
#: ``"fields.vertex_fans"``     tuple of index tensors, the vertex fans of ``fields.representation``
#: ===========================  ============================================================
#:
#: Nothing that depends on vertex positions is kept on a topology.
DerivedKey = Literal[
    "pattern.EE", "pattern.EV", "pattern.VV", "pattern.FE", "plan.laplace_beltrami", "fields.vertex_fans"
]

_NEXT = np.array([1, 2, 0])
_PREV = np.array([2, 0, 1])


class Topology:
    """Edges, incidences, orientation signs, boundary and components of a triangle mesh.

    Parameters
    ----------
    faces : (F, 3) integer tensor or array
        Counter-clockwise triangles. Never modified.
    num_vertices : int, optional
        Number of vertices ``V``. Defaults to ``faces.max() + 1``; pass ``verts.shape[0]``
        when the mesh may have unreferenced vertices at the end.

    Raises
    ------
    ValueError
        For an empty mesh, wrong shapes or dtypes, negative, out-of-range or repeated indices
        in a face, duplicated faces, non-manifold edges or vertices, and inconsistent
        orientation; the message names the offending faces, edges or vertices.

    Attributes
    ----------
    faces : (F, 3) int64 tensor
    edges : (E, 2) int64 tensor, ``edges[:, 0] < edges[:, 1]``, lexicographically sorted
    face_edges : (F, 3) int64 tensor, the edge opposite each corner
    face_edge_signs : (F, 3) int64 tensor of +-1, the sign delta of that edge in the face
    edge_faces : (E, 2) int64 tensor, see the module docstring
    edge_corners : (E, 2) int64 tensor, the corner of ``edge_faces`` opposite the edge, or -1
    boundary_edges : (E,) bool tensor
    boundary_vertices : (V,) bool tensor
    unreferenced_vertices : (U,) int64 tensor
    components : (V,) int64 tensor, connected-component label per vertex (-1 if unreferenced)
    num_components : int
    euler_characteristic : int, ``V_referenced - E + F``
    """

    def __init__(self, faces, num_vertices: int | None = None):
        faces = as_faces(faces)
        f = faces.detach().cpu().numpy()
        nf = f.shape[0]
        nv = _check_indices(f, num_vertices)
        it = _work_dtype(nv, nf)
        fi = f.astype(it)

        # the half-edge opposite each corner c = 3 f + k runs from corner k + 1 to k + 2;
        # sorted by (edge, side), side 1 for a run from the higher to the lower index
        src, dst = fi[:, _NEXT].ravel(), fi[:, _PREV].ravel()
        negative = src > dst
        keys, side, corner = _sorted_half_edges(src, dst, negative, nv, it)
        del src, dst
        nc = keys.shape[0]
        new = np.empty(nc, dtype=bool)
        new[0] = True
        np.not_equal(keys[1:], keys[:-1], out=new[1:])
        face_edges = np.empty(nc, dtype=it)
        across = np.empty(nc, dtype=it)  # the corner across the edge opposite each corner, -1 if none
        first, second = corner[0::2], corner[1::2]
        if (
            nc % 2 == 0
            and new[0::2].all()
            and not new[1::2].any()
            and not side[0::2].any()
            and side[1::2].all()
        ):  # closed, manifold edges, consistently oriented: the two sides of every edge in turn
            ne = nc // 2
            edge_keys = keys[0::2]
            side_corner = corner.reshape(ne, 2)
            ids = np.arange(ne, dtype=it)
            face_edges[first] = ids
            face_edges[second] = ids
            across[first] = second
            across[second] = first
            del ids
        else:
            ids = np.cumsum(new, dtype=it)
            ids -= 1
            ne = int(ids[-1]) + 1
            edge_keys = keys[new]
            slot = ids * 2
            slot += side
            if (slot[1:] == slot[:-1]).any():  # a side used twice: duplicate, non-manifold or flipped
                _check_duplicate_faces(f)  # the clearer message when that is the cause
                edges = _edges_of(edge_keys, nv)
                fe = np.empty(nc, dtype=it)
                fe[corner] = ids
                sided = np.bincount(slot, minlength=2 * ne)
                counts = sided[0::2] + sided[1::2]
                if counts.max() > 2:
                    _check_manifold_edges(edges, fe.reshape(nf, 3), counts)
                _check_orientation(edges, fe.reshape(nf, 3), sided)
            side_corner = np.full(2 * ne, -1, dtype=it)
            side_corner[slot] = corner
            face_edges[corner] = ids
            across[corner] = side_corner[slot ^ 1]
            side_corner = side_corner.reshape(ne, 2)
            del ids, slot
        del keys, side, corner, new, first, second
        count = _check_manifold_vertices(fi, nv, across)
        del across

        boundary_edges = side_corner[:, 0] < 0
        boundary_edges |= side_corner[:, 1] < 0
        boundary_vertices = np.zeros(nv, dtype=bool)
        if boundary_edges.any():
            boundary_vertices[_edges_of(edge_keys[boundary_edges], nv).ravel()] = True
        referenced = count > 0

        self.num_vertices = int(nv)
        self.num_edges = int(ne)
        self.num_faces = int(nf)
        # Compact working arrays (int32 where they fit); the int64 tensors of the public
        # attributes are made from them on first use.
        self._faces = fi  # a copy: later edits of the caller's faces are not seen
        self._edge_keys = edge_keys
        self._face_edges = face_edges.reshape(nf, 3)
        self._negative = negative.reshape(nf, 3)
        self._side_corners = side_corner
        self.boundary_edges = torch.from_numpy(boundary_edges)
        self.boundary_vertices = torch.from_numpy(boundary_vertices)
        self.unreferenced_vertices = torch.from_numpy(np.flatnonzero(~referenced))
        self.euler_characteristic = int(referenced.sum()) - int(ne) + int(nf)
        self._referenced = referenced
        self._derived: dict[DerivedKey, object] = {}

    # The int64 index tensors, made on first use (a first assembly of L_c needs none of them).

    @cached_property
    def faces(self) -> torch.Tensor:
        """(F, 3) int64 tensor: the counter-clockwise triangles (a copy of the input)."""
        return torch.from_numpy(self._faces.astype(np.int64))

    @cached_property
    def edges(self) -> torch.Tensor:
        """(E, 2) int64 tensor, ``edges[:, 0] < edges[:, 1]``, lexicographically sorted."""
        return torch.from_numpy(_edges_of(self._edge_keys, self.num_vertices))

    @cached_property
    def face_edges(self) -> torch.Tensor:
        """(F, 3) int64 tensor: the edge opposite each corner."""
        return torch.from_numpy(self._face_edges.astype(np.int64))

    @cached_property
    def face_edge_signs(self) -> torch.Tensor:
        """(F, 3) int64 tensor of +-1: the sign delta of the edge opposite each corner."""
        return torch.from_numpy(1 - 2 * self._negative.astype(np.int64))

    @cached_property
    def edge_faces(self) -> torch.Tensor:
        """(E, 2) int64 tensor: the face on each side of every edge, -1 if none (module docstring)."""
        return torch.from_numpy(self._side_corners // 3).to(torch.int64)  # -1 // 3 == -1

    @cached_property
    def edge_corners(self) -> torch.Tensor:
        """(E, 2) int64 tensor: the corner of ``edge_faces`` opposite the edge, -1 if none."""
        sc = self._side_corners
        return torch.from_numpy(np.where(sc >= 0, sc % 3, -1).astype(np.int64))

    def compact_faces(self) -> np.ndarray:
        """(F, 3) int array: :attr:`faces`, int32 where the mesh allows, else int64; do not modify."""
        return self._faces

    def compact_face_edges(self) -> np.ndarray:
        """(F, 3) int array: :attr:`face_edges`, int32 where the mesh allows, else int64; do not modify."""
        return self._face_edges

    def side_corners(self) -> np.ndarray:
        """(E, 2) int array: the corner ``3 f + k`` opposite each side of every edge, -1 if none.

        Side 0 is the face of ``edge_faces[:, 0]``, side 1 that of ``edge_faces[:, 1]``.
        int32 where the mesh allows, else int64; do not modify.
        """
        return self._side_corners

    def edge_faces_t(self) -> torch.Tensor:
        """(2, E) contiguous index tensor: ``edge_faces.t()``, int32 where the mesh allows (cached)."""
        return self._edge_faces_t

    @cached_property
    def _edge_faces_t(self) -> torch.Tensor:
        return torch.from_numpy(np.ascontiguousarray(self._side_corners.T // 3))

    def corner_vertices(self) -> torch.Tensor:
        """(3, F) contiguous index tensor: ``faces.t()``, int32 where the mesh allows (cached)."""
        return self._corner_vertices

    @cached_property
    def _corner_vertices(self) -> torch.Tensor:
        return torch.from_numpy(np.ascontiguousarray(self._faces.T))

    def edge_ends(self) -> torch.Tensor:
        """(2, 3, F) contiguous index tensor: the vertex at the head (``[0]``, corner ``k + 2``)
        and at the tail (``[1]``, corner ``k + 1``) of the edge opposite corner ``k`` of every
        face, int32 where the mesh allows (cached)."""
        return self._edge_ends

    @cached_property
    def _edge_ends(self) -> torch.Tensor:
        ft = self._faces.T
        return torch.from_numpy(np.stack([ft[[2, 0, 1]], ft[[1, 2, 0]]]))

    @property
    def components(self) -> torch.Tensor:
        """(V,) int64 connected-component label per vertex, ``-1`` if unreferenced (computed on first use)."""
        return self._components[0]

    @property
    def num_components(self) -> int:
        """Number of connected components (computed on first use)."""
        return self._components[1]

    @cached_property
    def _components(self) -> tuple[torch.Tensor, int]:
        nv, ne = self.num_vertices, self.num_edges
        edges = self.edges.numpy()
        graph = sp.coo_matrix((np.ones(ne), (edges[:, 0], edges[:, 1])), shape=(nv, nv))
        _, labels = connected_components(graph, directed=False)
        referenced = self._referenced
        labels = np.where(referenced, labels, -1)
        _, labels[referenced] = np.unique(labels[referenced], return_inverse=True)
        return torch.from_numpy(labels.astype(np.int64)), int(labels.max()) + 1

    @property
    def is_closed(self) -> bool:
        """True when the mesh has no boundary edge."""
        return not bool(self.boundary_edges.any())

    @property
    def num_boundary_edges(self) -> int:
        return int(self.boundary_edges.sum())

    def require_closed(self, what: str = "this operation") -> None:
        """Raise ``ValueError`` if the mesh has a boundary."""
        if not self.is_closed:
            bad = torch.nonzero(self.boundary_edges).flatten().tolist()
            pairs = [tuple(self.edges[e].tolist()) for e in bad[:10]]
            raise ValueError(
                f"{what} requires a closed mesh, but it has {len(bad)} boundary edges, "
                f"e.g. vertex pairs {list_some(pairs)}"
            )

    def summary(self) -> dict:
        """Counts and invariants as a plain dict (for printing and logging)."""
        return {
            "vertices": self.num_vertices,
            "edges": self.num_edges,
            "faces": self.num_faces,
            "boundary_edges": self.num_boundary_edges,
            "unreferenced_vertices": int(self.unreferenced_vertices.numel()),
            "components": self.num_components,
            "euler_characteristic": self.euler_characteristic,
        }

    def __repr__(self) -> str:
        items = ", ".join(f"{k}={v}" for k, v in self.summary().items())
        return f"Topology({items})"

    def cached(self, key: DerivedKey, build: Callable[[], _T]) -> _T:
        """The derived data ``key`` (see :data:`DerivedKey`), computed with ``build()`` the first time.

        For the layers above: data that depends on the faces alone (sparsity patterns,
        assembly plans), so that re-assembly for new positions needs no sort.
        """
        if key not in self._derived:
            self._derived[key] = build()
        return self._derived[key]  # type: ignore[return-value]


def remove_unreferenced_vertices(
    verts: torch.Tensor, faces
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Drop vertices that no face references.

    Returns
    -------
    verts : (V', 3) tensor, a new tensor (gradients flow back to the input)
    faces : (F, 3) int64 tensor, re-indexed
    kept : (V',) int64 tensor, the original index of each kept vertex
    """
    faces = as_faces(faces)
    used = torch.zeros(verts.shape[0], dtype=torch.bool, device=faces.device)
    used[faces.flatten()] = True
    kept = torch.nonzero(used).flatten()
    new_index = torch.full((verts.shape[0],), -1, dtype=torch.int64, device=faces.device)
    new_index[kept] = torch.arange(kept.numel(), device=faces.device)
    return verts[kept.to(verts.device)], new_index[faces], kept


def _work_dtype(nv: int, nf: int):
    """int32 work arrays where every index fits (half the memory traffic of int64), else int64."""
    return np.int32 if max(nv, 6 * nf + 2) < 2**31 - 1 else np.int64


def _edges_of(keys: np.ndarray, nv: int) -> np.ndarray:
    """(K, 2) int64 vertex pairs ``(i, j)`` of edge keys ``i * nv + j``."""
    edges = np.empty((keys.shape[0], 2), dtype=np.int64)
    np.floor_divide(keys, nv, out=edges[:, 0])
    np.subtract(keys, edges[:, 0] * nv, out=edges[:, 1])
    return edges


def _check_indices(f: np.ndarray, num_vertices: int | None) -> int:
    nv = int(f.max()) + 1 if num_vertices is None else int(num_vertices)
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])
    if f.min() >= 0 and f.max() < nv and not repeated.any():
        return nv
    bad = np.flatnonzero((f < 0).any(axis=1))
    if bad.size:
        raise ValueError(f"faces has negative vertex indices in faces [{list_some(bad)}]")
    nv = int(f.max()) + 1 if num_vertices is None else int(num_vertices)
    bad = np.flatnonzero((f >= nv).any(axis=1))
    if bad.size:
        raise ValueError(
            f"faces has out-of-range vertex indices (>= {nv} vertices) in faces [{list_some(bad)}]"
        )
    bad = np.flatnonzero((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0]))
    if bad.size:
        raise ValueError(f"faces repeat a vertex index within a face at faces [{list_some(bad)}]")
    return nv


def _check_duplicate_faces(f: np.ndarray) -> None:
    key = np.sort(f, axis=1).astype(np.int64, copy=False)
    n = int(key.max()) + 1
    if n < 2**21:  # fast path: one int64 key per face
        packed = np.sort((key[:, 0] * n + key[:, 1]) * n + key[:, 2])
        if not (packed[1:] == packed[:-1]).any():
            return
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    if (counts > 1).any():
        dup_keys = key[first[counts > 1]]
        groups = []
        for k in dup_keys[:10]:
            groups.append(np.flatnonzero((key == k).all(axis=1)).tolist())
        raise ValueError(
            f"faces has {int((counts > 1).sum())} duplicated faces (same three vertices); "
            f"duplicate groups of face indices: {list_some(groups)}"
        )


def _faces_of_edges(face_edges: np.ndarray, bad_edges: np.ndarray) -> list:
    rows = np.flatnonzero(np.isin(face_edges, bad_edges).any(axis=1))
    return rows.tolist()


def _check_manifold_edges(edges, face_edges, counts) -> None:
    bad = np.flatnonzero(counts > 2)
    if bad.size:
        pairs = [tuple(edges[e].tolist()) for e in bad[:10]]
        raise ValueError(
            f"non-manifold edges (shared by 3 or more faces): vertex pairs {list_some(pairs)}"
            f"{'' if bad.size <= 10 else f' ({bad.size} in all)'}; faces involved "
            f"[{list_some(_faces_of_edges(face_edges, bad))}]"
        )


def _check_orientation(edges, face_edges, sided) -> None:
    bad = np.flatnonzero((sided.reshape(-1, 2) > 1).any(axis=1))
    if bad.size:
        pairs = [tuple(edges[e].tolist()) for e in bad[:10]]
        raise ValueError(
            "inconsistent face orientation: two faces traverse the same edge in the same "
            f"direction at vertex pairs {list_some(pairs)}"
            f"{'' if bad.size <= 10 else f' ({bad.size} in all)'}; faces involved "
            f"[{list_some(_faces_of_edges(face_edges, bad))}]"
        )


def _check_manifold_vertices(f, nv, across) -> np.ndarray:
    """Every vertex's faces must form a single fan (connected through shared edges).

    The corners around a vertex are linked by ``next``: from corner ``k`` of a face, across
    the edge leaving the vertex (opposite corner ``k + 2``), to the corner at the same vertex
    in the neighbouring face. A fan is a cycle (closed) or a chain (ending at the boundary).
    From one corner per vertex, walk forward (and, on a chain, backward) and count the
    corners reached: a single fan reaches all of them. Each step advances every vertex that
    is still walking, so the loop runs at most (largest valence) times on shrinking arrays;
    the pairing is injective here (manifold edges, consistent orientation checked before).

    A closed fan of two faces means both faces have the same three vertices: a duplicated
    face (with flipped orientation, the other case is caught as an orientation error).

    Returns the number of corners at each vertex.
    """
    it = across.dtype
    nc = 3 * f.shape[0]
    # the corner across the edge opposite each corner (-1 on the boundary), ...
    nxt = across.reshape(-1, 3)[:, _PREV].ravel()
    del across
    walled = nxt < 0
    nxt += np.where(nxt % 3 == 0, 2, -1).astype(it)
    nxt[walled] = -1
    vertex = f.ravel()
    count = np.bincount(vertex, minlength=nv)
    start = np.full(nv, -1, dtype=it)
    start[vertex] = np.arange(nc, dtype=it)  # one corner per referenced vertex
    vs = np.flatnonzero(start >= 0)
    c0 = start[vs]
    reached = np.ones(vs.shape[0], dtype=it)
    limit = int(count.max())
    # forward; the walks that fall off a boundary (chains) then walk backward from c0
    idx, cur = np.arange(vs.shape[0], dtype=it), nxt[c0]
    chains = []
    for _ in range(limit):
        ended = cur < 0
        if ended.any():
            chains.append(idx[ended])
        alive = ~ended & (cur != c0[idx])
        idx, cur = idx[alive], cur[alive]
        if not idx.size:
            break
        reached[idx] += 1
        cur = nxt[cur]
    chain = np.concatenate(chains) if chains else np.zeros(0, dtype=it)
    if chain.size:
        has_next = ~walled
        prv = np.full(nc, -1, dtype=it)
        prv[nxt[has_next]] = np.flatnonzero(has_next)
        idx, cur = chain, prv[c0[chain]]
        for _ in range(limit):
            alive = cur >= 0
            idx, cur = idx[alive], cur[alive]
            if not idx.size:
                break
            reached[idx] += 1
            cur = prv[cur]
    bad = vs[reached != count[vs]]
    if bad.size:
        _check_duplicate_faces(f)  # the clearer message when that is the cause
        raise ValueError(
            f"non-manifold vertices (their faces form several fans): vertices [{list_some(bad)}]"
        )
    pillow = count[vs] == 2
    pillow[chain] = False
    if pillow.any():
        _check_duplicate_faces(f)
    return count


def _sorted_half_edges(src, dst, negative, nv: int, it) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The half-edges ``src -> dst`` sorted by edge key ``min * nv + max``, then side, then corner.

    Returns ``(keys int64, side bool, corner it)`` in sorted order; ``side`` is ``negative``
    (a run from the higher to the lower index). When they fit, key, side and corner are
    packed into one int64 so that a plain in-place sort, cheaper than an argsort, gives all
    three.
    """
    n = src.shape[0]
    keys = np.minimum(src, dst).astype(np.int64)
    keys *= nv
    keys += np.maximum(src, dst)
    keys <<= 1
    keys |= negative
    shift = max(int(n - 1).bit_length(), 1)
    if nv * nv * 2 <= 2 ** (63 - shift):
        keys <<= shift
        keys |= np.arange(n, dtype=np.int64)
        keys.sort()
        corner = (keys & ((1 << shift) - 1)).astype(it)
        keys >>= shift
    else:
        order = np.argsort(keys, kind="stable")
        keys = keys[order]
        corner = order.astype(it)
    side = (keys & 1).astype(bool)
    keys >>= 1
    return keys, side, corner


def unique_pairs(
    lo: np.ndarray, hi: np.ndarray, nv: int, num_lo: int | None = None, index_dtype=np.int64
) -> tuple[np.ndarray, np.ndarray]:
    """Sorted unique keys ``lo * nv + hi`` of integer pairs and the index of each pair's key.

    ``0 <= hi < nv`` and ``0 <= lo < num_lo`` (default ``nv``). The keys are int64; the
    indices have ``index_dtype``.

    When they fit, the key and the pair's position are packed into one int64 so that
    a plain in-place sort, cheaper than an argsort, gives both the order and the keys.
    """
    keys = np.asarray(lo).astype(np.int64)  # a copy: worked on in place below
    keys *= nv
    keys += np.asarray(hi)
    n = keys.shape[0]
    if n == 0:
        return keys, np.zeros(0, dtype=index_dtype)
    shift = max(int(n - 1).bit_length(), 1)
    if (nv if num_lo is None else num_lo) * nv <= 2 ** (63 - shift):
        keys <<= shift
        keys |= np.arange(n, dtype=np.int64)
        keys.sort()
        order = keys & ((1 << shift) - 1)
        keys >>= shift
    else:
        order = np.argsort(keys)
        keys = keys[order]
    new = np.empty(n, dtype=bool)
    new[0] = True
    np.not_equal(keys[1:], keys[:-1], out=new[1:])
    ids = np.cumsum(new, dtype=index_dtype)
    ids -= 1
    inverse = np.empty(n, dtype=index_dtype)
    inverse[order] = ids
    return keys[new], inverse
