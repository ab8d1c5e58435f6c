"""Data: per-mesh operators, the on-disk cache, batching (with DataLoader workers), PSB."""

import logging

import numpy as np
import pytest
import scipy.linalg
import torch

import torch_edgevf as ev
from torch_edgevf.learning import cache as cache_module
from torch_edgevf.learning import progress as progress_module
from torch_edgevf.learning.batching import MeshSample, collate_meshes
from torch_edgevf.learning.cache import OperatorCache
from torch_edgevf.learning.datasets import PSBDataset, psb_path
from torch_edgevf.learning.precompute import (
    compute_operators,
    heat_kernel_signature,
    mean_curvature_signature,
)
from torch_edgevf.learning.progress import progress
from torch_edgevf.mesh.repair import find_degenerate_faces, repair_degenerate_faces

from conftest import perturbed_icosphere, psb_file


@pytest.fixture(scope="module")
def two_meshes():
    out = []
    for level, seed in ((1, 0), (2, 1)):
        v, f = perturbed_icosphere(level, 0.05, seed=seed)
        o = compute_operators(v, f, k_edge=8, k_vertex=6, vertex_gradient=True)
        x = heat_kernel_signature(o.vertex_evals, o.vertex_evecs, count=4, area=o.face_area.sum())
        out.append(MeshSample(o, x, level, level))
    return out


def _dense_pairs(A, m, k):
    w, X = scipy.linalg.eigh(A.to_dense().numpy(), np.diag(m.numpy()))
    return w[:k], X[:, :k]


@pytest.mark.parametrize("level", [1, 2])  # dense path (E = 120) and ARPACK path (E = 480)
def test_compute_operators_eigenpairs(level):
    v, f = perturbed_icosphere(level, 0.05, seed=2)
    o = compute_operators(v, f, k_edge=6, k_vertex=5, vertex_laplacian="edge")
    o.check()
    topo = ev.Topology(f, v.shape[0])
    w, X = _dense_pairs(ev.connection_laplacian(v, topo, 1), o.edge_mass, 6)
    np.testing.assert_allclose(o.edge_evals.numpy(), w, rtol=1e-8, atol=1e-8)
    gram = o.edge_evecs.conj().T @ (o.edge_mass[:, None] * o.edge_evecs)
    torch.testing.assert_close(gram, torch.eye(6, dtype=gram.dtype), atol=1e-8, rtol=0)
    # same subspace as the dense eigenvectors
    P = X @ X.conj().T @ np.diag(o.edge_mass.numpy())
    np.testing.assert_allclose(P @ o.edge_evecs.numpy(), o.edge_evecs.numpy(), atol=1e-6)
    wv, _ = _dense_pairs(ev.laplace_beltrami(v, topo), o.vertex_mass, 5)
    np.testing.assert_allclose(o.vertex_evals.numpy(), np.maximum(wv, 0), rtol=1e-8, atol=1e-8)
    assert o.vertex_gradient is None and o.gradient.shape == (topo.num_edges, topo.num_vertices)


def test_heat_kernel_signature_invariances():
    v, f = perturbed_icosphere(1, 0.05, seed=3)
    o = compute_operators(v, f, k_edge=4, k_vertex=8)
    o2 = compute_operators(3.0 * v, f, k_edge=4, k_vertex=8)
    h = heat_kernel_signature(o.vertex_evals, o.vertex_evecs, count=5, area=o.face_area.sum())
    h2 = heat_kernel_signature(o2.vertex_evals, o2.vertex_evecs, count=5, area=o2.face_area.sum())
    torch.testing.assert_close(h2, h)  # scale normalised
    flipped = o.vertex_evecs * torch.tensor([1.0, -1.0] * 4, dtype=torch.float64)
    torch.testing.assert_close(
        heat_kernel_signature(o.vertex_evals, flipped, count=5),
        heat_kernel_signature(o.vertex_evals, o.vertex_evecs, count=5),
    )
    with pytest.raises(ValueError, match="do not match"):
        heat_kernel_signature(o.vertex_evals[:3], o.vertex_evecs)


