"""Fixed sparsity patterns: sort once per topology, then assemble by one scatter.

An operator is a sum of per-face (or per-edge) contributions at known ``(row, col)``
positions. :class:`Pattern` coalesces those positions once; re-assembly for new vertex
positions is then a gather of the first contribution of every nonzero and one
``index_add`` of the remaining ones into the ``nnz`` values of a coalesced sparse COO
tensor, with no sort, and autograd flows through it.
"""

from __future__ import annotations

import functools
import sys

import numpy as np
import torch

from ..linalg import sparse_matrix
from ..mesh.geometry import face_blocks
from ..mesh.topology import unique_pairs

__all__ = [
    "Pattern",
    "EdgePairPattern",
    "EdgeVertexPattern",
    "VertexPairPattern",
    "sparse_coo",
    "diagonal",
    "symmetric_layout",
    "index_dtype",
]


def sparse_coo(indices: torch.Tensor, values: torch.Tensor, shape) -> torch.Tensor:
    """A coalesced COO tensor from already sorted, unique ``indices``.

    With autograd, the backward to ``values`` reads the gradient on the pattern
    (:func:`torch_edgevf.linalg.sparse_matrix`) instead of torch's ``sparse_mask``.
    """
    if values.requires_grad and torch.is_grad_enabled():
        return sparse_matrix(indices, values, (int(shape[0]), int(shape[1])), assume_sorted=True)
    return torch.sparse_coo_tensor(indices, values, tuple(shape), is_coalesced=True, check_invariants=False)


def diagonal(values: torch.Tensor) -> torch.Tensor:
    """The ``(N, N)`` sparse diagonal matrix with the given ``(N,)`` values."""
    idx = torch.arange(values.shape[0], device=values.device)
    return sparse_coo(torch.stack([idx, idx]), values, (values.shape[0], values.shape[0]))


class _OnDevice:
    """A fixed sparsity pattern: index tensors kept on the CPU and copied once to each other
    device they are used on."""

    _indices: torch.Tensor
    num_contributions: int

    @property
    def indices(self) -> torch.Tensor:
        """(2, nnz) int64 row and column indices, sorted lexicographically."""
        return self._indices

    def _check_contributions(self, values: torch.Tensor) -> None:
        if values.shape[0] != self.num_contributions:
            raise ValueError(f"expected {self.num_contributions} contributions, got {values.shape[0]}")

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
        index = index_dtype(self.num_contributions)
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

    def assemble(self, values: torch.Tensor) -> torch.Tensor:
        """Sum ``values`` (one per contribution) into a coalesced sparse COO tensor."""
        self._check_contributions(values)
        indices, first, rest_src, rest_dst = self._tensors(values.device)
        out = values.index_select(0, first)
        if rest_src.numel():
            out = out.index_add(0, rest_dst, values.index_select(0, rest_src))
        return sparse_coo(indices, out, self.shape)


def index_dtype(size: int):
    """int32 indices where they fit (half the memory of int64), else int64."""
    return np.int32 if size < 2**31 - 1 else np.int64


# Knuth's 9-comparator sorting network of 5 elements
_NETWORK_5 = ((0, 1), (3, 4), (2, 4), (2, 3), (1, 4), (0, 3), (0, 2), (1, 3), (1, 2))


def _sort_rows(keys: np.ndarray) -> None:
    """Sort ``keys[:, e]`` (5 rows) for every column ``e`` in place: 9 compare-exchanges of
    whole rows, much cheaper than ``np.sort(axis=0)`` on short columns."""
    low = np.empty_like(keys[0])
    for a, b in _NETWORK_5:
        np.minimum(keys[a], keys[b], out=low)
        np.maximum(keys[a], keys[b], out=keys[b])
        keys[a] = low


