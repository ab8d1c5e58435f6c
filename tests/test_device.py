"""Devices and dtypes: every object that holds tensors moves with ``.to``, the networks run on
every available device with the numbers of the CPU, and a mismatch is a ``ValueError``.

The ``meta`` device (tensors without data, on every machine) proves that nothing falls back
to CPU tensors: an operation mixing a meta and a CPU tensor raises. The device-parametrised
tests run on the CPU and on CUDA or MPS where torch sees them.
"""

from __future__ import annotations

import copy
import warnings

import pytest
import torch

import torch_edgevf as ev
from torch_edgevf import _device
from torch_edgevf.learning import (
    DiffusionNet,
    EdgeFieldNet,
    MeshBatch,
    MeshSample,
    OperatorCache,
    collate_meshes,
    compute_operators,
    heat_kernel_signature,
)
from torch_edgevf.learning.layers import gradient_features, spectral_diffusion
from torch_edgevf.learning.layers import sparse as sparse_layers
from torch_edgevf.learning.models import EdgeDiffusionBlock

META = torch.device("meta")


def _devices() -> list[str]:
    out = ["cpu"]
    if torch.cuda.is_available():
        out.append("cuda")
    mps = getattr(torch.backends, "mps", None)
    if mps is not None and mps.is_available():
        out.append("mps")
    return out


DEVICES = _devices()


def _dtype_on(device: str) -> torch.dtype:
    return torch.float32 if device == "mps" else torch.float64  # MPS has no float64


@pytest.fixture(scope="module")
def operators():
    """The operators of two different meshes (a sphere and a bumpy, stretched one)."""
    v, f = ev.icosphere(1)
    out = []
    for k, scale in enumerate((1.0, 1.7)):
        w = v * torch.tensor([scale, 1.0, 1.0 / scale], dtype=v.dtype) + 0.05 * k * v**2
        out.append(compute_operators(w, f, k_edge=12, k_vertex=12, vertex_gradient=True))
    return out


def _batch(operators, labels=(0, 2)) -> MeshBatch:
    g = torch.Generator().manual_seed(0)
    samples = [
        MeshSample(o, torch.randn(o.num_vertices, 5, generator=g, dtype=torch.float64), lab, i)
        for i, (o, lab) in enumerate(zip(operators, labels))
    ]
    return collate_meshes(samples)


NETWORKS = {
    "edgefieldnet": lambda: EdgeFieldNet(5, 3, width=8, vector_width=4, num_blocks=2, mlp=(8,), dropout=0.0),
    "edgefieldnet-vertex": lambda: EdgeFieldNet(
        5, 3, width=8, vector_width=4, num_blocks=2, mlp=(8,), dropout=0.0, vector="vertex"
    ),
    "edgefieldnet-none": lambda: EdgeFieldNet(
        5, 3, width=8, num_blocks=2, mlp=(8,), dropout=0.0, vector="none"
    ),
    "diffusionnet": lambda: DiffusionNet(5, 3, width=8, num_blocks=2, mlp=(8,), dropout=0.0),
    "edgefieldnet-face": lambda: EdgeFieldNet(5, 3, width=8, vector_width=4, num_blocks=1, head="face"),
}


def _all_tensors(obj) -> dict[str, torch.Tensor]:
    if isinstance(obj, torch.nn.Module):
        return dict(obj.state_dict(keep_vars=True))
    return obj.tensors()


# --------------------------------------------------------------------------- .to of every object


def test_mesh_operators_to_meta_moves_every_tensor_and_keeps_the_original(operators):
    ops = operators[0]
    before = {k: (t.device, t.dtype) for k, t in ops.tensors().items()}
    moved = ops.to("meta")
    assert moved is not ops
    tensors = moved.tensors()
    assert set(tensors) == set(before) and "gradient" in tensors and "vertex_gradient" in tensors
    assert all(t.device == META for t in tensors.values()), {k: t.device for k, t in tensors.items()}
    assert {k: t.dtype for k, t in tensors.items()} == {k: d for k, (_, d) in before.items()}
    assert {k: (t.device, t.dtype) for k, t in ops.tensors().items()} == before  # unchanged
    assert moved.device == META and moved.n == ops.n


