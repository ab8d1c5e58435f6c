"""The networks: EdgeFieldNet (recommended) and DiffusionNet.

Invariance of the outputs to rigid motions and to vertex renumbering, the eigenbasis path
against the formula on the edges, gradchecks in float64, the checks at the boundary (and
none inside), dtype agreement at the first call, and learning: accuracy well above chance
on generated shapes (and on a few PSB classes, slow lane).
"""

import numpy as np
import pytest
import torch

from torch_edgevf.learning import batching, layers, models, precompute
from torch_edgevf.learning.layers import sparse as layer_checks

from conftest import (
    classification_accuracy,
    generated_shapes_task,
    perturbed_icosphere,
    psb_classes_task,
    random_rotation,
    train_classifier,
)

OPTIONS = dict(k_edge=16, k_vertex=16, vertex_gradient=True)


def _sample(v, f, label=0, dtype=torch.float64, log=True):
    ops = precompute.compute_operators(v, f, **OPTIONS)
    x = precompute.heat_kernel_signature(ops.vertex_evals, ops.vertex_evecs, count=8, log=log)
    return batching.MeshSample(ops.to(dtype), x.to(dtype), label)


def _batch(v, f, label=0, dtype=torch.float64):
    return batching.collate_meshes([_sample(v, f, label, dtype)])


@pytest.fixture(scope="module")
def mesh():
    v, f = perturbed_icosphere(2, 0.08, seed=3)
    return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)


def _small_edge_net(**options):
    """A small EdgeFieldNet with ``options``, as a function of its head."""
    return lambda head: models.EdgeFieldNet(
        8, 5, width=8, vector_width=4, num_blocks=2, mlp=(8,), head=head, **options
    )


NETWORKS = {
    "edge": _small_edge_net(fields="smooth"),
    "edge-local": _small_edge_net(fields="local"),
    "edge-vertex": _small_edge_net(vector="vertex"),
    "edge-none": _small_edge_net(vector="none"),
    "diffusionnet": lambda head: models.DiffusionNet(8, 5, width=8, num_blocks=2, mlp=(8,), head=head),
}


def test_the_default_network_is_the_recommended_one():
    """``EdgeFieldNet(C_in, C_out)``: 3 blocks of 64 scalar and 16 complex channels, edge
    fields, dropout 0.5, one output per mesh; with the 16 scales of the heat kernel
    signature and 19 classes, 64,067 parameters (the study's count)."""
    net = models.EdgeFieldNet(16, 19)
    assert (net.vector, net.head, net.fields, len(net.blocks)) == ("edge", "global", "smooth", 3)
    assert sum(p.numel() for p in net.parameters()) == 64_067
    assert sum(p.numel() for p in models.DiffusionNet(16, 19).parameters()) == 118_035
    assert [m.p for m in net.modules() if isinstance(m, torch.nn.Dropout)] == [0.5] * 6


@pytest.mark.parametrize("head", ["vertex", "face"])
def test_the_default_per_vertex_and_face_network_has_local_fields(mesh, head):
    """Per vertex or face (segmentation) the recommended network's fields are local (the RNA
    study's result): no eigenpair of ``L_c`` is needed, and none is learned a time for."""
    net = models.EdgeFieldNet(8, 5, width=8, vector_width=4, num_blocks=2, head=head)
    assert net.fields == "local" and all(b.field_diffusion is None for b in net.blocks)
    assert models.EdgeFieldNet(8, 5, head=head, vector="vertex").fields == "smooth"  # unused there
    v, f = mesh
    ops = precompute.compute_operators(v, f, k_edge=0, k_vertex=16)
    x = precompute.heat_kernel_signature(ops.vertex_evals, ops.vertex_evecs, count=8, log=True)
    out = net.double()(batching.collate_meshes([batching.MeshSample(ops, x, 0)]))
    assert out.shape == ((v if head == "vertex" else f).shape[0], 5)