class EdgePairPattern(_OnDevice):
    """The ``(E, E)`` pattern of operators coupling the edges of each face, filled by gathers.

    Row ``e`` holds the diagonal and the two other edges of each face of ``e``; on a
    manifold mesh every off-diagonal nonzero comes from exactly one face. Values are given
    as the three ``(F,)`` columns of corner ``k`` (or ``(F, 3)`` tensors): ``diag[k]`` at the
    edge opposite corner ``k`` (summed over the faces of the edge), ``upper[k]`` at (edge
    opposite corner ``k``, edge opposite corner ``k + 1``) and ``lower[k]`` at the transposed
    position. Assembly is two gathers for the diagonal and one gather into sorted COO
    order: no scatter, no sort.

    Parameters
    ----------
    face_edges : (F, 3) int array
    side_corners : (E, 2) int array
        The corner ``3 f + k`` opposite each side of every edge (see
        :attr:`Topology.edge_faces`), ``-1`` where there is no face.
    """

    def __init__(self, face_edges, side_corners):
        flat_fe = np.ascontiguousarray(face_edges).ravel()
        sc = np.asarray(side_corners)
        ne, nf = sc.shape[0], flat_fe.shape[0] // 3
        if ne + 6 * nf >= 2**32:
            raise ValueError(f"mesh too large for EdgePairPattern: {ne} edges and {nf} faces")
        self.shape = (ne, ne)
        self._num_faces = nf
        self._closed = closed = bool((sc >= 0).all())
        i64 = np.int64
        # The values are numbered [diagonal (E) | upper (3 F) | lower (3 F)], the face terms
        # corner-major (k F + f). Row e holds (column << 32 | value number) keys: the diagonal
        # and, for each side, the next and the previous edge of its face; sorted, then split.
        keys = np.empty((5, ne), dtype=i64)
        np.multiply(np.arange(ne, dtype=i64), (1 << 32) | 1, out=keys[0])  # diagonal: (e, e)
        diag_src = []
        for side in (0, 1):
            c = sc[:, side].astype(i64)
            f, k = np.divmod(c, 3)
            if not closed:
                missing = c < 0
                c[missing] = f[missing] = k[missing] = 0
            base = 3 * f
            cm = k * nf
            cm += f  # corner-major number of the corner
            # the edges opposite corners k + 1 and k + 2 of the same face
            nxt = np.where(k == 2, base, c + 1)
            prv = np.where(k == 0, base + 2, c - 1)
            # (e_k, e_k+1) is upper[k] of the face; (e_k, e_k+2) is lower[k + 2]
            up, low = keys[1 + 2 * side], keys[2 + 2 * side]
            np.left_shift(flat_fe[nxt], 32, out=up, dtype=i64)
            up += cm
            up += ne
            k2 = np.where(k == 0, 2, k - 1)
            np.left_shift(flat_fe[prv], 32, out=low, dtype=i64)
            low += k2 * nf + f
            low += ne + 3 * nf
            if not closed:
                up[missing] = low[missing] = ne << 32  # sorts last
                cm[missing] = 3 * nf  # a zero
            diag_src.append(cm)
        del nxt, prv, f, k, k2, base, c
        _sort_rows(keys)
        index = index_dtype(ne + 6 * nf)
        indices = np.empty((2, 5 * ne), dtype=i64)
        indices[0].reshape(ne, 5)[:] = np.arange(ne)[:, None]
        np.right_shift(keys.T, 32, out=indices[1].reshape(ne, 5))
        if sys.byteorder == "little":  # the low halves of the keys, without a temporary
            gather = keys.view(np.uint32)[:, 0::2].T
        else:
            gather = (keys & 0xFFFFFFFF).T
        gather = gather.astype(index).ravel()  # row-major: the value of each nonzero
        del keys
        if not closed:
            valid = indices[1] < ne
            indices, gather = indices[:, valid], gather[valid]
        self.nnz = int(indices.shape[1])
        self._indices = torch.from_numpy(indices)
        self._gather = torch.from_numpy(gather)
        self._diag = tuple(torch.from_numpy(d.astype(index_dtype(3 * nf + 1))) for d in diag_src)

    def _host(self) -> tuple[torch.Tensor, ...]:
        return (self._indices, self._gather) + self._diag

    def assemble(self, diag, upper, lower=None) -> torch.Tensor:
        """Sparse COO from face diagonal, upper and lower terms.

        Each term is an ``(F, 3)`` tensor or a sequence of its three ``(F,)`` columns (corner
        ``k``). ``lower=None`` means ``conj(upper)``: a Hermitian operator (``upper`` itself
        for a real one).
        """

        def columns(t):
            return None if t is None else list(t) if isinstance(t, (list, tuple)) else list(t.unbind(1))

        diag_cols, up_cols, low_cols = columns(diag), columns(upper), columns(lower)
        pieces = [*diag_cols, *up_cols, *(low_cols or [])]
        dtype = functools.reduce(torch.promote_types, (p.dtype for p in pieces))
        device = pieces[0].device
        indices, gather, side0, side1 = self._tensors(device)
        ne, nf = self.shape[0], self._num_faces
        flat = torch.cat(diag_cols + ([] if self._closed else [diag_cols[0].new_zeros(1)]))
        on_diag = flat.index_select(0, side0) + flat.index_select(0, side1)
        if torch.is_grad_enabled() and any(p.requires_grad for p in pieces):
            up = torch.cat([c.to(dtype) for c in up_cols])
            low = up.conj() if low_cols is None else torch.cat([c.to(dtype) for c in low_cols])
            values = torch.cat([on_diag.to(dtype), up, low])
        else:  # one buffer, filled by contiguous copies: no concatenation, no conjugated copy
            values = torch.empty(ne + 6 * nf, dtype=dtype, device=device)
            values[:ne] = on_diag
            up, low = values[ne : ne + 3 * nf], values[ne + 3 * nf :]
            for cols, out in ((up_cols, up), (low_cols, low)):
                for k, col in enumerate(cols or []):
                    out[k * nf : (k + 1) * nf] = col
            if low_cols is None:
                if dtype.is_complex:
                    torch.conj_physical(up, out=low)
                else:
                    low.copy_(up)
        return sparse_coo(indices, values.index_select(0, gather), self.shape)

    def assemble_by_blocks(self, terms, dtype: torch.dtype) -> torch.Tensor:
        """:meth:`assemble` of a Hermitian operator whose face terms are computed block by block.

        ``terms(block)`` returns the diagonal and upper columns of the faces of ``block`` (a
        slice of :func:`~torch_edgevf.mesh.geometry.face_blocks`); they are written straight
        into the value buffer, so the temporaries of a block stay in the cache. CPU, without
        autograd.
        """
        indices, gather, side0, side1 = self._host()
        ne, nf = self.shape[0], self._num_faces
        real = dtype.to_real()
        values = torch.empty(ne + 6 * nf, dtype=dtype)
        face_diag = torch.zeros(3 * nf + (0 if self._closed else 1), dtype=real)
        up = values[ne : ne + 3 * nf]
        for block in face_blocks(nf):
            diag_cols, up_cols = terms(block)
            for k in range(3):
                face_diag[k * nf + block.start : k * nf + block.stop] = diag_cols[k]
                up[k * nf + block.start : k * nf + block.stop] = up_cols[k]
        values[:ne] = face_diag.index_select(0, side0) + face_diag.index_select(0, side1)
        low = values[ne + 3 * nf :]
        if dtype.is_complex:
            torch.conj_physical(up, out=low)
        else:
            low.copy_(up)
        return sparse_coo(indices, values.index_select(0, gather), self.shape)

    def assemble_pairs(self, values: torch.Tensor) -> torch.Tensor:
        """Sparse COO from ``(F, 9)`` per-face values of the ordered corner pairs (row-major ``3a + b``)."""
        v = values.reshape(-1, 9)
        # diag (k, k); upper (k, k+1); lower (k+1, k)
        return self.assemble(v[:, [0, 4, 8]], v[:, [1, 5, 6]], v[:, [3, 7, 2]])