def test_mesh_operators_to_dtype_and_device_dtype(operators):
    ops = operators[0]
    for moved in (
        ops.to(torch.float32),
        ops.float(),
        ops.to("meta", torch.float32),
        ops.to(dtype=torch.complex64),
    ):
        kinds = moved.tensors()
        assert kinds["verts"].dtype == kinds["edge_mass"].dtype == torch.float32
        assert kinds["gradient"].dtype == kinds["connection_laplacian"].dtype == torch.complex64
        assert kinds["faces"].dtype == kinds["edges"].dtype == torch.int64
    assert ops.to("meta", torch.float32).device == META
    back = ops.float().double()
    torch.testing.assert_close(back.edge_evecs, ops.edge_evecs, rtol=1e-6, atol=1e-6)
    like = ops.to(torch.empty(0, device="meta", dtype=torch.float32))
    assert like.edge_mass.dtype == torch.float32 and like.edge_evecs.dtype == torch.complex64
    assert like.device == META
    assert ops.cpu().device == torch.device("cpu")


@pytest.mark.parametrize("bad", [torch.int32, torch.float16, torch.bool])
def test_to_an_unsupported_dtype_is_a_value_error(operators, bad):
    with pytest.raises(ValueError, match="floating dtype"):
        operators[0].to(bad)
    with pytest.raises(ValueError, match="floating dtype"):
        _batch(operators).to(bad)
    with pytest.raises(ValueError, match="floating dtype"):
        ev.EdgeOperators(*ev.icosphere(0)).to(bad)


def test_mesh_batch_to_meta_moves_every_tensor_and_keeps_its_offsets(operators):
    batch = _batch(operators)
    moved = batch.to("meta")
    tensors = moved.tensors()
    for name in (
        "features",
        "labels",
        "vertex_offsets",
        "edge_batch",
        "gradient",
        "connection_laplacian",
        "indices",
    ):
        assert name in tensors
    assert all(t.device == META for t in tensors.values()), {k: t.device for k, t in tensors.items()}
    assert batch.features.device.type == "cpu"  # the original is unchanged
    for kind in ("vertex", "edge", "face"):
        assert (
            moved.host_offsets(kind)
            == batch.host_offsets(kind)
            == tuple(getattr(batch, f"{kind}_offsets").tolist())
        )
    # a batch made without collate_meshes reads its offsets from the tensors
    rebuilt = MeshBatch(**{k: getattr(batch, k) for k in batch.__dataclass_fields__})
    assert rebuilt.host_offsets("edge") == batch.host_offsets("edge")


def test_edge_operators_move_every_buffer():
    v, f = ev.icosphere(1)
    ops = ev.EdgeOperators(v, f)
    out = ops.to("meta")
    assert out is ops  # an nn.Module moves in place, as torch's do
    assert all(t.device == META for t in _all_tensors(ops).values())
    assert "connection_laplacian" in _all_tensors(ops)
    ops32 = ev.EdgeOperators(v, f).to(torch.float32)
    assert ops32.connection_laplacian.dtype == torch.complex64 and ops32.mass.dtype == torch.float32
    assert ops32.edges.dtype == torch.int64


@pytest.mark.parametrize("name", sorted(NETWORKS))
def test_networks_move_every_parameter_and_buffer(name):
    model = NETWORKS[name]().to("meta", torch.float64)
    tensors = _all_tensors(model)
    assert tensors and all(t.device == META and t.dtype == torch.float64 for t in tensors.values())


# --------------------------------------------------------------------------- nothing falls back to the CPU


@pytest.mark.parametrize("name", sorted(NETWORKS))
def test_networks_run_forward_backward_and_a_step_on_meta(operators, name):
    """On the meta device: any CPU tensor made on the way would raise when mixed in."""
    torch.manual_seed(0)
    model = NETWORKS[name]().double().to("meta")
    batch = _batch(operators).to("meta")
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", _device.SparseFallbackWarning)  # meta has no sparse kernels
        out = model(batch)
        assert out.device == META
        target = (
            batch.labels
            if out.shape[0] == batch.num_meshes
            else torch.zeros(out.shape[0], dtype=torch.int64, device="meta")
        )
        torch.nn.functional.cross_entropy(out, target).backward()
    assert all(p.grad is not None and p.grad.device == META for p in model.parameters() if p.requires_grad)
    opt.step()
    assert all(p.device == META for p in model.parameters())


