"""``edgevf prepare-psb``: a tiny synthetic benchmark folder in the benchmark's layout."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.learning.datasets import PSBDataset
from torch_edgevf.learning.prepare import PSB_CLASSES, prepare_psb, psb_class

ROOT = Path(__file__).resolve().parents[2]


def write_off(path: Path, verts, faces) -> None:
    lines = ["OFF", f"{len(verts)} {len(faces)} 0"]
    lines += [" ".join(f"{x:.12g}" for x in p) for p in np.asarray(verts)]
    lines += ["3 " + " ".join(str(int(k)) for k in f) for f in np.asarray(faces)]
    path.write_text("\n".join(lines) + "\n")


def ellipsoid(level: int, centre, scale):
    v, f = ev.icosphere(level)
    return v.numpy() * np.asarray(scale) + np.asarray(centre), f.numpy()


@pytest.fixture
def benchmark(tmp_path) -> Path:
    """``data/off/<id>.off``: 17 humans (1-17), 2 cups (21, 22), a spring (261), a fourleg
    (400), and a file that is not a benchmark mesh."""
    off = tmp_path / "data" / "off"
    off.mkdir(parents=True)
    for i in [*range(1, 18), 21, 22, 261, 400]:
        v, f = ellipsoid(2 if i != 400 else 3, centre=(i, 2.0, -1.0), scale=(3.0, 2.0, 1.0 + 0.01 * i))
        write_off(off / f"{i}.off", v, f)
    (off / "notes.off").write_text("not a mesh\n")
    return tmp_path / "data"


def test_classes_follow_the_benchmark_numbering():
    assert len(PSB_CLASSES) == 19 and PSB_CLASSES[0] == "human" and PSB_CLASSES[-1] == "fourleg"
    assert psb_class(1) == 0 and psb_class(20) == 0 and psb_class(21) == 1
    assert psb_class(261) is None and psb_class(280) is None and psb_class(0) is None
    assert psb_class(281) == PSB_CLASSES.index("armadillo") and psb_class(400) == 18


def test_prepare_psb_layout(benchmark, tmp_path):
    pytest.importorskip("fast_simplification")
    out = tmp_path / "psb.npz"
    result = prepare_psb(benchmark, out, faces=200)
    assert result["meshes"] == 20 and result["skipped"] == []
    with np.load(out, allow_pickle=False) as d:
        assert sorted(d.files) == sorted(
            [
                "verts",
                "faces",
                "vert_offsets",
                "face_offsets",
                "labels",
                "psb_ids",
                "split",
                "euler",
                "classes",
            ]
        )
        assert d["verts"].dtype == np.float32 and d["faces"].dtype == np.int32 and d["split"].dtype == np.int8
        assert list(d["classes"]) == list(PSB_CLASSES)
        ids = d["psb_ids"].tolist()
        assert ids == [*range(1, 18), 21, 22, 400]  # the spring (261) is left out
        assert d["labels"].tolist() == [0] * 17 + [1, 1, 18]
        assert d["split"].tolist() == [0] * 16 + [1] + [0, 0, 0]  # the first 16 of a class train
        assert len(d["vert_offsets"]) == len(d["face_offsets"]) == 21
        assert (d["euler"] == 2).all()
        for k in range(20):
            v = d["verts"][d["vert_offsets"][k] : d["vert_offsets"][k + 1]]
            f = d["faces"][d["face_offsets"][k] : d["face_offsets"][k + 1]]
            assert len(f) <= 200 and len(f) >= 150  # icosphere 2 (320) and 3 (1,280) decimated
            assert f.min() == 0 and f.max() == len(v) - 1
            np.testing.assert_allclose(v.mean(axis=0), 0, atol=1e-6)
            assert np.linalg.norm(v, axis=1).max() == pytest.approx(1, abs=1e-6)
            topo = ev.Topology(torch.from_numpy(f.astype(np.int64)), num_vertices=len(v))
            topo.require_closed()
    ds = PSBDataset(out, split="test", k_edge=4, k_vertex=4, hks_count=2)
    assert ds.psb_ids == [17] and ds.classes == list(PSB_CLASSES)


def test_prepare_psb_keeps_small_meshes(tmp_path):
    off = tmp_path / "off"
    off.mkdir()
    v, f = ellipsoid(1, centre=(5.0, 0.0, 0.0), scale=(1.0, 1.0, 1.0))
    write_off(off / "30.off", v, f)
    prepare_psb(off, tmp_path / "small.npz", faces=2000)  # the off folder itself works too
    with np.load(tmp_path / "small.npz") as d:
        assert len(d["faces"]) == 80 and d["labels"].tolist() == [1]


def test_prepare_psb_errors(tmp_path):
    with pytest.raises(ValueError, match="not a folder"):
        prepare_psb(tmp_path / "missing", tmp_path / "out.npz")
    with pytest.raises(ValueError, match="no benchmark OFF files"):
        prepare_psb(tmp_path, tmp_path / "out.npz")
    with pytest.raises(ValueError, match="at least 4"):
        prepare_psb(tmp_path, tmp_path / "out.npz", faces=2)


def _edgevf(*args, cwd):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run(
        [sys.executable, "-m", "torch_edgevf", *args], cwd=cwd, env=env, capture_output=True, text=True
    )


def test_command_line(benchmark, tmp_path):
    pytest.importorskip("fast_simplification")
    r = _edgevf("prepare-psb", str(benchmark), "out.npz", "--faces", "100", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "wrote out.npz: 20 meshes" in r.stdout
    quiet = _edgevf("prepare-psb", str(benchmark), "quiet.npz", "--faces", "100", "-q", cwd=tmp_path)
    assert quiet.returncode == 0, quiet.stderr  # global flags after the subcommand too
    assert (tmp_path / "quiet.npz").exists()
    with np.load(tmp_path / "out.npz") as d:
        assert len(d["labels"]) == 20 and np.diff(d["face_offsets"]).max() <= 100
    bad = _edgevf("prepare-psb", str(tmp_path / "nowhere"), "out.npz", cwd=tmp_path)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "not a folder" in bad.stderr
    bad = _edgevf("prepare-psb", str(benchmark), "out.txt", cwd=tmp_path)
    assert bad.returncode == 2 and ".npz" in bad.stderr