@pytest.mark.parametrize("name", sorted(NETWORKS))
@pytest.mark.parametrize("head", ["global", "vertex", "face"])
def test_outputs_are_invariant_to_rigid_motion_and_renumbering(mesh, name, head):
    v, f = mesh
    torch.manual_seed(0)
    net = NETWORKS[name](head).double().eval()
    perm = np.random.default_rng(1).permutation(v.shape[0])
    inverse = np.argsort(perm)
    v2 = (v @ random_rotation().T + np.array([0.3, -1.0, 2.0]))[perm]
    f2 = inverse[f][:, [1, 2, 0]]  # renumbered vertices, rotated corners
    with torch.no_grad():
        a, b = net(_batch(v, f)), net(_batch(v2, f2))
    if head == "vertex":
        b = b[inverse]
    assert a.abs().max() > 1e-3  # not a trivial output
    torch.testing.assert_close(b, a, rtol=1e-6, atol=1e-8)


def _block_on_the_edges(block, x, z, batch):
    """The block as its formula reads, every field on the edges and every function the
    public, checked one of :mod:`torch_edgevf.learning.layers` (a reference for the
    eigenbasis path of :meth:`EdgeFieldBlock.forward`, and for local fields, which skip
    the ``L_c`` diffusion)."""
    t = block.diffusion.times
    xd = layers.spectral_diffusion(
        x, batch.vertex_evals, batch.vertex_evecs, batch.vertex_mass, t, batch.vertex_offsets
    )
    a = torch.view_as_complex(block.lift(xd).unflatten(1, (block.vector_width, 2)).contiguous())
    u = layers.gradient_features(a, batch.gradient, batch.edge_mass)
    if z is not None and block.mix is not None:
        u = u + block.mix(z)
    if block.field_diffusion is not None:
        s = block.field_diffusion.times
        u = layers.spectral_diffusion(
            u, batch.edge_evals, batch.edge_evecs, batch.edge_mass, s, batch.edge_offsets
        )
    inv = torch.tanh(layers.invariant_features(u, block.products, modulus=False))
    inv = layers.pool_edges_to_vertices(inv, batch.edges, batch.num_vertices, batch.edge_mass)
    return x + block.mlp(torch.cat([x, xd, inv], dim=1)), u if z is None else z + u


@pytest.mark.parametrize("carry", [False, True])
def test_the_fields_as_eigenbasis_coefficients_are_the_fields_on_the_edges(mesh, carry):
    """The block works on the fields' coefficients in the edge eigenbasis: the same numbers
    as every field on the edges, on a batch of two meshes, for the scalars, the fields and
    the gradients."""
    pair = batching.collate_meshes([_sample(*mesh), _sample(*perturbed_icosphere(1, 0.05, seed=7))])
    torch.manual_seed(0)
    block = models.EdgeFieldBlock(8, 4, mlp=(8,), dropout=0.0, carry=carry).double()
    assert block.mlp[0].in_features == 2 * 8 + 4
    with torch.no_grad():
        block.diffusion.raw_times.uniform_(0.0, 0.05)
        block.field_diffusion.raw_times.uniform_(0.01, 0.2)
    x = torch.randn(pair.num_vertices, 8, dtype=torch.float64, requires_grad=True)
    z = torch.randn(pair.num_edges, 4, dtype=torch.complex128, requires_grad=True)
    got = block(x, z, pair)
    want = _block_on_the_edges(block, x, z, pair)
    for g, w in zip(got, want):
        assert w.abs().max() > 1e-3
        torch.testing.assert_close(g, w, rtol=1e-10, atol=1e-12)
    grads = [
        torch.autograd.grad(sum(t.abs().square().sum() for t in out), (x, z, *block.parameters()))
        for out in (got, want)
    ]
    for g, w in zip(*grads):
        torch.testing.assert_close(g, w, rtol=1e-9, atol=1e-12)


