"""compute_operators gives every mesh its operators: zero-area faces go through mollified lengths."""

import numpy as np
import torch

from torch_edgevf.learning.precompute import compute_operators
from torch_edgevf.mesh.repair import find_degenerate_faces

from conftest import psb_file


def test_zero_area_face_gets_operators_of_the_mollified_lengths():
    d = np.load(psb_file(), allow_pickle=False)
    i = int(np.nonzero(d["psb_ids"] == 351)[0][0])  # a bearing with one zero-area face
    v = d["verts"][d["vert_offsets"][i] : d["vert_offsets"][i + 1]].astype(np.float64)
    f = d["faces"][d["face_offsets"][i] : d["face_offsets"][i + 1]].astype(np.int64)
    assert len(find_degenerate_faces(v, f)) == 1
    before = (v.copy(), f.copy())
    ops = compute_operators(v, f, k_edge=8, k_vertex=8, vertex_gradient=True)
    np.testing.assert_array_equal(before[0], v)
    np.testing.assert_array_equal(before[1], f)
    for t in (ops.edge_mass, ops.vertex_mass, ops.face_area, ops.edge_evals, ops.vertex_evals):
        assert torch.isfinite(t).all()
    assert (ops.edge_mass > 0).all() and (ops.vertex_mass > 0).all() and (ops.face_area > 0).all()
    assert torch.isfinite(ops.vertex_gradient.values()).all()
    # the eigenvectors are M-orthonormal and the constant is the first vertex mode
    phi = ops.vertex_evecs
    gram = phi.T @ (ops.vertex_mass[:, None] * phi)
    torch.testing.assert_close(gram, torch.eye(8, dtype=gram.dtype), atol=1e-8, rtol=0)
    assert abs(float(ops.vertex_evals[0])) < 1e-8
    psi = ops.edge_evecs
    gram = psi.mH @ (ops.edge_mass[:, None] * psi)
    torch.testing.assert_close(gram, torch.eye(8, dtype=gram.dtype), atol=1e-8, rtol=0)
    # every length grows by the same small epsilon: the areas move by under 1% of the mean
    p = v[f]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    assert np.abs(ops.face_area.numpy() - area).max() < 1e-2 * area.mean()
