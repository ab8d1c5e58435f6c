"""PyTorch Geometric: the transform, the batching of its Data by PyG's DataLoader, the networks
on PyG batches, and the example that trains on a PyG dataset of the PSB file."""

import numpy as np
import pytest
import torch

import torch_edgevf as ev

pytest.importorskip("torch_geometric")

from torch_geometric.data import Batch, Data, InMemoryDataset  # noqa: E402
from torch_geometric.loader import DataLoader  # noqa: E402

from torch_edgevf.learning import (  # noqa: E402
    DiffusionNet,
    EdgeFieldNet,
    MeshSample,
    collate_meshes,
    compute_operators,
    heat_kernel_signature,
)
from torch_edgevf.pyg import ComputeOperators, OperatorData, to_mesh_batch  # noqa: E402

from conftest import load_example  # noqa: E402

K = 8
OPTIONS = dict(k_edge=K, k_vertex=K, hks_count=4, dtype=torch.float64)


def two_meshes():
    """Two meshes of different sizes and topologies: a stretched sphere and a bumpy open
    cylinder (with boundary), numbered by trimesh."""
    import trimesh

    v1, f1 = ev.icosphere(1)
    v1 = v1 * torch.tensor([1.0, 0.6, 1.4], dtype=v1.dtype)
    cyl = trimesh.creation.cylinder(radius=0.7, height=1.5, sections=10)
    v2 = torch.tensor(np.asarray(cyl.vertices), dtype=torch.float64)
    f2 = torch.tensor(np.asarray(cyl.faces), dtype=torch.int64)
    v2 = v2 + 0.05 * torch.sin(3 * v2[:, [1, 2, 0]])
    return [(v1, f1), (v2, f2)]


def data_list(transform=None, labels=(0, 1)):
    transform = transform or ComputeOperators(**OPTIONS)
    return [
        transform(Data(pos=v.float(), face=f.t().contiguous(), y=torch.tensor(y)))
        for (v, f), y in zip(two_meshes(), labels)
    ]


def dense(t):
    return t.to_dense() if t is not None and t.layout == torch.sparse_coo else t


def test_pyg_transform_adds_the_operators_of_compute_operators():
    (v, f), _ = two_meshes()
    data = data_list()[0]
    assert isinstance(data, OperatorData)
    o = compute_operators(v.float(), f, k_edge=K, k_vertex=K, vertex_gradient=True)
    assert torch.equal(data.mesh_edge, o.edges.t()) and torch.equal(data.face_edge, o.face_edges.t())
    for name in ("edge_mass", "vertex_mass", "face_area", "edge_evals", "vertex_evals"):
        torch.testing.assert_close(getattr(data, name), getattr(o, name))
    torch.testing.assert_close(
        data.x,
        heat_kernel_signature(
            o.vertex_evals, o.vertex_evecs, count=4, area=float(o.face_area.sum()), log=True
        ),
    )
    mb = data.to_mesh_batch()
    for name in ("gradient", "connection_laplacian", "vertex_gradient"):
        torch.testing.assert_close(dense(getattr(mb, name)), dense(getattr(o, name)))
    assert data.num_mesh_edges == o.num_edges and data.num_mesh_faces == o.num_faces and data.n == 1


