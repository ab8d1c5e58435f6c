"""The learning examples run at a small size and give their numbers."""

import numpy as np
import pytest

from conftest import load_example as load


def test_isospectralization_reduces_the_spectral_loss():
    out = load("isospectralization").main(level=1, k=6, steps=40, lr=1e-2)
    assert out["losses"][-1] < 0.2 * out["losses"][0]
    assert out["final_error"] < 0.5 * out["initial_error"]


def test_learn_field_denoises_the_guide():
    out = load("learn_field").main(num_train=2, num_test=1, level=1, epochs=8, width=4)
    assert out["losses"][-1] < out["losses"][0]
    t = out["test"]
    assert t["align_clean_pred"] < t["align_clean_noisy"]
    assert t["smooth_pred"] < t["smooth_noisy"]


def _psb_subset(path, per_class_train=2, per_class_test=1, classes=(0, 1)):
    d = np.load(path, allow_pickle=False)
    ids = []
    for c in classes:
        for split, count in ((0, per_class_train), (1, per_class_test)):
            ids += d["psb_ids"][(d["labels"] == c) & (d["split"] == split)][:count].tolist()
    return ids


def test_train_psb_small(tmp_path, psb, monkeypatch):
    """The recommended network on a subset: only the meshes of the subset are precomputed."""
    from torch_edgevf.learning.datasets import psb as psb_module

    computed = []
    real = psb_module.OperatorCache.get
    monkeypatch.setattr(
        psb_module.OperatorCache, "get", lambda self, v, f, **o: computed.append(1) or real(self, v, f, **o)
    )
    example = load("train_psb")
    ids = example.subset_ids(psb, classes=2, limit=2)
    assert len(ids) == 2 * (2 + 4)  # 2 training meshes and the 4 test meshes of each class
    out = example.main(
        epochs=2, width=4, num_blocks=1, classes=2, limit=2, k_edge=8, k_vertex=8, cache_dir=tmp_path
    )
    assert out["num_train"] == 4 and out["num_test"] == 8 and len(computed) == 12
    (r,) = out["results"]
    assert r["model"] == "edgefieldnet" and 0.0 <= r["test_accuracy"] <= 1.0
    assert len(r["losses"]) == 2 and np.isfinite(r["losses"]).all()
    assert out["table"].count("\n") == 2 and "| edgefieldnet |" in out["table"]
    again = example.main(
        epochs=1,
        width=4,
        num_blocks=1,
        model="diffusionnet",
        ids=ids[:3],
        k_edge=8,
        k_vertex=8,
        cache_dir=tmp_path,
    )
    assert again["results"][0]["model"] == "diffusionnet"


def test_train_psb_ddp_two_processes(tmp_path, psb):
    """Two gloo processes on 127.0.0.1, two steps (about 5 s).

    The example starts its workers with ``spawn``: with ``fork`` (after the parent had
    started OpenMP threads) this test hung twice on 2026-11-23 and was marked slow.
    """
    ids = _psb_subset(psb)
    out = load("train_psb_ddp").main(
        world_size=2,
        max_steps=2,
        width=4,
        num_blocks=1,
        batch_size=1,
        ids=ids,
        k_edge=8,
        k_vertex=8,
        cache_dir=tmp_path,
    )
    assert out["world_size"] == 2 and out["steps"] == 2
    assert out["params_in_sync"]
    assert np.isfinite(out["losses"]).all() and 0.0 <= out["test_accuracy"] <= 1.0


@pytest.mark.slow
def test_train_psb_from_the_command_line(tmp_path, psb):
    """``examples/train_psb.py --classes 2 --limit 1 --epochs 1`` as a user runs it."""
    import subprocess
    import sys

    from conftest import EXAMPLES

    argv = ["--classes", "2", "--limit", "1", "--epochs", "1", "--cache", str(tmp_path), "--device", "cpu"]
    out = subprocess.run(
        [sys.executable, str(EXAMPLES / "train_psb.py"), *argv], capture_output=True, text=True, timeout=900
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert "PSB: 2 train / 8 test meshes" in out.stdout and "| edgefieldnet |" in out.stdout


def test_train_psb_names_a_device_torch_cannot_use():
    from conftest import load_example

    with pytest.raises(ValueError, match="'nonsense' is not a device"):
        load_example("train_psb").main(device="nonsense")
