"""The study's networks (experiments/psb_classification/variants.py), with every switch.

Invariance of the outputs to rigid motions and to vertex renumbering, gradchecks in
float64, the switches (high-pass, local fields, divergence, dropout of the streams, field
readout, spectrum, log input, mean-and-deviation readout), and learning on generated shapes
and PSB classes. The library's networks are tested in tests/learning/test_models.py; that
they are the study's networks of the same names is tested here.
"""

import dataclasses

import numpy as np
import pytest
import torch

from torch_edgevf.learning import batching
from torch_edgevf.learning import models as library
from torch_edgevf.learning.layers import pool_edges_to_vertices

from conftest import (
    classification_accuracy,
    generated_shapes_task,
    perturbed_icosphere,
    psb_classes_task,
    random_rotation,
    train_classifier,
)
from study import one_batch, sample, variants_common
from study import variants as models


@pytest.fixture(scope="module")
def mesh():
    v, f = perturbed_icosphere(2, 0.08, seed=3)
    return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)


def _small_edge_net(**options):
    """A small EdgeFieldNet with ``options``, as a function of its head."""
    return lambda head: models.StudyEdgeFieldNet(
        8, 5, width=8, vector_width=4, num_blocks=2, mlp=(8,), head=head, **options
    )


NETWORKS = {
    "edge": _small_edge_net(log_features=True),
    "edge-meanpool": _small_edge_net(pool="mean"),
    "edge-highpass": _small_edge_net(log_features=True, high_pass=True),
    "edge-local": _small_edge_net(log_features=True, field_diffusion=False),
    "edge-nodiv-meanpool": _small_edge_net(log_features=True, divergence=False, pool="mean"),
    "edge-dropout": _small_edge_net(vector_dropout=0.5, head_dropout=0.5),
    "edge-fieldread": _small_edge_net(log_features=True, readout_fields=True),
    "edge-vertex-fieldread": _small_edge_net(vector="vertex", readout_fields=True),
    "edge-vertex": _small_edge_net(vector="vertex"),
    "diffusionnet": lambda head: models.StudyDiffusionNet(8, 5, width=8, num_blocks=2, mlp=(8,), head=head),
    "diffusionnet-logstd": lambda head: models.StudyDiffusionNet(
        8, 5, width=8, num_blocks=2, mlp=(8,), head=head, pool="mean_std", log_features=True
    ),
}


@pytest.mark.parametrize("name", sorted(NETWORKS))
@pytest.mark.parametrize("head", ["global", "vertex", "face"])
def test_outputs_are_invariant_to_rigid_motion_and_renumbering(mesh, name, head):
    v, f = mesh
    torch.manual_seed(0)
    net = NETWORKS[name](head).double().eval()
    with torch.no_grad():  # the high-pass weights start at zero: make them act
        for block in getattr(net, "blocks", ()):
            if getattr(block, "high_pass", None) is not None:
                block.high_pass.normal_()
    perm = np.random.default_rng(1).permutation(v.shape[0])
    inverse = np.argsort(perm)
    v2 = (v @ random_rotation().T + np.array([0.3, -1.0, 2.0]))[perm]
    f2 = inverse[f][:, [1, 2, 0]]  # renumbered vertices, rotated corners
    with torch.no_grad():
        a, b = net(one_batch(v, f)), net(one_batch(v2, f2))
    if head == "vertex":
        b = b[inverse]
    assert a.abs().max() > 1e-3  # not a trivial output
    torch.testing.assert_close(b, a, rtol=1e-6, atol=1e-8)


def test_edge_field_block_without_field_diffusion_gradcheck():
    v, f = perturbed_icosphere(1, 0.08, seed=4)
    batch = one_batch(v, f)
    torch.manual_seed(0)
    block = models.StudyEdgeFieldBlock(3, 2, mlp=(4,), dropout=0.0, field_diffusion=False).double()
    x = torch.randn(batch.num_vertices, 3, dtype=torch.float64, requires_grad=True)
    z = torch.randn(batch.num_edges, 2, dtype=torch.complex128, requires_grad=True)

    def f(x, z):  # the block once per evaluation: its scalars and its fields as real numbers
        y, w = block(x, z, batch)
        return y, torch.view_as_real(w)

    assert torch.autograd.gradcheck(f, (x, z))