def test_pyg_dataloader_batch_is_the_library_batch():
    """PyG's DataLoader batches OperatorData as collate_meshes batches the same meshes:
    offsets, global indices, block diagonal operators, stacked eigenvalues."""
    items = data_list()
    batch = next(iter(DataLoader(items, batch_size=2)))
    got = to_mesh_batch(batch)
    singles = [d.to_mesh_batch() for d in items]
    samples = []
    for s in singles:
        fields = {
            name: getattr(s, name)
            for name in (
                "verts",
                "faces",
                "edges",
                "face_edges",
                "edge_mass",
                "vertex_mass",
                "face_area",
                "gradient",
                "connection_laplacian",
                "edge_evecs",
                "vertex_evecs",
                "vertex_gradient",
            )
        }
        ops = ev.learning.precompute.MeshOperators(
            **fields, edge_evals=s.edge_evals[0], vertex_evals=s.vertex_evals[0], n=1
        )
        samples.append(MeshSample(ops, s.features, int(s.labels[0])))
    ref = collate_meshes(samples)
    for name in (
        "features",
        "labels",
        "verts",
        "faces",
        "edges",
        "face_edges",
        "edge_mass",
        "vertex_mass",
        "face_area",
        "gradient",
        "connection_laplacian",
        "edge_evals",
        "edge_evecs",
        "vertex_evals",
        "vertex_evecs",
        "vertex_gradient",
        "vertex_offsets",
        "edge_offsets",
        "face_offsets",
        "vertex_batch",
        "edge_batch",
        "face_batch",
    ):
        a, b = dense(getattr(got, name)), dense(getattr(ref, name))
        assert a.shape == b.shape, name
        torch.testing.assert_close(a, b, msg=name)
    # the pieces are the meshes' own: the edges of mesh 1 index its own vertices
    nv0 = items[0].num_nodes
    assert int(got.edges[got.edge_batch == 1].min()) == nv0
    assert got.num_meshes == 2 and got.edge_evals.shape == (2, K)


@pytest.mark.parametrize("head", ["global", "vertex", "face"])
@pytest.mark.parametrize("network", ["edgefieldnet", "diffusionnet"])
def test_pyg_batch_gives_the_outputs_of_the_meshes_one_by_one(network, head):
    items = data_list()
    torch.manual_seed(0)
    make = EdgeFieldNet if network == "edgefieldnet" else DiffusionNet
    model = make(items[0].x.shape[1], 3, width=8, num_blocks=2, head=head).double().eval()
    batch = next(iter(DataLoader(items, batch_size=2)))
    out = model(batch)  # the PyG batch as it is
    singles = [model(d) for d in items]
    assert out.shape[0] == sum(s.shape[0] for s in singles)
    torch.testing.assert_close(out, torch.cat(singles), rtol=1e-10, atol=1e-12)
    # the same in the library's own batch, and the gradients add up
    torch.testing.assert_close(out, model(batch.to_mesh_batch()), rtol=0, atol=0)
    model.zero_grad()
    out.square().sum().backward()
    batched = [p.grad.clone() for p in model.parameters()]
    model.zero_grad()
    sum(s.square().sum() for s in (model(d) for d in items)).backward()
    for a, p in zip(batched, model.parameters()):
        torch.testing.assert_close(a, p.grad, rtol=1e-9, atol=1e-12)


def test_pyg_batches_of_every_size_and_order():
    """Three meshes, batches of two in both orders and a last batch of one."""
    items = data_list()
    items = [items[1], items[0], items[1]]
    torch.manual_seed(1)
    model = EdgeFieldNet(items[0].x.shape[1], 2, width=8, num_blocks=1, head="vertex").double().eval()
    want = torch.cat([model(d) for d in items])
    got = torch.cat([model(b) for b in DataLoader(items, batch_size=2)])
    torch.testing.assert_close(got, want, rtol=1e-10, atol=1e-12)


def test_pyg_batches_without_edge_eigenpairs_feed_the_per_vertex_network():
    """``ComputeOperators(k_edge=0)``: no eigenpair of ``L_c`` (empty columns), batched by PyG
    as by ``collate_meshes``; the per-vertex network (local fields) runs on it."""
    items = data_list(ComputeOperators(**dict(OPTIONS, k_edge=0)))
    assert items[0].edge_evecs.shape == (items[0].edge_mass.shape[0], 0)
    batch = next(iter(DataLoader(items, batch_size=2)))
    assert batch.edge_evecs.shape == (sum(d.edge_mass.shape[0] for d in items), 0)
    torch.manual_seed(1)
    model = EdgeFieldNet(items[0].x.shape[1], 2, width=8, num_blocks=2, head="vertex").double().eval()
    assert model.fields == "local"
    torch.testing.assert_close(model(batch), torch.cat([model(d) for d in items]), rtol=1e-10, atol=1e-12)