def symmetric_layout(up_row: np.ndarray, up_col: np.ndarray, has_diag: np.ndarray, nv: int):
    """Sorted COO layout of a symmetric ``(V, V)`` pattern from its unique upper pairs.

    ``up_row < up_col`` must be sorted lexicographically. Returns ``(indices, gather)``: the
    ``(2, nnz)`` int64 indices, and for each nonzero its position in the value vector
    ``[diagonal (V) | upper (U) | lower (U)]``, where ``lower[u]`` is the value at the
    transpose of upper pair ``u``.
    """
    nu = up_row.shape[0]
    n_upper = np.bincount(up_row, minlength=nv)
    n_lower = np.bincount(up_col, minlength=nv)
    row_len = n_lower + has_diag + n_upper
    row_start = np.cumsum(row_len) - row_len
    nnz = int(row_len.sum())
    gather = np.empty(nnz, dtype=index_dtype(nv + 2 * nu))
    out_cols = np.empty(nnz, dtype=np.int64)
    diag = np.flatnonzero(has_diag)
    diag_pos = (row_start + n_lower)[diag]
    gather[diag_pos] = diag
    out_cols[diag_pos] = diag
    # upper entries, already sorted by (row, col): rank within the row
    first_upper = np.cumsum(n_upper) - n_upper
    rank = np.arange(nu) - first_upper[up_row]
    upper_pos = row_start[up_row] + n_lower[up_row] + has_diag[up_row] + rank
    gather[upper_pos] = nv + np.arange(nu)
    out_cols[upper_pos] = up_col
    del upper_pos, rank
    # lower entries (v, u), sorted by (v, u): a stable sort by v keeps u increasing
    order = np.argsort(up_col, kind="stable")
    lo_row = up_col[order]
    first_lower = np.cumsum(n_lower) - n_lower
    lower_pos = row_start[lo_row] + (np.arange(nu) - first_lower[lo_row])
    gather[lower_pos] = nv + nu + order
    out_cols[lower_pos] = up_row[order]
    indices = np.empty((2, nnz), dtype=np.int64)
    indices[0] = np.repeat(np.arange(nv), row_len)
    indices[1] = out_cols
    return indices, gather


