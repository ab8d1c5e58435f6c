"""Fixed sparsity patterns: sort once per topology, then assemble by one scatter.

An operator is a sum of per-face (or per-edge) contributions at known ``(row, col)``
positions. :class:`Pattern` coalesces those positions once; re-assembly for new vertex
positions is then a gather of the first contribution of every nonzero and one
``index_add`` of the remaining ones into the ``nnz`` values of a coalesced sparse COO
tensor, with no sort, and autograd flows through it.
"""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["Pattern", "EdgePairPattern", "sparse_coo", "diagonal", "unique_pairs"]


def sparse_coo(indices: torch.Tensor, values: torch.Tensor, shape) -> torch.Tensor:
    """A coalesced COO tensor from already sorted, unique ``indices``.

    With autograd, the backward to ``values`` reads the gradient on the pattern
    (:func:`torch_edgevf.linalg.sparse_matrix`) instead of torch's ``sparse_mask``.
    """
    if values.requires_grad and torch.is_grad_enabled():
        from .linalg._utils import _SparseMatrix

        return _SparseMatrix.apply(indices, values, (int(shape[0]), int(shape[1])))
    return torch.sparse_coo_tensor(
        indices, values, tuple(shape), is_coalesced=True, check_invariants=False
    )


def diagonal(values: torch.Tensor) -> torch.Tensor:
    """The ``(N, N)`` sparse diagonal matrix with the given ``(N,)`` values."""
    idx = torch.arange(values.shape[0], device=values.device)
    return sparse_coo(torch.stack([idx, idx]), values, (values.shape[0], values.shape[0]))


class _OnDevice:
    """Index tensors kept on the CPU and copied once to each other device they are used on."""

    def _host(self) -> tuple[torch.Tensor, ...]:
        raise NotImplementedError

    def _tensors(self, device) -> tuple[torch.Tensor, ...]:
        device = torch.device(device)
        if device.type == "cpu":
            return self._host()
        cache = self.__dict__.setdefault("_on_device", {})
        if device not in cache:
            cache[device] = tuple(t.to(device) for t in self._host())
        return cache[device]


class Pattern(_OnDevice):
    """The coalesced sparsity pattern of a sum of contributions.

    Parameters
    ----------
    rows, cols : (C,) int arrays
        Position of each contribution; repeated positions are summed.
    shape : (int, int)
    """

    def __init__(self, rows, cols, shape):
        rows = np.asarray(rows, dtype=np.int64).ravel()
        cols = np.asarray(cols, dtype=np.int64).ravel()
        self.shape = (int(shape[0]), int(shape[1]))
        unique, target = unique_pairs(rows, cols, self.shape[1], self.shape[0])
        self.nnz = int(unique.shape[0])
        self.num_contributions = int(rows.shape[0])
        index = _index_dtype(self.num_contributions)
        row = unique // self.shape[1]
        self._indices = torch.from_numpy(np.stack([row, unique - row * self.shape[1]]))
        # assembly = gather the first contribution of every nonzero, then add the others
        first = np.empty(self.nnz, dtype=np.int64)
        first[target] = np.arange(self.num_contributions)  # one contribution per nonzero, whichever
        rest = np.ones(self.num_contributions, dtype=bool)
        rest[first] = False
        self._first = torch.from_numpy(first.astype(index))
        self._rest_src = torch.from_numpy(np.flatnonzero(rest).astype(index))
        self._rest_dst = torch.from_numpy(target[rest].astype(index))

    def _host(self) -> tuple[torch.Tensor, ...]:
        return (self._indices, self._first, self._rest_src, self._rest_dst)

    @property
    def indices(self) -> torch.Tensor:
        """(2, nnz) int64 row and column indices, sorted lexicographically."""
        return self._indices

    def assemble(self, values: torch.Tensor) -> torch.Tensor:
        """Sum ``values`` (one per contribution) into a coalesced sparse COO tensor."""
        if values.shape[0] != self.num_contributions:
            raise ValueError(
                f"expected {self.num_contributions} contributions, got {values.shape[0]}"
            )
        indices, first, rest_src, rest_dst = self._tensors(values.device)
        out = values.index_select(0, first)
        if rest_src.numel():
            out = out.index_add(0, rest_dst, values.index_select(0, rest_src))
        return sparse_coo(indices, out, self.shape)


