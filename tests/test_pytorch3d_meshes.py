"""Batches of meshes held as ``pytorch3d.structures.Meshes`` are taken as they are.

pytorch3d is not a dependency: :class:`FakeMeshes` has the part of its ``Meshes`` the
library reads (``verts_list()``, ``faces_list()``; float32 vertices and int64 faces, as
pytorch3d stores them; indexing gives a batch of one mesh).
"""

from __future__ import annotations

import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.learning import (
    EdgeFieldNet,
    MeshBatch,
    MeshSample,
    OperatorCache,
    collate_meshes,
    compute_operators,
)
from torch_edgevf.learning.precompute import vertex_gradient_operator


class FakeMeshes:
    """The interface of ``pytorch3d.structures.Meshes`` that duck typing needs."""

    def __init__(self, verts, faces):
        self._verts, self._faces = list(verts), list(faces)

    def verts_list(self):
        return self._verts

    def faces_list(self):
        return self._faces

    def __len__(self):
        return len(self._verts)

    def __getitem__(self, i):
        return FakeMeshes([self._verts[i]], [self._faces[i]])


@pytest.fixture(scope="module")
def meshes():
    """A sphere and a stretched, subdivided sphere of another size (float32, as pytorch3d)."""
    v0, f0 = ev.icosphere(1)
    v1, f1 = ev.icosphere(2)
    v1 = v1 * torch.tensor([2.0, 1.0, 0.5], dtype=v1.dtype)
    return FakeMeshes([v0.float(), v1.float()], [f0, f1])


def _same_operators(a, b):
    ta, tb = a.tensors(), b.tensors()
    assert set(ta) == set(tb)
    for name in ta:
        x, y = ta[name], tb[name]
        if x.layout == torch.sparse_coo:
            x, y = x.to_dense(), y.to_dense()
        torch.testing.assert_close(x, y, msg=name)


OPTIONS = dict(k_edge=8, k_vertex=8)


def test_compute_operators_of_a_batch_is_one_result_per_mesh(meshes):
    out = compute_operators(meshes, **OPTIONS)
    assert isinstance(out, list) and len(out) == 2
    for ops, v, f in zip(out, meshes.verts_list(), meshes.faces_list()):
        _same_operators(ops, compute_operators(v, f, **OPTIONS))
    assert out[1].num_vertices == meshes.verts_list()[1].shape[0]
    one = compute_operators(meshes[0], **OPTIONS)
    assert len(one) == 1
    _same_operators(one[0], out[0])


def test_a_batch_with_faces_or_empty_is_a_value_error(meshes):
    with pytest.raises(ValueError, match="holds its faces"):
        compute_operators(meshes, meshes.faces_list()[0], **OPTIONS)
    with pytest.raises(ValueError, match="holds no mesh"):
        compute_operators(FakeMeshes([], []), **OPTIONS)
    with pytest.raises(ValueError, match="needs faces"):
        compute_operators(meshes.verts_list()[0], **OPTIONS)


def test_edge_operators_and_operator_functions_take_one_mesh(meshes):
    v, f = meshes.verts_list()[1], meshes.faces_list()[1]
    ops, ref = ev.EdgeOperators(meshes[1], n=2), ev.EdgeOperators(v, f, n=2)
    for name in ("mass", "connection_laplacian", "gradient", "curl_div"):
        torch.testing.assert_close(getattr(ops, name).to_dense(), getattr(ref, name).to_dense())
    for fn in (ev.mass_matrix, ev.gradient, ev.cotan_laplacian, ev.laplace_beltrami):
        torch.testing.assert_close(fn(meshes[1]).to_dense(), fn(v, f).to_dense())
    torch.testing.assert_close(
        ev.connection_laplacian(meshes[1], n=4).to_dense(), ev.connection_laplacian(v, f, 4).to_dense()
    )
    z = torch.randn(ops.num_edges, dtype=torch.complex64)
    torch.testing.assert_close(ev.face_curl(meshes[1], None, z), ev.face_curl(v, f, z))
    D = vertex_gradient_operator(meshes[1])
    torch.testing.assert_close(D.to_dense(), vertex_gradient_operator(v, f).to_dense())
    with pytest.raises(ValueError, match="EdgeOperators takes one mesh, got a FakeMeshes batch of 2"):
        ev.EdgeOperators(meshes)
    with pytest.raises(ValueError, match="takes one mesh"):
        ev.mass_matrix(meshes)


