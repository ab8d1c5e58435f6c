r"""Eigenpairs of a pencil that splits into independent blocks: one solve per block.

A mesh cut into pieces (disjoint parts, or the components that repair leaves) gives
operators that are block diagonal up to a permutation: the spectrum of :math:`(A, M)` is
the union of the spectra of its blocks.  Identical pieces (the wheels and bolts of a
model) give every eigenvalue the multiplicity of the piece, and every piece contributes a
null vector to a vertex Laplacian; a block Lanczos finds at most as many copies of an
eigenvalue as its block has columns, so on the whole pencil it stalls.  Solved block by
block, every multiplicity across pieces disappears: each block gets its ``min(k, n_b)``
smallest pairs (Lanczos for a large block, a dense decomposition for a small one, small
blocks taken together), and the ``k`` smallest of all of them are returned, each vector
zero outside its block.

Blocks are the connected components of the graph of the nonzeros of :math:`A` and
:math:`M`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .shift_invert import dense_is_faster, eig_dense, shift_invert_eigsh

__all__ = ["blocks", "eigsh_by_blocks"]

#: blocks up to this size are solved dense, several at a time up to this many rows together
_SMALL = 300


def blocks(A: sp.spmatrix, M: sp.spmatrix) -> list[np.ndarray] | None:
    """The rows of each independent block of ``(A, M)`` (ascending), or ``None`` for one block.

    Blocks with no nonzero in ``M`` carry no eigenpair (rows of vertices that no face uses:
    zero in both matrices); they are left out.
    """
    n = A.shape[0]
    graph = (abs(sp.csr_matrix(A)) + abs(sp.csr_matrix(M))).tocsr()
    count, labels = connected_components(graph, directed=False)
    if count == 1:
        return None
    massive = np.zeros(count, dtype=bool)
    mdiag = np.abs(sp.csr_matrix(M).diagonal())
    massive[labels[mdiag > 0]] = True
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(count + 1))
    out = [order[bounds[c] : bounds[c + 1]] for c in range(count) if massive[c]]
    return out if len(out) > 1 or (out and out[0].size < n) else None


def eigsh_by_blocks(A, M, sigma, k, rows, *, tol, maxiter, ncv, v0, block_size):
    """The ``k`` smallest eigenpairs of ``(A, M)`` from those of its blocks ``rows``.

    Returns ``(lam, X)`` ascending, ``X`` zero outside the block of each vector.
    """
    A, M = sp.csr_matrix(A), sp.csr_matrix(M)
    n = A.shape[0]
    start = None if v0 is None else np.asarray(v0).reshape(n, -1)
    found = []  # (values, vectors, rows) per solved group of blocks
    small: list[np.ndarray] = []
    small_rows = 0

    def solve(idx):
        Ab, Mb = A[idx][:, idx], M[idx][:, idx]
        kb = min(k, idx.size)
        if kb == idx.size or dense_is_faster(idx.size, kb):
            lam, X = eig_dense(Ab, Mb, kb)
        else:
            lam, X, _ = shift_invert_eigsh(
                Ab,
                Mb,
                sigma,
                kb,
                tol=tol,
                maxiter=maxiter,
                ncv=ncv,
                v0=None if start is None else start[idx],
                block_size=block_size,
            )
        found.append((lam, X, idx))

    for idx in sorted(rows, key=len):
        if idx.size <= _SMALL:
            small.append(idx)
            small_rows += idx.size
            if small_rows >= _SMALL:
                solve(np.concatenate(small))
                small, small_rows = [], 0
        else:
            solve(idx)
    if small:
        solve(np.concatenate(small))
    values = np.concatenate([lam for lam, _, _ in found])
    which = np.argsort(values, kind="stable")[:k]
    X = np.zeros((n, which.size), dtype=found[0][1].dtype)
    offsets = np.cumsum([0] + [lam.size for lam, _, _ in found])
    for g, (_, Xg, idx) in enumerate(found):
        mine = np.flatnonzero((which >= offsets[g]) & (which < offsets[g + 1]))
        if mine.size:
            X[np.ix_(idx, mine)] = Xg[:, which[mine] - offsets[g]]
    return values[which], X