@pytest.mark.parametrize("high_pass", [False, True])
def test_edge_field_block_gradcheck(mesh, high_pass):
    v, f = perturbed_icosphere(1, 0.08, seed=4)
    batch = one_batch(v, f)
    torch.manual_seed(0)
    block = models.StudyEdgeFieldBlock(3, 2, mlp=(4,), dropout=0.0, high_pass=high_pass).double()
    if high_pass:  # the weight of the high-pass term, nonzero (it starts at zero)
        with torch.no_grad():
            block.high_pass.normal_()
    with torch.no_grad():  # nonzero times, so that the diffusion is exercised
        block.diffusion.raw_times.fill_(0.05)
        block.field_diffusion.raw_times.fill_(0.05)
    x = torch.randn(batch.num_vertices, 3, dtype=torch.float64, requires_grad=True)
    z = torch.randn(batch.num_edges, 2, dtype=torch.complex128, requires_grad=True)

    def f_(x, z, t, s):
        block.diffusion.raw_times, block.field_diffusion.raw_times = t, s
        y, w = block(x, z, batch)
        return y, torch.view_as_real(w)

    t = block.diffusion.raw_times.detach().clone().requires_grad_(True)
    s = block.field_diffusion.raw_times.detach().clone().requires_grad_(True)
    del block.diffusion.raw_times, block.field_diffusion.raw_times
    assert torch.autograd.gradcheck(f_, (x, z, t, s))
    if high_pass:  # and in the high-pass weight
        w0 = block.high_pass.detach().clone().requires_grad_(True)
        del block.high_pass

        def g_(w):
            block.high_pass = w
            return torch.view_as_real(block(x.detach(), z.detach(), batch)[1])

        assert torch.autograd.gradcheck(g_, (w0,))


def _block_on_the_edges(block, x, z, batch, keep=None):
    """The block as its formula reads, every field on the edges (a reference for the
    eigenbasis path of :meth:`EdgeFieldBlock.forward`)."""
    L = models  # the layer functions the models import
    xd = L._diffuse_vertices(block.diffusion, x, batch)
    a = torch.view_as_complex(block.lift(xd).unflatten(1, (block.vector_width, 2)).contiguous())
    u = L.gradient_features(a, batch.gradient, batch.edge_mass)
    if z is not None and block.mix is not None:
        u = u + block.mix(z)
    if keep is not None:
        u = u * keep[batch.edge_batch].to(u.real.dtype)[:, None]
    ud = block.field_diffusion(
        u, batch.edge_mass, evals=batch.edge_evals, evecs=batch.edge_evecs, offsets=batch.edge_offsets
    )
    inv = torch.tanh((ud * L.complex_linear(ud, block.products).conj()).real)
    inv = pool_edges_to_vertices(inv, batch.edges, batch.num_vertices, batch.edge_mass)
    feats = [x, xd, inv]
    if block.divergence:
        dc = L.divergence_features(ud, batch.gradient, batch.vertex_mass)
        feats += [torch.tanh(dc.real), torch.tanh(dc.imag)]
    return x + block.mlp(torch.cat(feats, dim=1)), ud if z is None else z + ud


@pytest.mark.parametrize("keep, divergence", [(None, True), ([True, False], True), (None, False)])
def test_the_fields_as_eigenbasis_coefficients_are_the_fields_on_the_edges(mesh, keep, divergence):
    """The block works on the fields' coefficients in the edge eigenbasis: the same numbers
    as every field on the edges, on a batch of two meshes, with and without a mesh whose
    vector stream is dropped, and without the divergence and curl features, for the
    scalars, the fields and the gradients."""
    pair = batching.collate_meshes([sample(*mesh), sample(*perturbed_icosphere(1, 0.05, seed=7))])
    torch.manual_seed(0)
    block = models.StudyEdgeFieldBlock(8, 4, mlp=(8,), dropout=0.0, divergence=divergence).double()
    assert block.mlp[0].in_features == 2 * 8 + (3 if divergence else 1) * 4
    with torch.no_grad():
        block.diffusion.raw_times.uniform_(0.0, 0.05)
        block.field_diffusion.raw_times.uniform_(0.01, 0.2)
    x = torch.randn(pair.num_vertices, 8, dtype=torch.float64, requires_grad=True)
    z = torch.randn(pair.num_edges, 4, dtype=torch.complex128, requires_grad=True)
    mask = None if keep is None else torch.tensor(keep)
    got = block(x, z, pair, mask)
    want = _block_on_the_edges(block, x, z, pair, mask)
    for g, w in zip(got, want):
        assert w.abs().max() > 1e-3
        torch.testing.assert_close(g, w, rtol=1e-10, atol=1e-12)
    grads = [
        torch.autograd.grad(sum(t.abs().square().sum() for t in out), (x, z, *block.parameters()))
        for out in (got, want)
    ]
    for g, w in zip(*grads):
        torch.testing.assert_close(g, w, rtol=1e-9, atol=1e-12)


