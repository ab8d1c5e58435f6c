"""eigsh on a subdivided box: highly degenerate spectrum (cube symmetry), flat faces, sharp edges.

The connection Laplacian of ``trimesh.creation.box()`` subdivided has eigenvalues of
multiplicity 2 and 3 (and, for ``n = 4``, where the holonomy of the corners is trivial, a
zero eigenvalue).  Every copy of a cluster among the ``k`` smallest must be found, and the
adaptive block (doubling from 2 while clusters fill it) must not spend the solves of a block
of 6 on multiplicities that a block of 4 resolves.
"""

from __future__ import annotations

import logging
import re

import numpy as np
import pytest
import scipy.sparse.linalg as sla
import torch

from torch_edgevf import EdgeOperators
from torch_edgevf.linalg import eigsh, to_scipy
from torch_edgevf.linalg.eigen import default_shift

trimesh = pytest.importorskip("trimesh")

K = 24


@pytest.fixture(scope="module")
def box():
    m = trimesh.creation.box()
    for _ in range(4):
        m = m.subdivide()
    return (
        torch.as_tensor(np.asarray(m.vertices, dtype=np.float64)),
        torch.as_tensor(np.asarray(m.faces, dtype=np.int64)),
    )


def _solves(caplog):
    counts = [
        int(m.group(1)) for r in caplog.records if (m := re.match(r"Lanczos: (\d+) solves", r.getMessage()))
    ]
    assert len(counts) == 1
    return counts[0]


@pytest.mark.parametrize("n", [1, 4])
def test_eigsh_subdivided_box_matches_scipy(box, n, caplog):
    verts, faces = box
    ops = EdgeOperators(verts, faces, n=n)
    L, Mz = ops.connection_laplacian.detach().coalesce(), ops.mass.detach().coalesce()
    A, M = to_scipy(L), to_scipy(Mz)
    ref = np.sort(sla.eigsh(A, K + 6, M, sigma=default_shift(A, M), which="LM", tol=0)[0])
    with caplog.at_level(logging.DEBUG, logger="torch_edgevf.linalg.lanczos"):
        lam, X = eigsh(L, Mz, K, method="lanczos")
    lam, X = lam.numpy(), X.numpy()
    scale = abs(ref[K - 1])
    np.testing.assert_allclose(lam, ref[:K], rtol=0, atol=1e-12 * scale)
    # the spectrum is degenerate: clusters of 2 and 3 among the wanted values, each complete
    clusters = np.split(ref, np.flatnonzero(np.diff(ref) > 1e-8 * scale) + 1)
    sizes = [c.size for c in clusters if c[-1] <= ref[K - 1]]
    assert max(sizes) >= 3
    for c in clusters:
        if c[-1] < ref[K - 1]:  # a cluster wholly among the k smallest: every copy is there
            assert np.count_nonzero(np.abs(lam - c.mean()) <= 1e-10 * scale) == c.size
    R = A @ X - (M @ X) * lam
    res = np.linalg.norm(R, axis=0) / (scale * np.linalg.norm(M @ X, axis=0))
    assert res.max() < 1e-9
    np.testing.assert_allclose(X.conj().T @ (M @ X), np.eye(K), atol=1e-10)
    # multiplicities of at most 3: the block stops at 4 (a block of 6 took 160-175 solves)
    assert _solves(caplog) <= 150