def _first_and_rest(first: np.ndarray, second: np.ndarray, none: int, index):
    """Split "the sum of up to two sources per entry" (``none`` marks a missing one) into a
    gather of one source per entry and an add of the second ones: ``(first, rest_pos, rest_src)``."""
    first, second = first.ravel(), second.ravel()
    swap = first == none
    if swap.any():
        first = np.where(swap, second, first)
        second = np.where(swap, none, second)
    rest = np.flatnonzero(second != none)
    return tuple(torch.from_numpy(a.astype(index, copy=False)) for a in (first, rest, second[rest]))


def _gather_sum(values: torch.Tensor, first: torch.Tensor, rest_pos: torch.Tensor, rest_src: torch.Tensor):
    """``values[first]``, then ``values[rest_src]`` added at ``rest_pos``."""
    out = values.index_select(0, first)
    return out.index_add(0, rest_pos, values.index_select(0, rest_src)) if rest_pos.numel() else out


class EdgeVertexPattern(_OnDevice):
    """The ``(E, V)`` pattern of the gradient ``G``, filled by gathers (no scatter, no sort).

    Row ``e = (i, j)`` holds ``i``, ``j`` and the vertex opposite ``e`` in each of its faces.
    A face contributes ``values[p F + f]`` at ``(edge opposite corner a, vertex of corner b)``
    for the corner pair ``p = 3 a + b`` (pair-major, as :class:`Pattern` would take it): the
    endpoints sum one term from each face, the opposite vertices take one.

    Parameters
    ----------
    faces : (F, 3) int array
    edges : (E, 2) int array
    side_corners : (E, 2) int array, see :meth:`Topology.side_corners`
    num_vertices : int
    """

    def __init__(self, faces, edges, side_corners, num_vertices: int):
        flat_f = np.ascontiguousarray(faces).ravel()
        sc = np.asarray(side_corners)
        ne, nf, nv = sc.shape[0], flat_f.shape[0] // 3, int(num_vertices)
        self.shape = (ne, nv)
        none = 9 * nf  # marks a missing term
        it = np.int32 if none < 2**31 - 1 and sc.dtype == np.int32 else np.int64
        # slots of row e: i, j, and the vertices opposite e in its side-0 and side-1 faces
        keys = np.empty((ne, 4), dtype=np.int64)
        keys[:, :2] = edges
        first = np.empty((ne, 4), dtype=it)
        second = np.full((ne, 4), none, dtype=it)
        nxt_k, prv_k = np.array([1, 2, 0], dtype=it), np.array([2, 0, 1], dtype=it)
        for side in (0, 1):
            c = sc[:, side].astype(it)
            missing = c < 0
            k = c % 3
            base = c // 3 + 3 * nf * k  # pair (k, b) of face g is (3 k + b) F + g = base + b F
            to_self = base + k * nf
            to_next = base + nxt_k[k] * nf  # towards corner k + 1: i on side 0, j on side 1
            to_prev = base + prv_k[k] * nf
            opposite = flat_f[np.where(missing, 0, c)]
            if missing.any():
                to_self[missing] = to_next[missing] = to_prev[missing] = none
                opposite[missing] = nv  # sorts last and is dropped
            keys[:, 2 + side] = opposite
            if side == 0:
                first[:, 0], first[:, 1], first[:, 2] = to_next, to_prev, to_self
            else:
                second[:, 0], second[:, 1], first[:, 3] = to_prev, to_next, to_self
        keys <<= 2
        keys |= np.arange(4)  # sort each row by column, remember the slot
        keys.sort(axis=1)
        slot = (keys & 3).astype(np.intp)
        first = np.take_along_axis(first, slot, axis=1)
        second = np.take_along_axis(second, slot, axis=1)
        del slot
        indices = np.empty((2, 4 * ne), dtype=np.int64)
        np.right_shift(keys, 2, out=indices[1].reshape(ne, 4))
        del keys
        indices[0].reshape(ne, 4)[:] = np.arange(ne)[:, None]
        if not bool((sc >= 0).all()):
            valid = indices[1] < nv
            indices, first, second = indices[:, valid], first.ravel()[valid], second.ravel()[valid]
        self._indices = torch.from_numpy(indices)
        self._sources = _first_and_rest(first, second, none, index_dtype(9 * nf + 1))
        self.nnz = int(indices.shape[1])
        self.num_contributions = 9 * nf

    def _host(self) -> tuple[torch.Tensor, ...]:
        return (self._indices, *self._sources)

    def assemble(self, values: torch.Tensor) -> torch.Tensor:
        """Sparse COO from the ``(9 F,)`` pair-major face contributions."""
        self._check_contributions(values)
        indices, *sources = self._tensors(values.device)
        return sparse_coo(indices, _gather_sum(values, *sources), self.shape)


