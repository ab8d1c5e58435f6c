"""Fixed sparsity patterns: sort once per topology, then assemble by one scatter.

An operator is a sum of per-face (or per-edge) contributions at known ``(row, col)``
positions. :class:`Pattern` coalesces those positions once; re-assembly for new vertex
positions is then a single ``index_add`` of the contribution values into the ``nnz``
values of a coalesced sparse COO tensor, with no sort, and autograd flows through it.
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
        keys, scatter = np.unique(rows * self.shape[1] + cols, return_inverse=True)
        self.nnz = int(keys.shape[0])
        self.num_contributions = int(rows.shape[0])
        self._indices = torch.from_numpy(np.stack([keys // self.shape[1], keys % self.shape[1]]))
        self._scatter = torch.from_numpy(scatter.ravel().astype(np.int64))
        self._on_device: dict = {}

    def _tensors(self, device) -> tuple[torch.Tensor, torch.Tensor]:
        device = torch.device(device)
        if device.type == "cpu":
            return self._indices, self._scatter
        if device not in self._on_device:
            self._on_device[device] = (self._indices.to(device), self._scatter.to(device))
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
        indices, scatter = self._tensors(values.device)
        out = values.new_zeros(self.nnz).index_add(0, scatter, values)
        return sparse_coo(indices, out, self.shape)