def test_pyg_in_memory_dataset_and_to_data_list_give_the_meshes_back():
    """PyG stores a dataset as one Data (concatenated, not offset) and separates it again, and a
    batch gives its meshes back: the operators survive both."""
    items = data_list()
    data, slices = InMemoryDataset.collate(items)
    batch = Batch.from_data_list(items)
    for i, item in enumerate(items):
        for back in (batch.get_example(i), separate(data, slices, i)):
            assert isinstance(back, OperatorData)
            assert set(back.keys()) == set(item.keys())
            for key in item.keys():
                a, b = item[key], back[key]
                if isinstance(a, torch.Tensor):
                    assert torch.equal(a, b.reshape(a.shape)), key
                else:
                    assert a == int(b), key
            torch.testing.assert_close(
                dense(back.to_mesh_batch().gradient), dense(item.to_mesh_batch().gradient)
            )


def separate(data, slices, i):
    from torch_geometric.data.separate import separate as pyg_separate

    return pyg_separate(cls=data.__class__, batch=data, idx=i, slice_dict=slices, decrement=False)


def test_pyg_in_memory_dataset_saves_and_loads(tmp_path):
    items = data_list()

    class Meshes(InMemoryDataset):
        def __init__(self, root):
            super().__init__(str(root))
            self.load(self.processed_paths[0])

        @property
        def processed_file_names(self):
            return ["meshes.pt"]

        def process(self):
            self.save(items, self.processed_paths[0])

    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "weights only load failed" fallback
        ds = Meshes(tmp_path)
    assert len(ds) == 2
    torch.manual_seed(0)
    model = EdgeFieldNet(items[0].x.shape[1], 2, width=8, num_blocks=1).double().eval()
    torch.testing.assert_close(
        model(next(iter(DataLoader(ds, batch_size=2)))),
        torch.cat([model(d) for d in items]),
        rtol=1e-10,
        atol=1e-12,
    )


def test_pyg_dataloader_with_a_worker_process():
    items = data_list()
    torch.manual_seed(0)
    model = EdgeFieldNet(items[0].x.shape[1], 2, width=8, num_blocks=1).double().eval()
    (batch,) = list(DataLoader(items, batch_size=2, num_workers=1))
    torch.testing.assert_close(model(batch), torch.cat([model(d) for d in items]), rtol=1e-10, atol=1e-12)


def test_pyg_transform_leaves_the_input_unchanged():
    (v, f), _ = two_meshes()
    x = torch.randn(v.shape[0], 2)
    data = Data(pos=v.float(), face=f.t().contiguous(), x=x, y=torch.tensor(3), edge_index=f[:, :2].t())
    before = {k: (val.clone() if isinstance(val, torch.Tensor) else val) for k, val in data.items()}
    out = ComputeOperators(**OPTIONS)(data)
    assert set(data.keys()) == set(before)
    for key, val in before.items():
        assert torch.equal(data[key], val), key
    # the input's attributes are kept; its features come first in x
    assert torch.equal(out.y, data.y) and torch.equal(out.edge_index, data.edge_index)
    assert out.x.shape == (v.shape[0], 2 + 4) and torch.equal(out.x[:, :2], x.double())