def _constant_basis(v, f):
    """The one-vector eigenbasis of any vertex Laplacian (the M-orthonormal constant), and the mass."""
    o = ev.vertex_mass(v, ev.Topology(f, v.shape[0]), lumped=True).values()
    return torch.zeros(1, dtype=o.dtype), (torch.ones_like(o) / o.sum().sqrt())[:, None], o


def test_mean_curvature_signature_of_a_torus_converges_at_second_order():
    """Against H = (R + 2 r cos t) / (2 r (R + r cos t)) on trimesh's torus (not our mesh),
    scale normalised by sqrt(A / 4 pi), A = 4 pi^2 R r; the fitted rate of the largest error."""
    import trimesh

    R, r = 1.0, 0.4
    sizes, errors = [], []
    for n in (12, 24, 48):
        t = trimesh.creation.torus(major_radius=R, minor_radius=r, major_sections=2 * n, minor_sections=n)
        v, f = torch.as_tensor(t.vertices), torch.as_tensor(t.faces)
        lam, phi, m = _constant_basis(v, f)
        h = mean_curvature_signature(v, f, lam, phi, m, compress=False)[:, 0]
        cos = (torch.linalg.vector_norm(v[:, :2], dim=1) - R) / r
        exact = (R + 2 * r * cos) / (2 * r * (R + r * cos)) * np.sqrt(np.pi * R * r)
        sizes.append(1 / n)
        errors.append(float((h - exact).abs().max() / exact.abs().max()))
    rate = np.polyfit(np.log(sizes), np.log(errors), 1)[0]
    assert rate > 1.8 and errors[-1] < 2e-3, (rate, errors)


def test_mean_curvature_signature_invariances_and_sign():
    """1 on a round sphere of any radius, at every time; invariant to rigid motions, the
    numbering, the orientation of a closed mesh's faces and the eigenvectors' signs."""
    import trimesh

    for radius in (0.5, 3.0):
        s = trimesh.creation.icosphere(3, radius=radius)
        o = compute_operators(s.vertices, s.faces, k_edge=4, k_vertex=9)
        h = mean_curvature_signature(o.verts, o.faces, o.vertex_evals, o.vertex_evecs, o.vertex_mass)
        assert h.shape == (len(s.vertices), 9)
        # log(1 + 1) everywhere; the pointwise curvature errs by up to 10% at the 12 vertices of
        # valence five, which the diffusion smooths out
        torch.testing.assert_close(h[:, 1:], torch.full_like(h[:, 1:], np.log(2.0)), atol=1e-2, rtol=0)
        assert (
            abs(float(h[:, 0].mean()) - np.log(2.0)) < 1e-2
            and float((h[:, 0] - np.log(2.0)).abs().max()) < 0.1
        )
    v, f = perturbed_icosphere(2, 0.1, seed=4)
    o = compute_operators(v, f, k_edge=4, k_vertex=12)
    h = mean_curvature_signature(v, f, o.vertex_evals, o.vertex_evecs, o.vertex_mass, count=5)
    assert h[:, 0].std() > 0.05  # the bumps show
    q, _ = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))
    q = torch.as_tensor(q * np.sign(np.linalg.det(q)))
    perm = torch.randperm(v.shape[0], generator=torch.Generator().manual_seed(1))
    inv = torch.empty_like(perm)
    inv[perm] = torch.arange(perm.numel())
    moved = 2.5 * (v[perm] @ q.T) + torch.tensor([1.0, -2.0, 0.5], dtype=v.dtype)
    o2 = compute_operators(moved, inv[f].flip(1), k_edge=4, k_vertex=12)
    h2 = mean_curvature_signature(
        moved, inv[f].flip(1), o2.vertex_evals, o2.vertex_evecs, o2.vertex_mass, count=5
    )
    torch.testing.assert_close(h2, h[perm], atol=1e-8, rtol=1e-6)
    flipped = o.vertex_evecs * torch.tensor([1.0, -1.0] * 6, dtype=torch.float64)
    torch.testing.assert_close(
        mean_curvature_signature(v, f, o.vertex_evals, flipped, o.vertex_mass, count=5), h
    )
    h32 = mean_curvature_signature(
        v, f, o.vertex_evals.float(), o.vertex_evecs.float(), o.vertex_mass, count=5
    )
    assert h32.dtype == torch.float32