class VertexPairPattern(_OnDevice):
    """The symmetric ``(V, V)`` pattern of per-face vertex-pair operators (P1 mass, cotan).

    A face contributes ``values[9 f + 3 a + b]`` at (vertex of corner a, vertex of corner b)
    (face-major, as :class:`Pattern` would take it). The diagonal sums the corners at each
    vertex (one ``index_add``); every off-diagonal entry sums one term from each face of its
    edge (two gathers); one more gather puts them in sorted COO order. Takes the
    parameters of :class:`EdgeVertexPattern`.
    """

    def __init__(self, faces, edges, side_corners, num_vertices: int):
        f = np.ascontiguousarray(faces)
        sc = np.asarray(side_corners, dtype=np.int64)
        edges = np.asarray(edges, dtype=np.int64)
        nf, nv = f.shape[0], int(num_vertices)
        self.shape = (nv, nv)
        none = 9 * nf
        k, g = sc % 3, sc // 3
        nxt, prv = (k + 1) % 3, (k + 2) % 3

        def term(a, b):
            return np.where(sc >= 0, 9 * g + 3 * a + b, none)

        # side 0: corner k + 1 is i, k + 2 is j; side 1 the reverse
        ij, ji = term(nxt, prv), term(prv, nxt)
        index = index_dtype(9 * nf + 1)
        # [upper (i, j) | lower (j, i)] entries, each the sum of a term of each face
        self._pairs = _first_and_rest(
            np.concatenate([ij[:, 0], ji[:, 0]]), np.concatenate([ji[:, 1], ij[:, 1]]), none, index
        )
        corners = f.ravel()
        self._diag_rows = torch.from_numpy(corners.astype(index))
        corner = np.arange(3 * nf)
        self._diag_src = torch.from_numpy((9 * (corner // 3) + 4 * (corner % 3)).astype(index))  # pair (k, k)
        has_diag = np.bincount(corners, minlength=nv) > 0
        indices, gather = symmetric_layout(edges[:, 0], edges[:, 1], has_diag, nv)
        self._indices = torch.from_numpy(indices)
        self._gather = torch.from_numpy(gather)
        self.nnz = int(gather.shape[0])
        self.num_contributions = 9 * nf

    def _host(self) -> tuple[torch.Tensor, ...]:
        return (self._indices, self._gather, self._diag_rows, self._diag_src, *self._pairs)

    def assemble(self, values: torch.Tensor) -> torch.Tensor:
        """Sparse COO from the ``(9 F,)`` face-major pair contributions."""
        self._check_contributions(values)
        indices, gather, diag_rows, diag_src, *pairs = self._tensors(values.device)
        diag = values.new_zeros(self.shape[0]).index_add(0, diag_rows, values.index_select(0, diag_src))
        off = _gather_sum(values, *pairs)
        return sparse_coo(indices, torch.cat([diag, off]).index_select(0, gather), self.shape)