def test_local_fields_are_the_gradients_on_the_edges(mesh):
    """``fields="local"``: the block's fields are ``M_z^-1 G (xd W)`` (plus the carried ones)
    on every edge, the same numbers as the formula with the public layers, on a batch of two
    meshes whose operators hold no eigenpair of ``L_c`` (``k_edge=0``)."""
    local = dict(OPTIONS, k_edge=0)
    samples = []
    for v, f in (mesh, perturbed_icosphere(1, 0.05, seed=7)):
        ops = precompute.compute_operators(v, f, **local)
        assert ops.edge_evecs.shape == (ops.edges.shape[0], 0) and ops.edge_evals.shape == (0,)
        x = precompute.heat_kernel_signature(ops.vertex_evals, ops.vertex_evecs, count=8, log=True)
        samples.append(batching.MeshSample(ops, x, 0))
    pair = batching.collate_meshes(samples)
    torch.manual_seed(0)
    block = models.EdgeFieldBlock(8, 4, mlp=(8,), dropout=0.0, fields="local").double()
    assert block.field_diffusion is None
    with torch.no_grad():
        block.diffusion.raw_times.uniform_(0.0, 0.05)
    x = torch.randn(pair.num_vertices, 8, dtype=torch.float64)
    z = torch.randn(pair.num_edges, 4, dtype=torch.complex128)
    got, want = block(x, z, pair), _block_on_the_edges(block, x, z, pair)
    for g, w in zip(got, want):
        assert w.abs().max() > 1e-3
        torch.testing.assert_close(g, w, rtol=1e-12, atol=1e-12)
    # the network on the same batch: per-vertex outputs; the smooth fields need L_c's eigenpairs
    net = models.EdgeFieldNet(8, 3, width=8, vector_width=4, num_blocks=2, head="vertex", fields="local")
    assert net.double()(pair).shape == (pair.num_vertices, 3)
    with pytest.raises(ValueError, match="fields='smooth' needs the eigenpairs of L_c.*k_edge=0"):
        models.EdgeFieldNet(8, 3, width=8, num_blocks=1).double()(pair)


@pytest.mark.parametrize("vector, fields", [("edge", "smooth"), ("edge", "local"), ("vertex", "smooth")])
def test_edge_field_block_gradcheck(vector, fields):
    """Float64 gradcheck of a block in its scalars, its fields and its diffusion times."""
    v, f = perturbed_icosphere(1, 0.08, seed=4)
    batch = _batch(v, f)
    torch.manual_seed(0)
    block = models.EdgeFieldBlock(3, 2, mlp=(4,), dropout=0.0, vector=vector, fields=fields).double()
    with torch.no_grad():  # nonzero times, so that the diffusion is exercised
        block.diffusion.raw_times.fill_(0.05)
    x = torch.randn(batch.num_vertices, 3, dtype=torch.float64, requires_grad=True)
    rows = batch.num_edges if vector == "edge" else batch.num_vertices
    z = torch.randn(rows, 2, dtype=torch.complex128, requires_grad=True)
    times = [block.diffusion] + ([block.field_diffusion] if block.field_diffusion is not None else [])
    raw = [d.raw_times.detach().clone().fill_(0.05).requires_grad_(True) for d in times]
    for d in times:
        del d.raw_times

    def f_(x, z, *t):
        for d, ti in zip(times, t):
            d.raw_times = ti
        y, w = block(x, z, batch)
        return y, torch.view_as_real(w)

    assert torch.autograd.gradcheck(f_, (x, z, *raw))


def test_forward_spectral_needs_edge_fields():
    for options in (dict(vector="vertex"), dict(fields="local")):
        block = models.EdgeFieldBlock(4, 2, **options)
        with pytest.raises(ValueError, match="forward_spectral needs vector='edge' and fields='smooth'"):
            block.forward_spectral(torch.zeros(3, 4), None, None)