def test_mean_curvature_signature_tells_a_fold_from_a_flat_sheet():
    """A sheet folded along a line of its mesh is isometric to the flat one: the heat
    kernel signatures agree, the mean curvature does not (and flips with the faces of an
    open mesh, whose sign follows their orientation)."""
    n = 6
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    flat = np.stack([i.ravel() / n, j.ravel() / n, np.zeros(i.size)], axis=1)
    idx = lambda a, b: a * (n + 1) + b  # noqa: E731
    f = np.array(
        [
            t
            for a in range(n)
            for b in range(n)
            for t in (
                (idx(a, b), idx(a + 1, b), idx(a + 1, b + 1)),
                (idx(a, b), idx(a + 1, b + 1), idx(a, b + 1)),
            )
        ]
    )
    folded = flat.copy()
    right = folded[:, 0] > 0.5 + 1e-9
    angle = np.pi / 3  # fold the half x > 1/2 up about the line x = 1/2
    dx = folded[right, 0] - 0.5
    folded[right, 0], folded[right, 2] = 0.5 + dx * np.cos(angle), dx * np.sin(angle)
    out = []
    for v in (flat, folded):
        o = compute_operators(torch.as_tensor(v), torch.as_tensor(f), k_edge=4, k_vertex=10)
        hks = heat_kernel_signature(o.vertex_evals, o.vertex_evecs, count=4)
        out.append(
            (
                hks,
                mean_curvature_signature(o.verts, o.faces, o.vertex_evals, o.vertex_evecs, o.vertex_mass),
            )
        )
    torch.testing.assert_close(out[1][0], out[0][0], atol=1e-8, rtol=1e-6)
    assert out[0][1].abs().max() < 1e-10
    hinge = np.flatnonzero(np.isclose(flat[:, 0], 0.5) & (flat[:, 1] > 0) & (flat[:, 1] < 1))
    assert (out[1][1][hinge, 0].abs() > 0.5).all()
    o = compute_operators(torch.as_tensor(folded), torch.as_tensor(f[:, ::-1].copy()), k_edge=4, k_vertex=10)
    back = mean_curvature_signature(o.verts, o.faces, o.vertex_evals, o.vertex_evecs, o.vertex_mass)
    torch.testing.assert_close(back, -out[1][1], atol=1e-8, rtol=1e-6)


def test_mean_curvature_signature_gradcheck_in_the_vertices():
    v, f = perturbed_icosphere(1, 0.1, seed=6)
    lam, phi, m = _constant_basis(v, f)
    lam = torch.tensor([0.0, 2.0], dtype=torch.float64)
    phi = torch.cat([phi, torch.linspace(-1, 1, v.shape[0], dtype=torch.float64)[:, None]], dim=1)
    x0 = v.clone().requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: mean_curvature_signature(x, f, lam, phi, m, count=2), (x0,))


def test_mean_curvature_signature_bad_arguments_are_named():
    v, f = perturbed_icosphere(1, 0.05, seed=3)
    lam, phi, m = _constant_basis(v, f)
    with pytest.raises(ValueError, match="must match the 42 vertices"):
        mean_curvature_signature(v, f, lam, phi[:-1], m)
    with pytest.raises(ValueError, match="must match"):
        mean_curvature_signature(v, f, torch.zeros(2, dtype=lam.dtype), phi, m)
    with pytest.raises(ValueError, match="mass must be"):
        mean_curvature_signature(v, f, lam, phi, -m)
    with pytest.raises(ValueError, match="count must be a positive integer"):
        mean_curvature_signature(v, f, lam, phi, m, count=0)
    vin = v.clone()
    mean_curvature_signature(vin, f, lam, phi, m)
    assert torch.equal(vin, v)


