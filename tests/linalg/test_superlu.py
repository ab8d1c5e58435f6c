"""SuperLU's symmetric mode: options that do not depend on the numbering of the input.

The time itself is measured in ``benchmarks/bench_linalg.py`` (generated meshes); here the
options and what they must give (diagonal pivots, the fill of the minimum degree order, an
accurate solve) are checked on a mesh numbered by another tool.
"""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import torch

import torch_edgevf as ev
from torch_edgevf.linalg import factor as fm
from torch_edgevf.linalg import to_scipy

trimesh = pytest.importorskip("trimesh")


def _shifted_laplacian(verts, faces) -> sp.csc_matrix:
    ops = ev.EdgeOperators(torch.as_tensor(verts), torch.as_tensor(faces), n=1)
    L = to_scipy(ops.connection_laplacian.detach().coalesce())
    M = to_scipy(ops.mass.detach().coalesce())
    return sp.csc_matrix(L + 0.1 * M)


def _trimesh_icosphere(level: int):
    m = trimesh.creation.icosphere(subdivisions=level)
    v = np.asarray(m.vertices, dtype=np.float64)
    return v / np.linalg.norm(v, axis=1, keepdims=True), np.asarray(m.faces, dtype=np.int64)


def test_symmetric_mode_options():
    opts = fm.SYMMETRIC_MODE
    assert opts["options"] == {"SymmetricMode": True}
    assert opts["diag_pivot_thresh"] == 0.0
    assert opts["permc_spec"] == "MMD_AT_PLUS_A"
    # no relaxed supernodes: with SuperLU's default relaxation the factorization of
    # trimesh's icosphere 3 took 25-400x the time of the library's icosphere 3 (same fill)
    assert opts["relax"] == 1


def test_trimesh_icosphere_factored_with_symmetric_mode(monkeypatch):
    calls = []
    splu = sla.splu

    def recording_splu(A, **kwargs):
        calls.append(kwargs)
        return splu(A, **kwargs)

    monkeypatch.setattr(fm.sla, "splu", recording_splu)
    K = _shifted_laplacian(*_trimesh_icosphere(3))
    f = fm._SuperLUFactor(K, hermitian=True, check_pd=True)
    assert calls == [fm.SYMMETRIC_MODE]
    # symmetric mode kept: diagonal pivots (an LDL^H), the fill of the minimum degree order,
    # far below SciPy's default (COLAMD, partial pivoting) on the same matrix
    assert np.array_equal(f._lu.perm_r, f._lu.perm_c)
    fill = f._lu.L.nnz + f._lu.U.nnz
    K_ref = _shifted_laplacian(*ev.icosphere(3))
    ref = fm._SuperLUFactor(K_ref, hermitian=True, check_pd=True)
    assert fill <= 1.05 * (ref._lu.L.nnz + ref._lu.U.nnz)
    lu_default = splu(K)
    assert fill < 0.6 * (lu_default.L.nnz + lu_default.U.nnz)
    b = np.random.default_rng(0).standard_normal(K.shape[0]) + 0j
    x = f.solve(b)
    assert np.linalg.norm(K @ x - b) <= 1e-12 * np.linalg.norm(b)


def test_factorize_without_cholmod_uses_symmetric_mode(monkeypatch):
    monkeypatch.setattr(fm, "cholmod_module", lambda: None)
    monkeypatch.setattr(fm, "cvxopt_cholmod_module", lambda: None)
    K = _shifted_laplacian(*_trimesh_icosphere(2))
    f = fm.factorize(K, "auto")
    assert f.backend == "superlu-hermitian"
    b = np.ones(K.shape[0], dtype=np.complex128)
    np.testing.assert_allclose(K @ f.solve(b), b, rtol=0, atol=1e-12)