def unique_pairs(lo: np.ndarray, hi: np.ndarray, nv: int, num_lo: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Sorted unique keys ``lo * nv + hi`` of integer pairs and the index of each pair's key.

    ``0 <= hi < nv`` and ``0 <= lo < num_lo`` (default ``nv``).

    When they fit, the key and the pair's position are packed into one int64 so that
    a plain sort (about 3x faster than an argsort) gives both the order and the keys.
    """
    keys = np.asarray(lo, dtype=np.int64) * nv + np.asarray(hi, dtype=np.int64)
    n = keys.shape[0]
    if n == 0:
        return keys, np.zeros(0, dtype=np.int64)
    shift = max(int(n - 1).bit_length(), 1)
    if (nv if num_lo is None else num_lo) * nv <= 2 ** (63 - shift):
        packed = np.sort((keys << shift) | np.arange(n))
        order = packed & ((1 << shift) - 1)
        sorted_keys = packed >> shift
    else:
        order = np.argsort(keys)
        sorted_keys = keys[order]
    new = np.empty(n, dtype=bool)
    new[0] = True
    np.not_equal(sorted_keys[1:], sorted_keys[:-1], out=new[1:])
    starts = np.flatnonzero(new)
    inverse = np.empty(n, dtype=np.int64)
    inverse[order] = np.repeat(np.arange(starts.shape[0]), np.diff(starts, append=n))
    return sorted_keys[starts], inverse


def _index_dtype(size: int):
    """int32 indices where they fit (half the memory of int64), else int64."""
    return np.int32 if size < 2**31 - 1 else np.int64


_NEXT = np.array([1, 2, 0])
_PREV = np.array([2, 0, 1])
_SORT5 = ((0, 1), (3, 4), (2, 4), (2, 3), (0, 3), (0, 2), (1, 4), (1, 3), (1, 2))


class EdgePairPattern(_OnDevice):
    """The ``(E, E)`` pattern of operators coupling the edges of each face, filled by gathers.

    Row ``e`` holds the diagonal and the two other edges of each face of ``e``; on a
    manifold mesh every off-diagonal nonzero comes from exactly one face. Values are given
    corner-major, as ``(3, F)`` tensors: ``diag[k, f]`` at the edge opposite corner ``k``
    (summed over the faces of the edge), ``upper[j, f]`` at (edge opposite corner ``j``,
    edge opposite corner ``j + 1``) and ``lower[j, f]`` at the transposed position.
    Assembly is two gathers for the diagonal and one into sorted COO order: no scatter,
    no sort.

    Parameters
    ----------
    face_edges : (F, 3) int array
    edge_faces, edge_corners : (E, 2) int arrays, -1 where there is no face
    """

    def __init__(self, face_edges, edge_faces, edge_corners):
        fe = np.asarray(face_edges, dtype=np.int64)
        ef = np.asarray(edge_faces, dtype=np.int64)
        ec = np.asarray(edge_corners, dtype=np.int64)
        ne, nf = ef.shape[0], fe.shape[0]
        if ne + 6 * nf >= 2**32:
            raise ValueError(f"mesh too large for EdgePairPattern: {ne} edges and {nf} faces")
        self.shape = (ne, ne)
        index = _index_dtype(ne + 6 * nf)
        closed = bool((ef >= 0).all())
        flat_fe = fe.ravel()
        # slot s of row e holds column cols[s][e], whose value comes from src[s][e]
        cols, src = [np.arange(ne)], [np.arange(ne)]
        for side in (0, 1):
            g, k = ef[:, side], ec[:, side]
            nxt, prv = _NEXT[k], _PREV[k]
            # (k, k+1) is upper[k, g]; (k, k+2) is the transpose of upper[k+2, g]
            cols += [flat_fe[3 * g + nxt], flat_fe[3 * g + prv]]
            src += [ne + k * nf + g, ne + 3 * nf + prv * nf + g]
            if not closed:
                missing = g < 0
                cols[-1][missing] = cols[-2][missing] = ne  # the sentinel ne sorts last
                src[-1][missing] = src[-2][missing] = 0
        # sort each row by column: a 9-comparator sorting network on keys (column << 32) | source
        keys = [(c << 32) | s for c, s in zip(cols, src)]
        for i, j in _SORT5:
            keys[i], keys[j] = np.minimum(keys[i], keys[j]), np.maximum(keys[i], keys[j])
        keys = np.stack(keys, axis=1).ravel()  # row-major (E, 5) = COO order
        cols = keys >> 32
        src = keys & 0xFFFFFFFF
        rows = np.repeat(np.arange(ne), 5)
        if not closed:
            valid = cols < ne
            rows, cols, src = rows[valid], cols[valid], src[valid]
        self.nnz = int(rows.shape[0])
        self._indices = torch.from_numpy(np.stack([rows, cols]))
        self._gather = torch.from_numpy(src.astype(index))
        # diagonal: the (corner, face) of each side of every edge in the flat (3F,) layout, 3F if none
        diag_src = np.where(ef >= 0, ec * nf + ef, 3 * nf).T
        self._diag = tuple(torch.from_numpy(np.ascontiguousarray(d).astype(index)) for d in diag_src)

    @property
    def indices(self) -> torch.Tensor:
        """(2, nnz) int64 row and column indices, sorted lexicographically."""
        return self._indices

    def _host(self) -> tuple[torch.Tensor, ...]:
        return (self._indices, self._gather) + self._diag

    def assemble(self, diag: torch.Tensor, upper: torch.Tensor, lower: torch.Tensor) -> torch.Tensor:
        """Sparse COO from corner-major ``(3, F)`` diagonal, upper and lower face terms."""
        indices, gather, side0, side1 = self._tensors(upper.device)
        dtype = torch.promote_types(torch.promote_types(diag.dtype, upper.dtype), lower.dtype)
        flat = torch.cat([diag.reshape(-1), diag.new_zeros(1)]).to(dtype)
        on_diag = flat.index_select(0, side0) + flat.index_select(0, side1)
        values = torch.cat([on_diag, upper.reshape(-1).to(dtype), lower.reshape(-1).to(dtype)])
        return sparse_coo(indices, values.index_select(0, gather), self.shape)

    def assemble_pairs(self, values: torch.Tensor) -> torch.Tensor:
        """Sparse COO from ``(F, 9)`` per-face values of the ordered corner pairs (row-major ``3a + b``)."""
        v = values.reshape(-1, 3, 3).permute(1, 2, 0)  # (a, b, F)
        k = [0, 1, 2]
        return self.assemble(v[k, k], v[k, [1, 2, 0]], v[[1, 2, 0], k])