# --------------------------------------------------------------------------- batching


def test_collate_offsets_and_block_diagonal(two_meshes):
    a, b = two_meshes
    batch = collate_meshes([a, b])
    oa, ob = a.operators, b.operators
    assert batch.num_meshes == 2
    assert batch.vertex_offsets.tolist() == [0, oa.num_vertices, oa.num_vertices + ob.num_vertices]
    assert batch.edge_offsets.tolist() == [0, oa.num_edges, oa.num_edges + ob.num_edges]
    assert batch.labels.tolist() == [1, 2] and batch.indices.tolist() == [1, 2]
    assert torch.equal(batch.edges[oa.num_edges :], ob.edges + oa.num_vertices)
    assert torch.equal(batch.faces[oa.num_faces :], ob.faces + oa.num_vertices)
    assert torch.equal(batch.face_edges[oa.num_faces :], ob.face_edges + oa.num_edges)
    assert torch.equal(batch.edge_batch, torch.tensor([0] * oa.num_edges + [1] * ob.num_edges))
    assert torch.equal(batch.face_batch.bincount(), torch.tensor([oa.num_faces, ob.num_faces]))
    G = batch.gradient.to_dense()
    torch.testing.assert_close(G[: oa.num_edges, : oa.num_vertices], oa.gradient.to_dense())
    torch.testing.assert_close(G[oa.num_edges :, oa.num_vertices :], ob.gradient.to_dense())
    assert G[: oa.num_edges, oa.num_vertices :].abs().max() == 0
    # block-diagonal products equal per-mesh products
    f = torch.randn(batch.num_vertices, 2, dtype=torch.float64)
    gz = batch.gradient @ f.to(torch.complex128)
    torch.testing.assert_close(gz[oa.num_edges :], ob.gradient @ f[oa.num_vertices :].to(torch.complex128))
    Lc = batch.connection_laplacian.to_dense()
    torch.testing.assert_close(Lc[oa.num_edges :, oa.num_edges :], ob.connection_laplacian.to_dense())
    assert batch.edge_evals.shape == (2, 8) and batch.edge_evecs.shape == (batch.num_edges, 8)
    assert batch.vertex_gradient.shape == (batch.num_vertices, batch.num_vertices)


def test_collate_errors(two_meshes):
    a, b = two_meshes
    with pytest.raises(ValueError, match="at least one"):
        collate_meshes([])
    with pytest.raises(ValueError, match="MeshSample"):
        collate_meshes([a, (1, 2)])
    with pytest.raises(ValueError, match="features"):
        collate_meshes([MeshSample(a.operators, a.features[:-1], 0)])
    with pytest.raises(ValueError, match="feature channels"):
        collate_meshes([a, MeshSample(b.operators, b.features[:, :2], 0)])
    other = compute_operators(b.operators.verts, b.operators.faces, k_edge=5, k_vertex=6)
    with pytest.raises(ValueError, match="eigenpairs"):
        collate_meshes([a, MeshSample(other, b.features, 0)])
    with pytest.raises(ValueError, match="labels"):
        collate_meshes([a, MeshSample(b.operators, b.features, torch.zeros(3))])


def test_dataloader_with_two_workers(two_meshes):
    samples = list(two_meshes) * 3
    loader = torch.utils.data.DataLoader(
        samples, batch_size=2, shuffle=False, num_workers=2, collate_fn=collate_meshes
    )
    batches = list(loader)
    assert len(batches) == 3
    for got in batches:
        ref = collate_meshes(list(two_meshes))
        assert torch.equal(got.edges, ref.edges) and torch.equal(got.labels, ref.labels)
        torch.testing.assert_close(got.gradient.to_dense(), ref.gradient.to_dense())
        torch.testing.assert_close(got.edge_evecs, ref.edge_evecs)


