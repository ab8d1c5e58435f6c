"""The RNA reader keeps every vertex's label and maps it to the network's mesh; the sample trains."""

import json
import shutil

import numpy as np
import pytest
import torch

from torch_edgevf.learning.batching import collate_meshes
from torch_edgevf.learning.datasets.rna import (
    RNA_CLASSES,
    RNADataset,
    prepare_rna_mesh,
    read_rna_mesh,
    rna_path,
    rna_split,
)
from torch_edgevf.learning.models import EdgeFieldNet
from torch_edgevf.learning.precompute import compute_operators

from conftest import shared_path


@pytest.fixture(scope="module")
def sample():
    return shared_path("datasets", "rna_sample")


def _file_records(path):
    tokens = path.read_text().split()
    nv = int(tokens[1])
    return nv, np.array(tokens[4 : 4 + 3 * nv], dtype=np.float64).reshape(nv, 3)


def test_reader_keeps_every_vertex_and_label(sample):
    # 6CFJ_2B: 18,696 vertices in the file, 4,092 of them in no face
    verts, faces, labels = read_rna_mesh(sample, "6CFJ_2B")
    nv, positions = _file_records(sample / "off" / "6CFJ_2B.off")
    raw = np.loadtxt(sample / "labels" / "6CFJ_2B.txt", dtype=np.int64)
    assert verts.shape == (nv, 3) == (18696, 3)
    np.testing.assert_array_equal(verts, positions)
    np.testing.assert_array_equal(labels, raw + 1)
    assert labels.min() >= 0 and labels.max() < RNA_CLASSES
    assert nv - len(np.unique(faces)) == 4092


def test_unreferenced_and_non_manifold_vertices_go_through(sample):
    verts, faces, labels = read_rna_mesh(sample, "6CFJ_2B")
    before = (verts.copy(), faces.copy(), labels.copy())
    mesh = prepare_rna_mesh(verts, faces, labels, "6CFJ_2B", target_vertices=None)
    for a, b in zip(before, (verts, faces, labels)):
        np.testing.assert_array_equal(a, b)  # the inputs are not modified
    assert mesh.report["unreferenced_vertices"] == 4092
    assert mesh.report["non_manifold_vertices"] > 0
    assert mesh.vertex_map.shape == (len(verts),)
    assert 0 <= mesh.vertex_map.min() and mesh.vertex_map.max() < len(mesh.verts)
    # at the file's resolution every referenced vertex maps to a copy of itself, with its label
    used = np.unique(faces)
    np.testing.assert_array_equal(mesh.verts[mesh.vertex_map[used]], verts[used])
    np.testing.assert_array_equal(mesh.mesh_labels[mesh.vertex_map[used]], labels[used])
    ops = compute_operators(mesh.verts, mesh.faces, k_edge=4, k_vertex=40)
    assert torch.isfinite(ops.vertex_evecs).all() and torch.isfinite(ops.edge_evecs).all()
    assert int((ops.vertex_evals < 1e-8).sum()) == mesh.report["components"]


def test_decimated_mesh_maps_every_vertex(sample):
    pytest.importorskip("fast_simplification")  # decimation: the [prepare] extra
    verts, faces, labels = read_rna_mesh(sample, "5J8A_DB")
    mesh = prepare_rna_mesh(verts, faces, labels, "5J8A_DB", target_vertices=2000)
    assert 1800 <= len(mesh.verts) <= 2200
    carried = mesh.carry_back(torch.from_numpy(mesh.mesh_labels)).numpy()
    assert carried.shape == labels.shape
    # labels survive the round trip through the decimated mesh on most vertices
    assert np.mean(carried == labels) > 0.75  # 0.82 at this resolution, 0.94 at 5,000


def test_split_official_and_from_json(sample, tmp_path):
    split = rna_split(sample)
    assert split == {
        "train": [line[:-4] for line in (sample / "train.txt").read_text().split()],
        "test": [line[:-4] for line in (sample / "test.txt").read_text().split()],
    }
    path = tmp_path / "split.json"
    path.write_text(json.dumps({"train": ["4V48_A9"], "test": ["3CXC_9.off"]}))
    assert rna_split(sample, path) == {"train": ["4V48_A9"], "test": ["3CXC_9"]}
    for bad, message in (
        ({"train": ["4V48_A9"], "test": ["4V48_A9"]}, "both"),
        ({"train": ["nope"], "test": []}, "not in"),
        ({"train": "4V48_A9"}, "must be"),
    ):
        path.write_text(json.dumps(bad))
        with pytest.raises(ValueError, match=message):
            rna_split(sample, path)


def test_bad_folder_and_labels_are_named(sample, tmp_path, monkeypatch):
    monkeypatch.delenv("TORCH_EDGEVF_RNA", raising=False)
    with pytest.raises(ValueError, match="git clone"):
        rna_path(None)
    with pytest.raises(ValueError, match="no off/"):
        rna_path(tmp_path)
    root = tmp_path / "rna"
    shutil.copytree(sample, root)
    (root / "labels" / "4V48_A9.txt").write_text("1\n2\n")
    with pytest.raises(ValueError, match="4V48_A9: 2 labels for 681 vertices"):
        read_rna_mesh(root, "4V48_A9")
    ds = RNADataset(root, ["4V48_A9", "3CXC_9"], target_vertices=None, k_edge=4, k_vertex=16)
    assert [m.name for m in ds.meshes] == ["3CXC_9"] and ds.skipped[0][0] == "4V48_A9"


def test_a_few_epochs_learn_well_above_the_majority_class(sample):
    pytest.importorskip("fast_simplification")  # decimation: the [prepare] extra
    torch.manual_seed(0)
    train = rna_split(sample)["train"]
    ds = RNADataset(sample, train, target_vertices=600, k_edge=16, k_vertex=48)
    labels = np.concatenate([m.mesh_labels for m in ds.meshes])
    majority = np.bincount(labels).max() / len(labels)
    model = EdgeFieldNet(16, RNA_CLASSES, head="vertex", dropout=0.0)  # the recommended network, log-HKS in
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    batches = [collate_meshes([s]) for s in ds]
    for _ in range(40):
        for b in batches:
            opt.zero_grad()
            torch.nn.functional.cross_entropy(model(b), b.labels).backward()
            opt.step()
    model.eval()
    with torch.no_grad():
        correct = sum(int((model(b).argmax(-1) == b.labels).sum()) for b in batches)
    accuracy = correct / len(labels)
    assert accuracy > 5 * majority, (accuracy, majority)