def test_the_network_on_coefficients_is_the_network_on_the_edges(mesh):
    """EdgeFieldNet carries the fields of its blocks as coefficients; with the high-pass
    term (zero weight) it carries them on the edges: the same outputs."""
    batch = one_batch(*mesh)
    torch.manual_seed(0)
    a = models.StudyEdgeFieldNet(8, 5, width=8, vector_width=4, num_blocks=3, mlp=(8,), readout_fields=True)
    torch.manual_seed(0)
    b = models.StudyEdgeFieldNet(
        8, 5, width=8, vector_width=4, num_blocks=3, mlp=(8,), readout_fields=True, high_pass=True
    )
    a, b = a.double().eval(), b.double().eval()
    with torch.no_grad():
        for blocks in zip(a.blocks, b.blocks):
            t = torch.rand(4, dtype=torch.float64) * 0.2
            for block in blocks:
                block.field_diffusion.raw_times.copy_(t)
        torch.testing.assert_close(a(batch), b(batch), rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("kwargs", [dict(vector="vertex"), dict(vector="none"), dict(high_pass=True)])
def test_forward_spectral_needs_edge_fields_without_high_pass(kwargs):
    block = models.StudyEdgeFieldBlock(4, 2, **kwargs)
    assert not block.spectral
    with pytest.raises(ValueError, match="forward_spectral needs"):
        block.forward_spectral(torch.zeros(3, 4), None, None)


def test_high_pass_starts_as_the_network_without_it(mesh):
    """Zero-initialised and drawing no random numbers: the same seed gives the same network."""
    batch = one_batch(*mesh)
    torch.manual_seed(0)
    a = models.StudyEdgeFieldNet(8, 5, width=8, vector_width=4, num_blocks=2, mlp=(8,)).double().eval()
    torch.manual_seed(0)
    b = models.StudyEdgeFieldNet(8, 5, width=8, vector_width=4, num_blocks=2, mlp=(8,), high_pass=True)
    b = b.double().eval()
    with torch.no_grad():  # the same up to rounding (b carries its fields on the edges)
        torch.testing.assert_close(b(batch), a(batch), rtol=1e-12, atol=1e-14)
        for block in b.blocks:
            block.high_pass.normal_()
        assert (b(batch) - a(batch)).abs().max() > 1e-6  # and the weight acts


@pytest.mark.parametrize("cls", [models.StudyEdgeFieldNet, models.StudyDiffusionNet])
@pytest.mark.parametrize("pool", ["mean_std", "mean"])
def test_dropout_options_act_in_training_only(mesh, cls, pool):
    """Dropout on the readout (and the vector stream): same weights, same eval output; random in training."""
    batch = one_batch(*mesh)
    small = dict(width=8, num_blocks=2, mlp=(8,), dropout=0.0, pool=pool)
    if cls is models.StudyEdgeFieldNet:
        small["vector_width"] = 4
    extra = dict(head_dropout=0.5, **({"vector_dropout": 0.5} if cls is models.StudyEdgeFieldNet else {}))
    torch.manual_seed(0)
    plain = cls(8, 5, **small).double()
    torch.manual_seed(0)
    dropped = cls(8, 5, **small, **extra).double()  # no random numbers drawn at construction
    assert all(torch.equal(p, q) for p, q in zip(plain.state_dict().values(), dropped.state_dict().values()))
    with torch.no_grad():
        torch.testing.assert_close(dropped.eval()(batch), plain.eval()(batch), rtol=0, atol=0)
        dropped.train()
        torch.manual_seed(1)
        first = dropped(batch)
        assert (first - dropped(batch)).abs().max() > 1e-6
        torch.manual_seed(1)
        torch.testing.assert_close(dropped(batch), first, rtol=0, atol=0)  # the seed decides
        plain.train()
        assert (first - plain(batch)).abs().max() > 1e-6


@pytest.mark.parametrize("vector", ["edge", "vertex"])
def test_a_mesh_without_its_vector_stream_is_alone_in_a_batch(mesh, vector):
    """keep=[True, False] on a batch of two: each mesh's output is its own, the first with
    its fields, the second as the block's path that skips the fields entirely."""
    v, f = mesh
    first, second = sample(v, f), sample(*perturbed_icosphere(1, 0.05, seed=7))
    pair = batching.collate_meshes([first, second])
    torch.manual_seed(0)
    block = models.StudyEdgeFieldBlock(8, 4, mlp=(8,), dropout=0.0, vector=vector).double()
    with torch.no_grad():
        block.diffusion.raw_times.fill_(0.01)
        x = torch.randn(pair.features.shape[0], 8, dtype=torch.float64)
        z0 = torch.randn(pair.edges.shape[0] if vector == "edge" else x.shape[0], 4, dtype=torch.complex128)
        keep = torch.tensor([True, False])
        xb, zb = block(
            x, z0 * keep[pair.edge_batch if vector == "edge" else pair.vertex_batch, None], pair, keep
        )
        n0 = first.operators.num_vertices
        e0 = first.operators.num_edges if vector == "edge" else n0
        alone = [batching.collate_meshes([s]) for s in (first, second)]
        x0, z1 = block(x[:n0], z0[:e0], alone[0])
        x1, z2 = block(x[n0:], None, alone[1], torch.tensor([False]))
    torch.testing.assert_close(xb[:n0], x0)
    torch.testing.assert_close(zb[:e0], z1)
    torch.testing.assert_close(xb[n0:], x1)
    assert z2 is None and zb[e0:].abs().max() == 0  # no fields where the stream is dropped
    assert (x1 - x[n0:]).abs().max() > 1e-6  # the scalar stream still acts


def test_stream_dropout_trains_on_both_networks_and_evaluates_the_full_one(mesh):
    """Same seed, same weights and the same output in evaluation as without it; in training
    each forward is either the full network or the one without its vector stream."""
    batch = one_batch(*mesh)
    small = dict(width=8, vector_width=4, num_blocks=2, mlp=(8,), dropout=0.0)
    torch.manual_seed(0)
    plain = models.StudyEdgeFieldNet(8, 5, **small).double()
    torch.manual_seed(0)
    dropped = models.StudyEdgeFieldNet(8, 5, **small, stream_dropout=0.5).double()
    assert all(torch.equal(p, q) for p, q in zip(plain.state_dict().values(), dropped.state_dict().values()))
    with torch.no_grad():
        full = plain.eval()(batch)
        torch.testing.assert_close(dropped.eval()(batch), full, rtol=0, atol=0)
        dropped.train()
        outs = [dropped(batch) for _ in range(24)]
        scalar = [o for o in outs if (o - full).abs().max() > 1e-9]
        assert 0 < len(scalar) < len(outs)  # both networks are drawn
        for o in scalar[1:]:
            torch.testing.assert_close(o, scalar[0], rtol=0, atol=0)
        assert (scalar[0] - full).abs().max() > 1e-6


def test_the_field_readout_reads_the_fields(mesh):
    """With readout_fields the rest is initialised as without it, and the output moves with
    the fields' readout weights."""
    batch = one_batch(*mesh)
    small = dict(width=8, vector_width=4, num_blocks=2, mlp=(8,), dropout=0.0)
    torch.manual_seed(0)
    plain = models.StudyEdgeFieldNet(8, 5, **small).double().eval()
    torch.manual_seed(0)
    read = models.StudyEdgeFieldNet(8, 5, **small, readout_fields=True).double().eval()
    shared = {
        k: v for k, v in read.state_dict().items() if k != "field_products" and not k.startswith("last.")
    }
    assert all(torch.equal(v, plain.state_dict()[k]) for k, v in shared.items())
    assert read.last.in_features == 2 * (8 + 4)
    with torch.no_grad():
        a = read(batch)
        read.field_products.mul_(-2.0)
        assert (read(batch) - a).abs().max() > 1e-6


def test_field_readout_options_are_checked():
    with pytest.raises(ValueError, match="readout_fields needs a vector stream"):
        models.StudyEdgeFieldNet(8, 5, vector="none", readout_fields=True)
    with pytest.raises(ValueError, match="readout_fields must be True or False"):
        models.StudyEdgeFieldNet(8, 5, readout_fields=1)


def _local_block_on_the_edges(block, x, z, batch):
    """The block with ``field_diffusion=False`` as its formula reads: the gradients of the
    lifted scalars plus the carried fields, neither diffused nor projected."""
    xd = variants_common._diffuse_vertices(block.diffusion, x, batch)
    a = torch.view_as_complex(block.lift(xd).unflatten(1, (block.vector_width, 2)).contiguous())
    u = torch.linalg.solve(torch.diag(batch.edge_mass).to(a.dtype), batch.gradient.to_dense().to(a.dtype) @ a)
    u = u + block.mix(z)
    inv = torch.tanh((u * models.complex_linear(u, block.products).conj()).real)
    inv = pool_edges_to_vertices(inv, batch.edges, batch.num_vertices, batch.edge_mass)
    dc = -(batch.gradient.to_dense().to(u.dtype).mH @ u) / batch.vertex_mass[:, None]
    feats = [x, xd, inv, torch.tanh(dc.real), torch.tanh(dc.imag)]
    return x + block.mlp(torch.cat(feats, dim=1)), z + u


def test_fields_not_diffused_are_the_gradients_on_the_edges(mesh):
    """``field_diffusion=False``: the block's fields are ``M_z^{-1} G a`` plus the carried
    fields, and its divergence and curl those of these fields, by dense algebra; the
    network needs no eigenpair of ``L_c``."""
    batch = one_batch(*mesh)
    torch.manual_seed(0)
    block = models.StudyEdgeFieldBlock(8, 4, mlp=(8,), dropout=0.0, field_diffusion=False).double()
    assert block.field_diffusion is None and not block.spectral
    with torch.no_grad():
        block.diffusion.raw_times.uniform_(0.0, 0.05)
    x = torch.randn(batch.num_vertices, 8, dtype=torch.float64)
    z = torch.randn(batch.num_edges, 4, dtype=torch.complex128)
    got, want = block(x, z, batch), _local_block_on_the_edges(block, x, z, batch)
    for g, w in zip(got, want):
        torch.testing.assert_close(g, w, rtol=1e-10, atol=1e-12)
    # not the diffused block: the eigenbasis holds only the lowest modes
    torch.manual_seed(0)
    diffused = models.StudyEdgeFieldBlock(8, 4, mlp=(8,), dropout=0.0).double()
    diffused.load_state_dict(block.state_dict(), strict=False)
    assert (diffused(x, z, batch)[1] - got[1]).abs().max() > 1e-2
    net = (
        models.StudyEdgeFieldNet(8, 5, width=8, vector_width=4, mlp=(8,), field_diffusion=False)
        .double()
        .eval()
    )
    without = dataclasses.replace(batch, edge_evals=None, edge_evecs=None)
    with torch.no_grad():
        torch.testing.assert_close(net(without), net(batch))


def test_field_diffusion_option_is_checked():
    with pytest.raises(ValueError, match="field_diffusion=False needs vector='edge'"):
        models.StudyEdgeFieldNet(8, 5, vector="vertex", field_diffusion=False)
    with pytest.raises(ValueError, match="field_diffusion must be True or False"):
        models.StudyEdgeFieldNet(8, 5, field_diffusion="no")
    with pytest.raises(ValueError, match="high_pass=True needs field_diffusion=True"):
        models.StudyEdgeFieldNet(8, 5, field_diffusion=False, high_pass=True)


def test_divergence_option_is_checked_and_reaches_every_block(mesh):
    with pytest.raises(ValueError, match="divergence=False needs vector='edge'"):
        models.StudyEdgeFieldNet(8, 5, vector="vertex", divergence=False)
    with pytest.raises(ValueError, match="divergence must be True or False"):
        models.StudyEdgeFieldNet(8, 5, divergence=0)
    net = models.StudyEdgeFieldNet(8, 5, width=8, vector_width=4, mlp=(8,), divergence=False).double().eval()
    assert all(b.mlp[0].in_features == 2 * 8 + 4 for b in net.blocks)
    with torch.no_grad():
        assert torch.isfinite(net(one_batch(*mesh))).all()


def test_stream_dropout_needs_a_vector_stream():
    with pytest.raises(ValueError, match="stream_dropout needs a vector stream"):
        models.StudyEdgeFieldNet(8, 5, vector="none", stream_dropout=0.5)
    with pytest.raises(ValueError, match="stream_dropout must be a probability"):
        models.StudyEdgeFieldNet(8, 5, stream_dropout=1.0)


@pytest.mark.parametrize(
    "kwargs", [dict(head_dropout=1.0), dict(vector_dropout=-0.1), dict(head_dropout="a")]
)
def test_bad_dropout_is_named(kwargs):
    with pytest.raises(ValueError, match="must be a probability in"):
        models.StudyEdgeFieldNet(8, 5, **kwargs)
    if "head_dropout" in kwargs:
        with pytest.raises(ValueError, match="head_dropout must be a probability"):
            models.StudyDiffusionNet(8, 5, **kwargs)


@pytest.mark.parametrize("log_features", [False, True])
def test_network_gradcheck_in_the_features(log_features):
    """Float64 gradcheck through the whole network: log input, blocks, mean-and-deviation readout."""
    v, f = perturbed_icosphere(1, 0.08, seed=5)
    batch = one_batch(v, f)
    torch.manual_seed(0)
    net = models.StudyEdgeFieldNet(8, 3, width=4, vector_width=2, num_blocks=2, mlp=(4,), dropout=0.0)
    net.log_features = log_features
    net = net.double()
    with torch.no_grad():
        for block in net.blocks:
            block.diffusion.raw_times.fill_(0.05)
            block.field_diffusion.raw_times.fill_(0.05)
    x0 = batch.features.detach().clone().requires_grad_(True)

    def f_(x):
        batch.features = x
        return net(batch)

    assert torch.autograd.gradcheck(f_, (x0,))


def test_mean_std_readout_separates_what_the_mean_does_not(mesh):
    """Two meshes whose last features have the same mean but different spreads get
    different logits from the mean-and-deviation readout and equal ones from the mean."""
    b = one_batch(*mesh)
    x = torch.randn(b.num_vertices, 4, dtype=torch.float64)
    w = b.vertex_mass
    x = x - (w[:, None] * x).sum(0) / w.sum()  # mass-weighted mean 0
    last = torch.nn.Linear(8, 2).double()
    a = variants_common._readout(x, last, b, "global", "mean_std")
    c = variants_common._readout(3 * x, last, b, "global", "mean_std")
    assert not torch.allclose(a, c)
    mean_last = torch.nn.Linear(4, 2).double()
    torch.testing.assert_close(
        variants_common._readout(x, mean_last, b, "global", "mean"),
        variants_common._readout(3 * x, mean_last, b, "global", "mean"),
    )


def test_log_features_need_positive_features(mesh):
    b = one_batch(*mesh)
    b.features = b.features.clone()
    b.features[7, 2] = -0.5
    net = models.StudyEdgeFieldNet(8, 5, width=8, vector_width=4, num_blocks=1, log_features=True).double()
    with pytest.raises(ValueError, match="positive features.*vertex 7, channel 2"):
        net(b)
    b.features[7, 2] = float("nan")
    with pytest.raises(ValueError, match="vertex 7, channel 2"):
        net(b)


@pytest.mark.parametrize("cls", [models.StudyEdgeFieldNet, models.StudyDiffusionNet])
def test_log_features_of_the_first_channels_only(mesh, cls):
    """``log_features=k`` takes the logarithm of the first ``k`` channels and passes the
    rest (signed features) as they are; a non-positive value among the first ``k`` is named."""
    b = one_batch(*mesh)
    signed = torch.randn(b.num_vertices, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    b.features = torch.cat([b.features, signed], dim=1)
    torch.manual_seed(0)
    net = cls(11, 5, width=8, num_blocks=1, log_features=8).double()
    expected = torch.cat([torch.log(b.features[:, :8]), signed], dim=1)
    torch.testing.assert_close(variants_common._inputs(net.log_features, b), expected)
    assert torch.isfinite(net(b)).all()
    b.features[3, 5] = 0.0
    with pytest.raises(ValueError, match="log_features=8 needs positive features.*vertex 3, channel 5"):
        net(b)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(pool="max"), "pool must be one of"),
        (dict(log_features=0), r"log_features must be True, False or a number of channels in \[1, 8\]"),
        (dict(log_features=9), r"number of channels in \[1, 8\], got 9"),
        (dict(log_features=2.5), "log_features must be True, False"),
    ],
)
def test_bad_readout_options_are_named(kwargs, match):
    for cls in (models.StudyEdgeFieldNet, models.StudyDiffusionNet):
        with pytest.raises(ValueError, match=match):
            cls(8, 5, **kwargs)