# --------------------------------------------------------------------------- cache


@pytest.fixture
def cache_setup(tmp_path):
    v, f = perturbed_icosphere(1, 0.05, seed=7)
    cache = OperatorCache(tmp_path / "cache")
    options = dict(k_edge=4, k_vertex=3)
    return v, f, cache, options


def _equal(a, b):
    for name in ("edges", "edge_mass", "edge_evals", "edge_evecs", "vertex_evals", "vertex_evecs"):
        assert torch.equal(getattr(a, name), getattr(b, name)), name
    assert torch.equal(a.gradient.to_dense(), b.gradient.to_dense())


def test_cache_roundtrip_without_pickle(cache_setup, monkeypatch):
    v, f, cache, options = cache_setup
    first = cache.get(v, f, **options)
    files = list(cache.root.iterdir())
    assert len(files) == 1 and files[0].suffix == ".npz"  # no temporary files left
    with np.load(files[0], allow_pickle=False) as d:
        assert all(d[name].dtype != object for name in d.files)

    def fail(*args, **kwargs):
        raise AssertionError("recomputed although cached")

    monkeypatch.setattr(cache_module, "compute_operators", fail)
    _equal(cache.get(v, f, **options), first)
    # float64 positions are part of the key
    v2 = v.clone()
    v2[0, 0] += 1e-12
    assert cache.path(cache.key(v2, f, **options)) != files[0]
    assert cache.path(cache.key(v, f, k_edge=5, k_vertex=3)) != files[0]


def test_cache_keeps_operators_without_edge_eigenpairs(cache_setup, monkeypatch):
    """``k_edge=0`` (no eigenpair of ``L_c``, for local edge fields): the empty eigenpairs
    are written and read back with their shapes, under a key of their own."""
    v, f, cache, _ = cache_setup
    first = cache.get(v, f, k_edge=0, k_vertex=3)
    assert first.edge_evecs.shape == (first.edges.shape[0], 0) and first.edge_evals.shape == (0,)
    monkeypatch.setattr(cache_module, "compute_operators", None)  # a recomputation would fail
    again = cache.get(v, f, k_edge=0, k_vertex=3)
    _equal(again, first)
    assert again.edge_evecs.dtype == torch.complex128
    assert cache.path(cache.key(v, f, k_edge=0, k_vertex=3)) != cache.path(
        cache.key(v, f, k_edge=4, k_vertex=3)
    )


def _rebuilt(cache, v, f, options, caplog):
    calls = []
    real = compute_operators

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    with caplog.at_level(logging.WARNING, logger="torch_edgevf.learning"):
        caplog.clear()
        cache_module.compute_operators = counting
        try:
            out = cache.get(v, f, **options)
        finally:
            cache_module.compute_operators = real
    assert calls == [1]
    assert any("invalid" in r.getMessage() and "rebuilt" in r.getMessage() for r in caplog.records)
    return out