def test_repair_and_save_mesh_take_one_mesh(meshes, tmp_path):
    v, f = meshes.verts_list()[0], meshes.faces_list()[0]
    repaired = ev.repair(meshes[0])
    torch.testing.assert_close(repaired.verts, ev.repair(v, f).verts)
    assert repaired.verts.dtype == torch.float32
    ev.save_mesh(tmp_path / "m.obj", meshes[0])
    back = ev.load_mesh(tmp_path / "m.obj")
    torch.testing.assert_close(back.verts.float(), v)
    assert torch.equal(back.faces, f)
    with pytest.raises(ValueError, match="save_mesh takes one mesh"):
        ev.save_mesh(tmp_path / "two.obj", meshes)


def test_the_cache_takes_a_batch(meshes, tmp_path):
    cache = OperatorCache(tmp_path)
    out = cache.get(meshes, **OPTIONS)
    assert len(out) == 2 and len(list(tmp_path.glob("*.npz"))) == 2
    again = cache.get(meshes, device="meta", **OPTIONS)
    assert all(o.device == torch.device("meta") for o in again)
    _same_operators(out[1], compute_operators(meshes.verts_list()[1], meshes.faces_list()[1], **OPTIONS))


def test_a_network_takes_a_batch_of_meshes(meshes):
    """``MeshBatch.from_meshes`` gives the network the batch of the meshes one by one."""
    sizes = [v.shape[0] for v in meshes.verts_list()]
    packed = torch.randn(sum(sizes), 4, generator=torch.Generator().manual_seed(0))
    batch = MeshBatch.from_meshes(meshes, packed, labels=[1, 0], **OPTIONS)
    pairs = zip(meshes.verts_list(), meshes.faces_list())
    ops = [compute_operators(v, f, dtype=torch.float32, **OPTIONS) for v, f in pairs]
    parts = torch.split(packed, sizes)
    ref = collate_meshes([MeshSample(o, x, lab, i) for i, (o, x, lab) in enumerate(zip(ops, parts, (1, 0)))])
    torch.manual_seed(0)
    model = EdgeFieldNet(4, 3, width=8, vector_width=4, num_blocks=2).eval()
    torch.testing.assert_close(model(batch), model(ref))
    assert batch.labels.tolist() == [1, 0] and batch.verts.dtype == torch.float32
    listed = MeshBatch.from_meshes(meshes, list(parts), **OPTIONS)
    torch.testing.assert_close(model(listed), model(ref))
    with pytest.raises(ValueError, match="packed features must have shape"):
        MeshBatch.from_meshes(meshes, packed[1:], **OPTIONS)
    with pytest.raises(ValueError, match="2 meshes but 1 feature tensors"):
        MeshBatch.from_meshes(meshes, [parts[0]], **OPTIONS)


def test_field_design_singularities_transport_and_quads_take_one_mesh():
    """The field functions take a batch of one mesh in place of ``verts, faces`` (``None``
    for ``faces`` where more arguments follow) and give what the tensors give."""
    v, f = ev.icosphere(2)
    one = FakeMeshes([v], [f])
    z = ev.smoothest_field(one, n=4)
    torch.testing.assert_close(z, ev.smoothest_field(v, f, n=4))
    torch.testing.assert_close(
        ev.FieldDesigner(one, n=2).smoothest(), ev.FieldDesigner(v, f, n=2).smoothest()
    )
    torch.testing.assert_close(ev.curvature_aligned_field(one), ev.curvature_aligned_field(v, f))
    s, s_ref = ev.singularities(one, None, z, n=4), ev.singularities(v, f, z, n=4)
    assert torch.equal(s.vertex_index, s_ref.vertex_index) and torch.equal(s.face_index, s_ref.face_index)
    w = ev.curl_free_field(v, f)
    torch.testing.assert_close(ev.transport(one, None, w, w, 0.3), ev.transport(v, f, w, w, 0.3))
    torch.testing.assert_close(ev.project_on_gradients(one, None, w), ev.project_on_gradients(v, f, w))
    q = ev.quad_mesh(one, quads=300)
    assert q.quads.shape == ev.quad_mesh(v, f, quads=300).quads.shape
    with pytest.raises(ValueError, match="takes one mesh"):
        ev.smoothest_field(FakeMeshes([v, v], [f, f]), n=4)
    with pytest.raises(ValueError, match="holds its faces"):
        ev.smoothest_field(one, f, n=4)