def test_dtype_mismatch_is_named_at_the_first_call(mesh):
    net = models.StudyEdgeFieldNet(8, 5, width=8, vector_width=4, num_blocks=1)
    with pytest.raises(ValueError, match="float64.*float32|float32.*float64"):
        net(one_batch(*mesh, dtype=torch.float64))


def test_missing_operators_are_named(mesh):
    b = one_batch(*mesh)
    b.vertex_gradient = None
    with pytest.raises(ValueError, match="vertex_gradient"):
        models.StudyDiffusionNet(8, 5, width=8, num_blocks=1).double()(b)


# --------------------------------------------------------------------------- learning


# The recommended network and the previous recommendation (mean and deviation readout, with
# the divergence and curl).
LEARNERS = {
    "recommended": dict(log_features=True, divergence=False, pool="mean"),
    "mean-std": dict(log_features=True),
}


@pytest.mark.parametrize("options", LEARNERS.values(), ids=LEARNERS.keys())
def test_edge_field_net_learns_generated_shapes(options):
    train, test = generated_shapes_task(one_batch)
    torch.manual_seed(0)
    net = models.StudyEdgeFieldNet(8, 4, width=16, vector_width=8, num_blocks=2, mlp=(16,), **options)
    train_classifier(net, train, epochs=15)
    assert classification_accuracy(net, test) >= 0.75  # chance: 0.25
    assert classification_accuracy(net, train) >= 0.75