def test_cache_truncated_file_is_rebuilt(cache_setup, caplog):
    v, f, cache, options = cache_setup
    ref = cache.get(v, f, **options)
    path = cache.path(cache.key(v, f, **options))
    raw = path.read_bytes()
    path.write_bytes(raw[: len(raw) // 2])
    _equal(_rebuilt(cache, v, f, options, caplog), ref)
    _equal(cache.get(v, f, **options), ref)  # and the rewritten entry is valid


def test_cache_flipped_bytes_are_rebuilt(cache_setup, caplog):
    v, f, cache, options = cache_setup
    ref = cache.get(v, f, **options)
    path = cache.path(cache.key(v, f, **options))
    raw = bytearray(path.read_bytes())
    for pos in range(len(raw) // 3, len(raw) // 3 + 8):  # inside the stored arrays
        raw[pos] ^= 0xFF
    path.write_bytes(bytes(raw))
    _equal(_rebuilt(cache, v, f, options, caplog), ref)


def test_cache_version_change_is_rebuilt(cache_setup, caplog, monkeypatch):
    v, f, cache, options = cache_setup
    cache.get(v, f, **options)
    monkeypatch.setattr(cache_module, "__version__", "0.0.0-other")
    _rebuilt(cache, v, f, options, caplog)
    assert any("version" in r.getMessage() for r in caplog.records)


def test_cache_entry_of_an_older_computation_is_rebuilt(cache_setup, caplog, monkeypatch):
    """A fix that changes the operators raises COMPUTATION: entries made before it are not
    reused, although the package version is the same."""
    v, f, cache, options = cache_setup
    cache.get(v, f, **options)
    monkeypatch.setattr(cache_module, "COMPUTATION", cache_module.COMPUTATION - 1)
    cache.get(v, f, **options)  # written by the older computation
    monkeypatch.undo()
    _rebuilt(cache, v, f, options, caplog)
    assert any("computation" in r.getMessage() for r in caplog.records)


def test_invalid_entry_is_removed_even_when_its_rebuild_fails(cache_setup, caplog, monkeypatch):
    """An entry that cannot be recomputed any more (a fix made its mesh raise) is not left
    behind to be read and reported again by every later run."""
    v, f, cache, options = cache_setup
    monkeypatch.setattr(cache_module, "COMPUTATION", cache_module.COMPUTATION - 1)
    cache.get(v, f, **options)
    monkeypatch.undo()
    (stale,) = cache.root.iterdir()

    def failing(*args, **kwargs):
        raise ValueError("eigsh: did not converge")

    monkeypatch.setattr(cache_module, "compute_operators", failing)
    with caplog.at_level(logging.WARNING, logger="torch_edgevf.learning"):
        with pytest.raises(ValueError, match="converge"):
            cache.get(v, f, **options)
    assert not stale.exists()
    assert sum("invalid" in r.getMessage() for r in caplog.records) == 1
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="torch_edgevf.learning"):
        with pytest.raises(ValueError, match="converge"):
            cache.get(v, f, **options)
    assert not any("invalid" in r.getMessage() for r in caplog.records)


# --------------------------------------------------------------------------- progress


def test_progress_is_quiet_under_pytest(capsys):
    assert list(progress(range(3), desc="x")) == [0, 1, 2]
    assert capsys.readouterr().err == ""
    bar = progress_module._SimpleBar(range(2), 2, "ops")
    assert list(bar) == [0, 1]
    assert "ops: 2/2" in capsys.readouterr().err
    assert list(progress(range(2), desc="shown", enabled=True)) == [0, 1]
    assert "shown" in capsys.readouterr().err


# --------------------------------------------------------------------------- PSB and degenerate faces


def _psb_mesh(pid):
    d = np.load(psb_file(), allow_pickle=False)
    i = int(np.nonzero(d["psb_ids"] == pid)[0][0])
    v = d["verts"][d["vert_offsets"][i] : d["vert_offsets"][i + 1]]
    f = d["faces"][d["face_offsets"][i] : d["face_offsets"][i + 1]].astype(np.int64)
    return v, f


def test_repair_degenerate_face_of_psb_351():
    v, f = _psb_mesh(351)
    bad = find_degenerate_faces(v, f)
    assert len(bad) == 1
    with pytest.raises(ValueError, match="zero-area"):
        ev.mass_matrix(torch.from_numpy(v.astype(np.float64)), f)
    v2, f2, kept, repaired = repair_degenerate_faces(v, f)
    assert repaired == [int(bad[0])]
    assert len(find_degenerate_faces(v2, f2)) == 0
    assert v2.shape[0] == v.shape[0] - 1 and f2.shape[0] == f.shape[0] - 2
    np.testing.assert_array_equal(v2, v[kept])  # no vertex moved
    t1, t2 = ev.Topology(f, v.shape[0]), ev.Topology(f2, v2.shape[0])
    assert t2.euler_characteristic == t1.euler_characteristic
    ev.mass_matrix(torch.from_numpy(v2.astype(np.float64)), f2)  # operators accept it


def test_psb_dataset_degenerate_policies(caplog, psb):
    with caplog.at_level(logging.WARNING, logger="torch_edgevf.learning"):
        ds = PSBDataset(split="train", ids=[351], degenerate="skip")
    assert len(ds) == 0 and ds.skipped == [351]
    assert any("351" in r.getMessage() and "skipped" in r.getMessage() for r in caplog.records)
    with pytest.raises(ValueError, match="351"):
        PSBDataset(split="all", ids=[351], degenerate="error")
    assert len(PSBDataset(split="test", ids=[351])) == 0  # 351 is in the training split
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="torch_edgevf.learning"):
        ds = PSBDataset(split="all", ids=[351], k_edge=4, k_vertex=4, hks_count=3)
    assert len(ds) == 1 and ds.repaired == [351] and ds.psb_ids == [351]
    assert any("repaired" in r.getMessage() for r in caplog.records)
    s = ds[0]
    assert s.features.shape == (s.operators.num_vertices, 3) and s.features.dtype == torch.float32
    assert ds.classes[s.label] == "bearing"


def test_psb_dataset_errors(tmp_path):
    with pytest.raises(ValueError, match="split"):
        PSBDataset(split="val")
    with pytest.raises(ValueError, match="not found"):
        PSBDataset(path=tmp_path / "missing.npz")
    with pytest.raises(ValueError, match="degenerate"):
        PSBDataset(degenerate="ignore")
    v, f = perturbed_icosphere(1, 0.05, seed=0)
    with pytest.raises(ValueError, match="k_edge"):
        compute_operators(v, f, k_edge=1000)
    with pytest.raises(ValueError, match="vertex_laplacian"):
        compute_operators(v, f, vertex_laplacian="fem")


def test_psb_path_from_argument_or_environment(tmp_path, monkeypatch):
    monkeypatch.delenv("TORCH_EDGEVF_PSB", raising=False)
    with pytest.raises(ValueError, match=r"pass path= or set \$TORCH_EDGEVF_PSB.*edgevf prepare-psb"):
        psb_path()
    with pytest.raises(ValueError, match="TORCH_EDGEVF_PSB"):
        PSBDataset()
    missing = tmp_path / "psb.npz"
    with pytest.raises(ValueError, match="PSB file not found.*psb.npz"):
        psb_path(missing)
    monkeypatch.setenv("TORCH_EDGEVF_PSB", str(missing))
    with pytest.raises(ValueError, match="PSB file not found"):
        psb_path()
    missing.write_bytes(b"")
    assert psb_path() == missing and psb_path(str(missing)) == missing


# --------------------------------------------------------------------------- robust Laplacian


def test_robust_vertex_laplacian_is_cotan_on_a_delaunay_mesh_and_not_on_a_sliver():
    """Intrinsic Delaunay (robust_laplacian): the cotan Laplacian where that is Delaunay,
    nonnegative edge weights where the cotan one has a negative one."""
    pytest.importorskip("robust_laplacian")
    from torch_edgevf.learning.precompute import robust_vertex_laplacian
    from torch_edgevf.mesh.topology import Topology

    v, f = ev.icosphere(2)
    L, m = robust_vertex_laplacian(v, Topology(f, num_vertices=v.shape[0]))
    C = ev.cotan_laplacian(v, f).to_dense()
    mass = ev.vertex_mass(v, Topology(f, num_vertices=v.shape[0]), lumped=True).values()
    torch.testing.assert_close(L.to_dense(), C, rtol=1e-4, atol=1e-4 * C.abs().max().item())
    torch.testing.assert_close(m, mass, rtol=1e-4, atol=0)
    # two triangles whose shared edge is not Delaunay (opposite angles sum past pi)
    v = torch.tensor(
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.05, 0.0], [0.5, -0.05, 0.0]], dtype=torch.float64
    )
    f = torch.tensor([[0, 1, 2], [1, 0, 3]])
    C = ev.cotan_laplacian(v, f).to_dense()
    assert C[0, 1] > 0  # a negative cotan weight on the long edge
    L, m = robust_vertex_laplacian(v, Topology(f, num_vertices=4))
    off = L.to_dense() - torch.diag(torch.diagonal(L.to_dense()))
    assert off.max() <= 1e-12 and abs(L.to_dense().sum()) < 1e-10  # flipped: weights >= 0, rows sum to 0
    torch.testing.assert_close(m.sum(), torch.tensor(0.05, dtype=torch.float64), rtol=1e-3, atol=0)