def test_edge_diffusion_block_and_layers_on_meta(operators):
    batch = _batch(operators).to("meta", torch.float32)
    block = EdgeDiffusionBlock(3).to("meta")
    z = torch.randn(batch.num_edges, 3, dtype=torch.complex64, device="meta")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", _device.SparseFallbackWarning)
        assert block(z, batch).device == META
        f = torch.randn(batch.num_vertices, 2, dtype=torch.float32, device="meta")
        assert gradient_features(f, batch.gradient, batch.edge_mass).device == META
        assert ev.learning.layers.divergence_features(z, batch.gradient, batch.vertex_mass).device == META
    hks = heat_kernel_signature(batch.vertex_evals[0], batch.vertex_evecs[: batch.host_offsets("vertex")[1]])
    assert hks.device == META


# --------------------------------------------------------------------------- mismatches


def test_a_model_and_a_batch_on_different_devices_is_a_value_error(operators):
    batch = _batch(operators)
    model = NETWORKS["edgefieldnet"]().double().to("meta")
    with pytest.raises(ValueError, match=r"batch\.features is on cpu but the model's parameters are on meta"):
        model(batch)
    half = copy.copy(batch)
    half.gradient = batch.gradient.to("meta")
    model = NETWORKS["edgefieldnet"]().double()
    with pytest.raises(ValueError, match=r"batch\.gradient is on meta but the model's parameters are on cpu"):
        model(half)


def test_layers_name_both_inputs_on_different_devices(operators):
    ops = operators[0]
    f = torch.randn(ops.num_vertices, 2, dtype=torch.float64)
    with pytest.raises(ValueError, match="G is on meta but f is on cpu"):
        gradient_features(f, ops.gradient.to("meta"))
    times = torch.ones(2, dtype=torch.float64)
    with pytest.raises(ValueError, match="evecs is on meta but z is on cpu"):
        spectral_diffusion(f, ops.vertex_evals, ops.vertex_evecs.to("meta"), ops.vertex_mass, times)
    with pytest.raises(ValueError, match="weight is on meta but z is on cpu"):
        ev.learning.layers.complex_linear(f.to(torch.complex128), torch.ones(2, 2, 2, device="meta"))
    with pytest.raises(ValueError, match="the module's parameters are on meta"):
        ev.learning.layers.LearnedDiffusion(2).to("meta")(
            f, ops.vertex_mass, evals=ops.vertex_evals, evecs=ops.vertex_evecs
        )


def test_fields_and_operators_name_the_devices():
    v, f = ev.icosphere(1)
    topo = ev.Topology(f)
    z = torch.ones(topo.num_edges, dtype=torch.complex128, device="meta")
    with pytest.raises(ValueError, match="z is on meta but the mesh is on cpu"):
        ev.face_curl(v, topo, z)
    ops = ev.EdgeOperators(v, f)
    with pytest.raises(ValueError, match="verts is on meta but the operators are on cpu"):
        ops.update(v.to("meta"))


def test_collate_refuses_samples_on_different_devices(operators):
    a, b = operators
    x = torch.zeros(a.num_vertices, 2, dtype=torch.float64)
    y = torch.zeros(b.num_vertices, 2, dtype=torch.float64)
    with pytest.raises(ValueError, match="operators on meta but sample 0 on cpu"):
        collate_meshes([MeshSample(a, x, 0, 0), MeshSample(b.to("meta"), y.to("meta"), 1, 1)])
    with pytest.raises(ValueError, match="features on meta but its operators on cpu"):
        collate_meshes([MeshSample(a, x.to("meta"), 0, 0)])


# --------------------------------------------------------------------------- the sparse fallback


def test_the_sparse_fallback_warns_once_per_device_and_dtype(monkeypatch):
    monkeypatch.setattr(_device, "_SPARSE_KERNELS", {})
    with pytest.warns(_device.SparseFallbackWarning, match="complex128 on the meta device"):
        assert not _device.sparse_kernels(META, torch.complex128)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert not _device.sparse_kernels(META, torch.complex128)  # no second warning
        assert _device.sparse_kernels(torch.device("cpu"), torch.complex128)