@pytest.mark.slow
@pytest.mark.parametrize("options", LEARNERS.values(), ids=LEARNERS.keys())
def test_edge_field_net_learns_psb_classes(options):
    train, test = psb_classes_task(one_batch)
    torch.manual_seed(0)
    net = models.StudyEdgeFieldNet(8, 4, width=32, vector_width=16, num_blocks=2, mlp=(32,), **options)
    train_classifier(net, train, epochs=10)
    assert classification_accuracy(net, test) >= 0.6  # chance: 0.25


# --------------------------------------------------------------------------- spectrum readout


SPECTRUM_NETWORKS = {
    "edge": lambda: models.StudyEdgeFieldNet(
        8, 5, width=8, vector_width=4, num_blocks=2, mlp=(8,), log_features=True, spectrum=12
    ),
    "diffusionnet": lambda: models.StudyDiffusionNet(8, 5, width=8, num_blocks=2, mlp=(8,), spectrum=12),
    "diffusionnet-laplacian": lambda: models.StudyDiffusionNet(
        8, 5, width=8, num_blocks=2, mlp=(8,), spectrum=12, spectrum_of="laplacian"
    ),
}


@pytest.mark.parametrize("name", sorted(SPECTRUM_NETWORKS))
def test_spectrum_readout_is_invariant_and_reads_the_spectrum(mesh, name):
    """With ``spectrum`` the rest of the network is initialised as without it; the
    logits are invariant to rigid motions and renumbering, and move with the spectrum's
    weights."""
    v, f = mesh
    torch.manual_seed(0)
    net = SPECTRUM_NETWORKS[name]().double().eval()
    torch.manual_seed(0)
    plain = (models.StudyEdgeFieldNet if name == "edge" else models.StudyDiffusionNet)(
        8,
        5,
        width=8,
        **({"vector_width": 4, "log_features": True} if name == "edge" else {}),
        num_blocks=2,
        mlp=(8,),
    ).double()
    shared = {k: w for k, w in net.state_dict().items() if not k.startswith("spectrum.")}
    assert shared.keys() == plain.state_dict().keys()
    assert all(torch.equal(w, plain.state_dict()[k]) for k, w in shared.items())
    perm = np.random.default_rng(1).permutation(v.shape[0])
    inverse = np.argsort(perm)
    v2, f2 = (v @ random_rotation().T + np.array([0.3, -1.0, 2.0]))[perm], inverse[f][:, [1, 2, 0]]
    with torch.no_grad():
        a, b = net(one_batch(v, f)), net(one_batch(v2, f2))
        torch.testing.assert_close(b, a, rtol=1e-6, atol=1e-8)
        net.spectrum.weight.mul_(-3.0)
        assert (net(one_batch(v, f)) - a).abs().max() > 1e-3


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(spectrum=-1), "spectrum must be an int >= 0, got -1"),
        (dict(spectrum=True), "spectrum must be an int >= 0, got True"),
        (dict(spectrum=2.5), "spectrum must be an int >= 0, got 2.5"),
        (dict(spectrum=8, head="vertex"), "spectrum needs head='global'"),
        (dict(spectrum=8, spectrum_of="hodge"), "spectrum_of must be one of"),
    ],
)
def test_bad_spectrum_is_named(kwargs, match):
    for cls in (models.StudyEdgeFieldNet, models.StudyDiffusionNet):
        with pytest.raises(ValueError, match=match):
            cls(8, 5, **kwargs)


