"""experiments/psb_classification/probe.py: the study's linear probes, on a small subset."""

import pytest
import torch

from torch_edgevf import icosphere
from torch_edgevf.learning.batching import MeshBatch
from torch_edgevf.learning.precompute import compute_operators, heat_kernel_signature

from conftest import load_script
from study import STUDY

PROBE = STUDY / "probe.py"


@pytest.fixture(scope="module")
def probe_module():
    return load_script(PROBE, "probe")


def test_pooled_is_the_weighted_mean_and_deviation(probe_module):
    x = torch.tensor([[1.0], [3.0]], dtype=torch.float64)
    out = probe_module.pooled(x, torch.tensor([1.0, 3.0], dtype=torch.float64))
    assert torch.allclose(
        out, torch.tensor([2.5, (0.25 * 1.5**2 + 0.75 * 0.5**2) ** 0.5], dtype=torch.float64)
    )


def test_mesh_features_of_a_sphere(probe_module):
    v, f = icosphere(2)
    ops = compute_operators(v, f, k_edge=8, k_vertex=16, vertex_gradient=True)
    batch = MeshBatch.from_operators(ops, heat_kernel_signature(ops.vertex_evals, ops.vertex_evecs, count=4))
    feats, kept = probe_module.mesh_features(batch)
    assert set(feats) == {"hks", "edge", "edge_projected", "vertex"}
    assert all(x.shape == (8,) and bool(torch.isfinite(x).all()) for x in feats.values())
    assert 0.0 < kept <= 1.0 + 1e-12
    # on the round sphere the HKS barely vary: the moduli of their gradients are below 1
    assert float(feats["edge"][:4].max()) < 0.0


def test_probe_separates_two_clouds(probe_module):
    g = torch.Generator().manual_seed(0)
    x = torch.cat(
        [
            torch.randn(20, 3, generator=g, dtype=torch.float64) + 3,
            torch.randn(20, 3, generator=g, dtype=torch.float64),
        ]
    )
    y = torch.tensor([0] * 20 + [1] * 20)
    test = torch.zeros(40, dtype=torch.bool)
    test[::4] = True
    assert probe_module.probe(x[~test], y[~test], x[test], y[test], 2, 1e-3) == 1.0


@pytest.mark.slow
def test_quick_run_is_well_above_chance(probe_module, psb, tmp_path, capsys):
    results = probe_module.main(["--quick", "--cache", str(tmp_path / "cache")])
    assert [r["features"] for r in results] == list(probe_module.FEATURE_SETS)
    for r in results:  # 4 classes: chance is 0.25
        assert r["fixed"] >= 0.6 and len(r["folds"]) == 2 and min(r["folds"]) >= 0.6
    assert "| log-HKS + edge gradients |" in capsys.readouterr().out