@pytest.mark.parametrize(
    "vector, fields", [("edge", "smooth"), ("edge", "local"), ("vertex", "smooth"), ("none", "smooth")]
)
def test_network_gradcheck_in_the_features(vector, fields):
    """Float64 gradcheck through the whole network: blocks and the mean readout."""
    v, f = perturbed_icosphere(1, 0.08, seed=5)
    batch = _batch(v, f)
    torch.manual_seed(0)
    net = models.EdgeFieldNet(
        8, 3, width=4, vector_width=2, num_blocks=2, mlp=(4,), dropout=0.0, vector=vector, fields=fields
    )
    net = net.double()
    with torch.no_grad():
        for block in net.blocks:
            block.diffusion.raw_times.fill_(0.05)
            if block.field_diffusion is not None:
                block.field_diffusion.raw_times.fill_(0.05)
    x0 = batch.features.detach().clone().requires_grad_(True)

    def f_(x):
        batch.features = x
        return net(batch)

    assert torch.autograd.gradcheck(f_, (x0,))


@pytest.mark.parametrize("name", sorted(NETWORKS))
def test_the_batch_is_checked_once_and_the_layers_inside_trust_it(mesh, monkeypatch, name):
    """Validation once, at the boundary: a forward pass runs no check of the layers'
    public functions (each would check the masses again, once per block)."""
    batch = _batch(*mesh)
    net = NETWORKS[name]("global").double()
    calls = []
    for check in ("_check_features", "_check_sparse", "_check_vector"):
        original = getattr(layer_checks, check)
        monkeypatch.setattr(layer_checks, check, lambda *a, _f=original, **k: calls.append(1) or _f(*a, **k))
        for module in (layers.diffusion, layers.gradient, layers.pointwise, layers.pooling):
            if hasattr(module, check):
                monkeypatch.setattr(module, check, getattr(layer_checks, check))
    net(batch)
    assert calls == []
    layers.spectral_diffusion(
        batch.features,
        batch.vertex_evals[0],
        batch.vertex_evecs,
        batch.vertex_mass,
        torch.zeros(8, dtype=torch.float64),
    )
    assert calls  # the public function checks (the counter works)


def test_log_heat_kernel_signatures_and_their_check(mesh):
    """``heat_kernel_signature(..., log=True)`` is the logarithm of the signatures; a
    signature that is not positive (wrong eigenpairs) is named, not a NaN."""
    ops = precompute.compute_operators(*mesh, k_edge=4, k_vertex=16)
    h = precompute.heat_kernel_signature(ops.vertex_evals, ops.vertex_evecs, count=6)
    torch.testing.assert_close(
        precompute.heat_kernel_signature(ops.vertex_evals, ops.vertex_evecs, count=6, log=True), torch.log(h)
    )
    evecs = ops.vertex_evecs.clone()
    evecs[5] = 0.0  # a vertex where every eigenvector vanishes
    with pytest.raises(ValueError, match="log=True needs positive heat kernel signatures.*vertex 5"):
        precompute.heat_kernel_signature(ops.vertex_evals, evecs, count=6, log=True)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(head="edge"), "head must be one of"),
        (dict(vector="face"), "vector must be one of"),
        (dict(dropout=1.0), "dropout must be a probability"),
        (dict(dropout="a"), "dropout must be a probability"),
        (dict(width=0), "width must be a positive integer"),
        (dict(num_blocks=-1), "num_blocks must be a positive integer"),
        (dict(vector_width=0), "vector_width must be a positive integer"),
        (dict(fields="rough"), "fields must be one of"),
        (dict(fields="local", vector="vertex"), "fields='local' needs vector='edge'"),
    ],
)
def test_bad_options_are_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        models.EdgeFieldNet(8, 5, **kwargs)
    if not {"vector", "vector_width", "fields"} & set(kwargs):
        with pytest.raises(ValueError, match=match):
            models.DiffusionNet(8, 5, **kwargs)


def test_dtype_mismatch_is_named_at_the_first_call(mesh):
    for net in (models.EdgeFieldNet(8, 5, width=8, vector_width=4, num_blocks=1), models.DiffusionNet(8, 5)):
        with pytest.raises(ValueError, match="float64.*float32|float32.*float64"):
            net(_batch(*mesh, dtype=torch.float64))


