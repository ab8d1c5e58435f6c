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

import numpy as np
import scipy.sparse as sp
import torch
from scipy.sparse.csgraph import connected_components

from ._sparse import unique_pairs
from ._validation import as_faces, list_some

__all__ = ["Topology", "remove_unreferenced_vertices"]

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

        src, dst = f[:, _NEXT], f[:, _PREV]  # the half-edge opposite each corner
        positive = src < dst
        lo, hi = np.minimum(src, dst).ravel(), np.maximum(src, dst).ravel()
        keys, face_edges = unique_pairs(lo, hi, nv)
        face_edges = face_edges.reshape(nf, 3)
        signs = np.where(positive, 1, -1)
        ne = keys.shape[0]
        edges = np.empty((ne, 2), dtype=np.int64)
        np.floor_divide(keys, nv, out=edges[:, 0])
        np.subtract(keys, edges[:, 0] * nv, out=edges[:, 1])

        counts = np.bincount(face_edges.ravel(), minlength=ne)
        if counts.max() > 2:
            _check_duplicate_faces(f)  # the clearer message when that is the cause
            _check_manifold_edges(edges, face_edges, counts)
        slot = (~positive).ravel().astype(np.int64)
        sided = np.bincount(face_edges.ravel() * 2 + slot, minlength=2 * ne)
        if sided.max() > 1:
            _check_duplicate_faces(f)
            _check_orientation(edges, face_edges, sided)

        # each side of every edge: (face, corner opposite the edge), -1 if there is none
        corner_side = 2 * face_edges.ravel() + slot
        side_corner = np.full(2 * ne, -1, dtype=np.int64)
        side_corner[corner_side] = np.arange(3 * nf)
        has_face = side_corner >= 0
        face_of_side = side_corner // 3
        edge_faces = np.where(has_face, face_of_side, -1).reshape(ne, 2)
        edge_corners = np.where(has_face, side_corner - 3 * face_of_side, -1).reshape(ne, 2)
        # the same vertex opposite both sides of an edge: a duplicated pair of faces
        opposite = f.ravel()[side_corner].reshape(ne, 2)
        if (has_face.reshape(ne, 2).all(axis=1) & (opposite[:, 0] == opposite[:, 1])).any():
            _check_duplicate_faces(f)
        _check_manifold_vertices(f, nv, side_corner, corner_side)

        boundary_edges = counts == 1
        boundary_vertices = np.zeros(nv, dtype=bool)
        boundary_vertices[edges[boundary_edges].ravel()] = True
        referenced = np.zeros(nv, dtype=bool)
        referenced[f.ravel()] = True

        self.num_vertices = int(nv)
        self.num_edges = int(ne)
        self.num_faces = int(nf)
        self.faces = torch.from_numpy(f.astype(np.int64, copy=True))
        self.edges = torch.from_numpy(edges)
        self.face_edges = torch.from_numpy(face_edges.astype(np.int64, copy=False))
        self.face_edge_signs = torch.from_numpy(signs.astype(np.int64, copy=False))
        self.edge_faces = torch.from_numpy(edge_faces)
        self.edge_corners = torch.from_numpy(edge_corners)
        self.boundary_edges = torch.from_numpy(boundary_edges)
        self.boundary_vertices = torch.from_numpy(boundary_vertices)
        self.unreferenced_vertices = torch.from_numpy(np.flatnonzero(~referenced))
        self.euler_characteristic = int(referenced.sum()) - int(ne) + int(nf)
        self._referenced = referenced
        self._cache: dict = {}

    @property
    def components(self) -> torch.Tensor:
        """(V,) int64 connected-component label per vertex, ``-1`` if unreferenced (computed on first use)."""
        return self._components()[0]

    @property
    def num_components(self) -> int:
        """Number of connected components (computed on first use)."""
        return self._components()[1]

    def _components(self) -> tuple[torch.Tensor, int]:
        def build():
            nv, ne = self.num_vertices, self.num_edges
            edges = self.edges.numpy()
            graph = sp.coo_matrix((np.ones(ne), (edges[:, 0], edges[:, 1])), shape=(nv, nv))
            _, labels = connected_components(graph, directed=False)
            referenced = self._referenced
            labels = np.where(referenced, labels, -1)
            _, labels[referenced] = np.unique(labels[referenced], return_inverse=True)
            return torch.from_numpy(labels.astype(np.int64)), int(labels.max()) + 1

        return self.cached("components", build)

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

    def cached(self, key, build):
        """Return ``self._cache[key]``, computing it with ``build()`` the first time."""
        if key not in self._cache:
            self._cache[key] = build()
        return self._cache[key]


def remove_unreferenced_vertices(verts: torch.Tensor, faces) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
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
    key = np.sort(f, axis=1)
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


def _check_manifold_vertices(f, nv, side_corner, corner_side) -> None:
    """Every vertex's faces must form a single fan (connected through shared edges).

    The corners around a vertex are linked by ``next``: from corner ``k`` of a face, across
    the edge leaving the vertex (opposite corner ``k + 2``), to the corner at the same vertex
    in the neighbouring face. A fan is a cycle (closed) or a chain (ending at the boundary).
    From one corner per vertex, walk forward (and, on a chain, backward) and count the
    corners reached: a single fan reaches all of them. Each step advances every vertex that
    is still walking, so the loop runs at most (largest valence) times on shrinking arrays;
    the pairing is injective here (manifold edges, consistent orientation checked before).
    """
    nc = 3 * f.shape[0]
    # corner k+2 of the same face; the edge opposite it leaves the vertex of corner k
    third = np.arange(nc).reshape(-1, 3)[:, _PREV].ravel()
    across = side_corner[corner_side[third] ^ 1]  # the corner across that edge, or -1
    nxt = np.where(across >= 0, third[across], -1)
    has_next = nxt >= 0
    prv = np.full(nc, -1, dtype=np.int64)
    prv[nxt[has_next]] = np.flatnonzero(has_next)
    vertex = f.ravel()
    count = np.bincount(vertex, minlength=nv)
    start = np.full(nv, -1, dtype=np.int64)
    start[vertex] = np.arange(nc)  # one corner per referenced vertex
    vs = np.flatnonzero(start >= 0)
    c0 = start[vs]
    reached = np.ones(vs.shape[0], dtype=np.int64)
    limit = int(count.max())
    # forward; the walks that fall off a boundary (chains) then walk backward from c0
    idx, cur = np.arange(vs.shape[0]), nxt[c0]
    chains = []
    for _ in range(limit):
        chains.append(idx[cur < 0])
        alive = (cur >= 0) & (cur != c0[idx])
        idx, cur = idx[alive], cur[alive]
        if not idx.size:
            break
        reached[idx] += 1
        cur = nxt[cur]
    idx = np.concatenate(chains)
    cur = prv[c0[idx]]
    for _ in range(limit):
        alive = cur >= 0
        idx, cur = idx[alive], cur[alive]
        if not idx.size:
            break
        reached[idx] += 1
        cur = prv[cur]
    bad = vs[reached != count[vs]]
    if bad.size:
        raise ValueError(
            f"non-manifold vertices (their faces form several fans): vertices [{list_some(bad)}]"
        )