def test_pyg_features_dtype_and_cache(tmp_path, monkeypatch):
    from torch_edgevf.learning import cache as cache_module

    calls = []
    real = cache_module.compute_operators
    monkeypatch.setattr(cache_module, "compute_operators", lambda *a, **k: calls.append(1) or real(*a, **k))
    transform = ComputeOperators(k_edge=K, k_vertex=K, features="hks", hks_count=3, cache_dir=tmp_path)
    first = data_list(transform)
    second = data_list(transform)
    assert len(calls) == 2 and len(list(tmp_path.glob("*.npz"))) == 2  # computed once per mesh
    for a, b in zip(first, second):
        assert a.x.dtype == torch.float32 and a.edge_evecs.dtype == torch.complex64 and a.x.shape[1] == 3
        assert bool((a.x > 0).all())  # the signatures themselves
        for key in a.keys():
            if isinstance(a[key], torch.Tensor):
                assert torch.equal(a[key], b[key]), key
    # float32 data and the float32 network of the defaults
    out = EdgeFieldNet(3, 2, width=8, num_blocks=1)(next(iter(DataLoader(first, batch_size=2))))
    assert out.shape == (2, 2) and out.dtype == torch.float32
    none = ComputeOperators(k_edge=K, k_vertex=K, features=None, vertex_gradient=False)(
        Data(pos=two_meshes()[0][0].float(), face=two_meshes()[0][1].t())
    )
    assert "x" not in none.keys() and "vertex_gradient_index" not in none.keys()
    assert none.to_mesh_batch().vertex_gradient is None


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda v, f: Data(pos=v), "data.face"),
        (lambda v, f: Data(face=f.t()), "data.pos"),
        (lambda v, f: Data(pos=v, face=f), r"\(3, F\).*face.t\(\)"),
        (lambda v, f: Data(pos=v, face=f.t().float()), "integer"),
        (lambda v, f: Data(pos=v[:, :2], face=f.t()), r"data.pos must have shape \(V, 3\)"),
        (lambda v, f: Data(pos=v.long(), face=f.t()), "floating"),
        (lambda v, f: Data(pos=v, face=f.t(), x=torch.ones(3, 2)), r"data.x must have shape \(V, C\)"),
        (
            lambda v, f: Data(pos=v, face=torch.cat([f.t(), torch.tensor([[0], [1], [999]])], 1)),
            "out-of-range",
        ),
        (lambda v, f: {"pos": v, "face": f.t()}, "Data"),
    ],
)
def test_pyg_bad_input_raises_value_error(make, match):
    (v, f), _ = two_meshes()
    with pytest.raises(ValueError, match=match):
        ComputeOperators(**OPTIONS)(make(v.float(), f))


def test_pyg_bad_options_and_data_raise_value_error():
    for kwargs in ({"features": "xyz"}, {"dtype": torch.float16}, {"hks_count": 0}):
        with pytest.raises(ValueError):
            ComputeOperators(**kwargs)
    (v, f), _ = two_meshes()
    plain = Data(pos=v.float(), face=f.t())
    with pytest.raises(ValueError, match="ComputeOperators"):
        to_mesh_batch(plain)
    model = EdgeFieldNet(4, 2, width=8, num_blocks=1).double()
    items = data_list()
    items[1].n = 2
    with pytest.raises(ValueError, match="same n"):
        to_mesh_batch(Batch.from_data_list(items))
    with pytest.raises(ValueError, match="features"):
        EdgeFieldNet(5, 2, width=8, num_blocks=1).double()(items[0])  # 4 feature channels, not 5
    assert model(items[0]).shape == (1, 2)


@pytest.mark.slow
def test_pyg_example_trains_well_above_chance(tmp_path, psb, monkeypatch):
    """The example on three classes (4 training meshes each): its test accuracy on the 12 test
    meshes of those classes is far above chance (1/3)."""
    torch.set_num_threads(1)
    example = load_example("train_pyg")
    out = example.main(
        epochs=8,
        classes=3,
        limit=4,
        batch_size=2,
        lr=3e-3,
        width=16,
        num_blocks=2,
        k_edge=16,
        k_vertex=16,
        root=tmp_path / "pyg",
        cache_dir=tmp_path / "cache",
    )
    assert out["num_train"] == 12 and out["num_test"] == 12 and out["num_classes"] == 3
    assert out["losses"][-1] < 0.8 * out["losses"][0]
    assert out["test_accuracy"] >= 0.75, out

    # a second run reads the saved dataset: nothing is processed again
    def refuse(self):
        raise AssertionError("processed again")

    monkeypatch.setattr(example.PSBGeometric, "process", refuse)
    pre = ComputeOperators(k_edge=16, k_vertex=16, vertex_gradient=False)
    again = example.PSBGeometric(
        tmp_path / "pyg", None, "test", example.subset_ids(None, 3, 4), pre_transform=pre
    )
    assert len(again) == 12 and again[0].x.shape[1] == 16 and isinstance(again[0], OperatorData)