def test_missing_operators_are_named(mesh):
    b = _batch(*mesh)
    b.vertex_gradient = None
    with pytest.raises(ValueError, match="vertex_gradient"):
        models.DiffusionNet(8, 5, width=8, num_blocks=1).double()(b)
    with pytest.raises(ValueError, match="vertex_gradient"):
        models.EdgeFieldNet(8, 5, width=8, num_blocks=1, vector="vertex").double()(b)
    b = _batch(*mesh)
    b.edge_evecs = None
    with pytest.raises(ValueError, match="edge_evecs"):
        models.EdgeFieldNet(8, 5, width=8, num_blocks=1).double()(b)
    with pytest.raises(ValueError, match=r"batch.features must be \(V, 7\)"):
        models.EdgeFieldNet(7, 5, width=8, num_blocks=1).double()(_batch(*mesh))


# --------------------------------------------------------------------------- learning


@pytest.mark.parametrize("fields", ["smooth", "local"])
def test_edge_field_net_learns_generated_shapes(fields):
    train, test = generated_shapes_task(_batch)
    torch.manual_seed(0)
    net = models.EdgeFieldNet(8, 4, width=16, vector_width=8, num_blocks=2, mlp=(16,), fields=fields)
    train_classifier(net, train, epochs=15)
    assert classification_accuracy(net, test) >= 0.75  # chance: 0.25
    assert classification_accuracy(net, train) >= 0.75


@pytest.mark.slow
def test_edge_field_net_learns_psb_classes():
    train, test = psb_classes_task(_batch)
    torch.manual_seed(0)
    net = models.EdgeFieldNet(8, 4, width=32, vector_width=16, num_blocks=2, mlp=(32,))
    train_classifier(net, train, epochs=10)
    assert classification_accuracy(net, test) >= 0.6  # chance: 0.25


# --------------------------------------------------------------------------- one dtype


def test_compute_operators_in_the_dtype_asked_for(mesh):
    ops = precompute.compute_operators(*mesh, k_edge=4, k_vertex=4, dtype=torch.float32)
    assert ops.edge_mass.dtype == torch.float32 and ops.verts.dtype == torch.float32
    assert ops.gradient.dtype == torch.complex64 and ops.edge_evecs.dtype == torch.complex64
    with pytest.raises(ValueError, match="dtype"):
        precompute.compute_operators(*mesh, k_edge=4, k_vertex=4, dtype=torch.float16)


def test_collate_names_a_features_and_operators_mismatch(mesh):
    ops = precompute.compute_operators(*mesh, k_edge=4, k_vertex=4)
    x = torch.ones(ops.num_vertices, 3, dtype=torch.float32)
    with pytest.raises(ValueError, match="float32 features but torch.float64 operators"):
        batching.collate_meshes([batching.MeshSample(ops, x, 0)])


@pytest.mark.filterwarnings("error")
def test_data_loader_workers_print_no_torch_warning(mesh):
    ops = precompute.compute_operators(*mesh, k_edge=4, k_vertex=4, vertex_gradient=True, dtype=torch.float32)
    x = precompute.heat_kernel_signature(ops.vertex_evals, ops.vertex_evecs, count=3)
    items = [batching.MeshSample(ops, x, i % 2, index=i) for i in range(4)]
    loader = torch.utils.data.DataLoader(
        items, batch_size=2, collate_fn=batching.collate_meshes, num_workers=1
    )
    batches = list(loader)  # a warning raised while unpickling in this process fails the test
    assert [int(b.num_meshes) for b in batches] == [2, 2]
    assert batches[0].gradient.layout == torch.sparse_coo and batches[0].gradient.is_coalesced()
    single = batching.collate_meshes(items[:2])
    torch.testing.assert_close(batches[0].gradient.to_dense(), single.gradient.to_dense())


# --------------------------------------------------------------------------- spectrum readout