def test_spectrum_larger_than_the_eigenpairs_is_named_at_the_first_call(mesh):
    net = models.StudyEdgeFieldNet(8, 5, width=8, vector_width=4, num_blocks=1, spectrum=32).double()
    with pytest.raises(ValueError, match="k_edge=32"):
        net(one_batch(*mesh))


# --------------------------------------------------------------------------- the library's networks


@pytest.mark.parametrize("name", sorted(models.LIBRARY_MODELS))
def test_the_library_networks_are_the_study_networks_of_their_names(mesh, name):
    """Each model the study runs from the library (the recommended network on log-HKS, its
    ablations of the vector stream, the DiffusionNets) is the study's network of that name:
    the same weights for a seed and the same outputs, in evaluation and in training (the
    same dropout masks), so that the saved runs are runs of the library's networks."""
    pair = batching.collate_meshes([sample(*mesh), sample(*perturbed_icosphere(1, 0.05, seed=7), 1)])
    torch.manual_seed(0)
    study = models.STUDY_MODELS[name](8, 5, True).double()
    torch.manual_seed(0)
    lib = models.LIBRARY_MODELS[name](8, 5, True).double()
    assert isinstance(getattr(lib, "net", lib), (library.EdgeFieldNet, library.DiffusionNet))
    mine = {k.removeprefix("net."): w for k, w in lib.state_dict().items()}
    theirs = study.state_dict()
    assert list(mine) == list(theirs) and all(torch.equal(w, theirs[k]) for k, w in mine.items())
    with torch.no_grad():
        for block in study.blocks:  # nonzero times, so that the diffusions act
            block.diffusion.raw_times.uniform_(0.0, 0.05)
            if getattr(block, "field_diffusion", None) is not None:
                block.field_diffusion.raw_times.uniform_(0.0, 0.2)
    lib.load_state_dict(
        {("net." if hasattr(lib, "net") else "") + k: w for k, w in study.state_dict().items()}
    )
    for training in (False, True):
        study.train(training), lib.train(training)
        torch.manual_seed(1)
        want = study(pair)
        torch.manual_seed(1)
        torch.testing.assert_close(lib(pair), want, rtol=0, atol=0)