def test_compute_operators_with_the_robust_laplacian():
    pytest.importorskip("robust_laplacian")
    v, f = perturbed_icosphere(2, 0.1, seed=1)
    o = compute_operators(v, f, k_edge=4, k_vertex=8, vertex_laplacian="robust")
    # the vertex eigenvectors are orthonormal in the mass returned
    gram = o.vertex_evecs.T @ (o.vertex_mass[:, None] * o.vertex_evecs)
    torch.testing.assert_close(gram, torch.eye(8, dtype=torch.float64), atol=1e-8, rtol=0)
    assert o.vertex_evals[0].abs() < 1e-8 and (o.vertex_evals[1:] > 0).all()


def test_robust_laplacian_missing_is_named(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "robust_laplacian", None)
    v, f = ev.icosphere(1)
    with pytest.raises(ValueError, match="pip install robust_laplacian"):
        compute_operators(v, f, k_edge=4, k_vertex=4, vertex_laplacian="robust")


def test_a_mesh_whose_operators_raise_is_refused_at_once_the_next_time(cache_setup, monkeypatch, caplog):
    """A ValueError of the computation is recorded: the same mesh and options raise it again
    without computing, until the record is removed or belongs to another computation."""
    v, f, cache, options = cache_setup
    calls = []

    def failing(*args, **kwargs):
        calls.append(1)
        raise ValueError("eigsh: Lanczos did not converge in 1000 restarts")

    monkeypatch.setattr(cache_module, "compute_operators", failing)
    with pytest.raises(ValueError, match="did not converge"):
        cache.get(v, f, **options)
    record = cache.failure_path(cache.key(v, f, **options))
    assert record.exists() and calls == [1]
    with pytest.raises(
        ValueError, match="did not converge.*recorded in the operator cache.*remove that file"
    ):
        cache.get(v, f, **options)
    assert calls == [1]  # not computed again
    with pytest.raises(ValueError):  # other options: another key, computed
        cache.get(v, f, k_edge=5, k_vertex=3)
    assert calls == [1, 1]
    # a record of another computation does not apply: removed, and the mesh computed again
    monkeypatch.setattr(cache_module, "COMPUTATION", cache_module.COMPUTATION + 1)
    monkeypatch.setattr(cache_module, "compute_operators", compute_operators)
    with caplog.at_level(logging.WARNING, logger="torch_edgevf.learning"):
        ops = cache.get(v, f, **options)
    assert ops.edges.shape[0] > 0 and not record.exists()
    assert any("does not apply" in r.getMessage() for r in caplog.records)
    # an entry written after a failure replaces the failure's record
    monkeypatch.undo()
    cache.record_failure(cache.key(v, f, **options), ValueError("x"))
    cache.save(cache.key(v, f, **options), ops)
    assert cache.failure(cache.key(v, f, **options)) is None
    _equal(cache.get(v, f, **options), ops)


def test_an_unreadable_failure_record_is_removed(cache_setup, caplog):
    v, f, cache, options = cache_setup
    key = cache.key(v, f, **options)
    cache.failure_path(key).write_text("{not json")
    with caplog.at_level(logging.WARNING, logger="torch_edgevf.learning"):
        assert cache.failure(key) is None
    assert not cache.failure_path(key).exists()
    assert any("does not apply" in r.getMessage() for r in caplog.records)