def test_the_fallback_products_equal_the_csr_products(operators, monkeypatch):
    """Where a device has no CSR kernel the gathers run: the same numbers and gradients."""
    batch = _batch(operators)
    model = NETWORKS["edgefieldnet"]().double()
    expected = model(batch)
    expected.sum().backward()
    grads = [p.grad.clone() for p in model.parameters()]
    model.zero_grad()
    asked = []

    def no_kernels(device, dtype):
        asked.append(dtype)
        return False

    monkeypatch.setattr(sparse_layers, "sparse_kernels", no_kernels)
    monkeypatch.setattr(ev.learning.layers.pooling, "sparse_kernels", no_kernels)
    sparse_layers._BASIS_CACHE.clear()
    got = model(_batch(operators))
    got.sum().backward()
    assert torch.complex128 in asked and torch.float64 in asked  # the gathers ran
    torch.testing.assert_close(got, expected, rtol=1e-12, atol=1e-12)
    for g, p in zip(grads, model.parameters()):
        torch.testing.assert_close(p.grad, g, rtol=1e-10, atol=1e-12)


# --------------------------------------------------------------------------- precompute on the CPU


def test_compute_operators_returns_on_the_device_asked_or_of_verts(operators, tmp_path):
    v, f = ev.icosphere(1)
    on_meta = compute_operators(v, f, k_edge=6, k_vertex=6, device="meta", dtype=torch.float32)
    assert all(t.device == META for t in on_meta.tensors().values())
    assert on_meta.edge_evecs.dtype == torch.complex64
    cache = OperatorCache(tmp_path)
    first = cache.get(v, f, k_edge=6, k_vertex=6, device="meta")
    again = cache.get(v, f, k_edge=6, k_vertex=6)
    assert first.device == META and again.device == torch.device("cpu")
    assert len(list(tmp_path.glob("*.npz"))) == 1  # the device is not part of the key


# --------------------------------------------------------------------------- every available device


def _trained(model, batch, device, dtype):
    model = model.to(device, dtype)
    batch = batch.to(device, dtype)
    opt = torch.optim.SGD(model.parameters(), lr=0.1)
    out = model(batch)
    target = (
        batch.labels
        if out.shape[0] == batch.num_meshes
        else torch.zeros(out.shape[0], dtype=torch.int64, device=device)
    )
    torch.nn.functional.cross_entropy(out, target).backward()
    grads = [p.grad.detach().cpu() for p in model.parameters()]
    opt.step()
    return out.detach().cpu(), grads, [p.detach().cpu() for p in model.parameters()]


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("name", sorted(NETWORKS))
def test_networks_on_each_device_equal_the_cpu(operators, device, name):
    """Forward, backward and one optimizer step on ``device`` give the CPU's numbers."""
    dtype = _dtype_on(device)
    torch.manual_seed(0)
    model = NETWORKS[name]().eval() if name.endswith("face") else NETWORKS[name]()
    batch = _batch(operators)
    reference = _trained(copy.deepcopy(model), batch, "cpu", dtype)
    got = _trained(copy.deepcopy(model), batch, device, dtype)
    tol = dict(rtol=1e-9, atol=1e-9) if dtype == torch.float64 else dict(rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(got[0], reference[0], **tol)
    for a, b in zip(got[1] + got[2], reference[1] + reference[2]):
        torch.testing.assert_close(a, b, **tol)


@pytest.mark.parametrize("device", DEVICES)
def test_operators_and_features_on_each_device_equal_the_cpu(device):
    dtype = _dtype_on(device)
    v, f = ev.icosphere(1)
    v = v.to(dtype)
    ops = ev.EdgeOperators(v.to(device), f)
    ref = ev.EdgeOperators(v, f)
    assert all(t.device.type == device for t in _all_tensors(ops).values())
    for name in ("mass", "connection_laplacian", "gradient", "laplace_beltrami"):
        torch.testing.assert_close(getattr(ops, name).cpu().to_dense(), getattr(ref, name).to_dense())
    assert ev.gradient(v.to(device), f).device.type == device
    o = compute_operators(v.to(device), f, k_edge=6, k_vertex=6, dtype=dtype)
    assert all(t.device.type == device for t in o.tensors().values())
    hks = heat_kernel_signature(o.vertex_evals, o.vertex_evecs, log=True)
    torch.testing.assert_close(
        hks.cpu(), heat_kernel_signature(o.cpu().vertex_evals, o.cpu().vertex_evecs, log=True)
    )
