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

__all__ = ["Pattern", "sparse_coo", "diagonal"]


def sparse_coo(indices: torch.Tensor, values: torch.Tensor, shape) -> torch.Tensor:
    """A coalesced COO tensor from already sorted, unique ``indices``."""
    return torch.sparse_coo_tensor(
        indices, values, tuple(shape), is_coalesced=True, check_invariants=False
    )


def diagonal(values: torch.Tensor) -> torch.Tensor:
    """The ``(N, N)`` sparse diagonal matrix with the given ``(N,)`` values."""
    idx = torch.arange(values.shape[0], device=values.device)
    return sparse_coo(torch.stack([idx, idx]), values, (values.shape[0], values.shape[0]))


class Pattern:
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
        keys = rows * self.shape[1] + cols
        order = np.argsort(keys, kind="stable")
        sorted_keys = keys[order]
        new = np.empty(keys.shape[0], dtype=bool)
        new[:1] = True
        new[1:] = sorted_keys[1:] != sorted_keys[:-1]
        unique = sorted_keys[new]
        target = np.cumsum(new) - 1
        self.nnz = int(unique.shape[0])
        self.num_contributions = int(keys.shape[0])
        index = _index_dtype(self.num_contributions)
        self._indices = torch.from_numpy(np.stack([unique // self.shape[1], unique % self.shape[1]]))
        # assembly = gather the first contribution of every nonzero, then add the others
        self._first = torch.from_numpy(order[new].astype(index))
        self._rest_src = torch.from_numpy(order[~new].astype(index))
        self._rest_dst = torch.from_numpy(target[~new].astype(index))
        self._on_device: dict = {}

    def _tensors(self, device) -> tuple[torch.Tensor, ...]:
        device = torch.device(device)
        host = (self._indices, self._first, self._rest_src, self._rest_dst)
        if device.type == "cpu":
            return host
        if device not in self._on_device:
            self._on_device[device] = tuple(t.to(device) for t in host)
        return self._on_device[device]

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


def _index_dtype(size: int):
    """int32 indices where they fit (half the memory of int64), else int64."""
    return np.int32 if size < 2**31 - 1 else np.int64
