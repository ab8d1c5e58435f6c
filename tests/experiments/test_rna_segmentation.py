"""The RNA segmentation experiment's command: help, JSON rows, a bad folder, resuming."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import load_script, shared_path

RUN = Path(__file__).resolve().parents[2] / "experiments" / "rna_segmentation" / "run.py"


def _run(*args, check=True):
    out = subprocess.run([sys.executable, str(RUN), *args], capture_output=True, text=True, timeout=900)
    if check:
        assert out.returncode == 0, out.stderr
    return out


def test_help_names_every_option():
    text = _run("--help").stdout
    for option in ("--data", "--split", "--models", "--seeds", "--epochs", "--json", "--device"):
        assert option in text


def test_bad_folder_is_named(tmp_path):
    out = _run("--data", str(tmp_path), check=False)
    assert out.returncode == 2 and "RNA dataset folder" in out.stderr


def test_a_device_torch_cannot_use_is_named(tmp_path):
    out = _run("--data", str(tmp_path), "--device", "nonsense", check=False)
    assert out.returncode == 2 and "'nonsense' is not a device" in out.stderr


def test_a_run_without_usable_meshes_names_them(tmp_path):
    """Every mesh skipped (here: faces naming vertices the file lacks): an error naming the
    meshes and the problem, not a traceback."""
    (tmp_path / "off").mkdir()
    (tmp_path / "labels").mkdir()
    for name in ("BAD_A", "BAD_B"):
        (tmp_path / "off" / f"{name}.off").write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n")
        (tmp_path / "labels" / f"{name}.txt").write_text("1\n1\n1\n")
    (tmp_path / "train.txt").write_text("BAD_A\n")
    (tmp_path / "test.txt").write_text("BAD_B\n")
    out = _run("--data", str(tmp_path), "--cache", str(tmp_path / "cache"), check=False)
    assert out.returncode == 2, out.stderr
    assert "no training" in out.stderr and "BAD_A" in out.stderr and "Traceback" not in out.stderr


def test_quick_run_writes_the_json_rows_and_resumes(tmp_path):
    pytest.importorskip("fast_simplification")  # the training meshes are decimated
    sample = shared_path("datasets", "rna_sample")
    split = tmp_path / "split.json"
    split.write_text(json.dumps({"train": ["4V48_A9", "5J8A_DB"], "test": ["3CXC_9"]}))
    args = ["--data", str(sample), "--split", str(split), "--epochs", "2", "--seeds", "0", "--width", "8"]
    args += [
        "--target-vertices",
        "400",
        "--cache",
        str(tmp_path / "cache"),
        "--run-dir",
        str(tmp_path / "runs"),
    ]
    _run(*args, "--json", str(tmp_path / "a.json"))
    rows = json.loads((tmp_path / "a.json").read_text())["results"]
    assert [r["model"] for r in rows] == ["edgefieldnet", "diffusionnet"]
    for r in rows:
        for key in ("seed", "test_accuracy", "test_miou", "train_seconds", "precompute_seconds"):
            assert key in r
        assert 0 <= r["test_miou"] <= 1 and 0 <= r["test_accuracy"] <= 1
        assert r["test_vertices"] == 15225  # every vertex of 3CXC_9's file, at file resolution
        assert r["test_resolution"] == "file" and "test_accuracy_decimated" in r
        assert len(r["history"]) == 2
    assert any("diffusion" in r["model"] for r in rows)
    # a second call resumes from the checkpoints: no epoch is trained again, same results
    out = _run(*args, "--json", str(tmp_path / "b.json"))
    again = json.loads((tmp_path / "b.json").read_text())["results"]
    assert "epoch 1/2" not in out.stdout and "resumed" in out.stdout
    for r, s in zip(rows, again):
        assert r["test_accuracy"] == pytest.approx(s["test_accuracy"])
    # the picture of a test molecule from the final weights: truth, prediction and errors
    png = tmp_path / "figure.png"
    figure = [sys.executable, str(RUN.with_name("figure.py")), "--data", str(sample), "--width", "8"]
    figure += ["--checkpoint", str(tmp_path / "runs" / "split-edgefieldnet-seed0.pt"), "-o", str(png)]
    figure += ["--cache", str(tmp_path / "cache")]
    out = subprocess.run(figure, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    accuracy = float(out.stdout.split("accuracy ")[-1])
    assert accuracy == pytest.approx(rows[0]["test_accuracy"], abs=1e-9)  # the run's score of 3CXC_9
    _assert_three_coloured_panels(png)
    # the learning curve's score of the final checkpoint is the run's (given twice: every
    # checkpoint is scored on each mesh as it is read)
    curve = [sys.executable, str(RUN.with_name("curve.py")), "--data", str(sample), "--split", str(split)]
    curve += ["--model", "edgefieldnet", "--width", "8", "--cache", str(tmp_path / "cache")]
    curve += ["--checkpoints", *[str(tmp_path / "runs" / "split-edgefieldnet-seed0.pt")] * 2]
    out = subprocess.run([*curve, "--json", str(tmp_path / "curve.json")], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    points = json.loads((tmp_path / "curve.json").read_text())["curve"]
    assert len(points) == 2
    for point in points:
        assert point["epoch"] == 2 and point["test_vertices"] == 15225 and point["split"] == "split.json"
        assert point["test_accuracy"] == pytest.approx(rows[0]["test_accuracy"], abs=1e-12)
    # ... and it scores the training meshes, decimated as trained, when asked
    train = [*curve[:-1], "--part", "train", "--limit", "1", "--target-vertices", "400"]
    out = subprocess.run([*train, "--json", str(tmp_path / "train.json")], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    (point,) = json.loads((tmp_path / "train.json").read_text())["curve"]
    assert point["part"] == "train" and point["meshes"] == 1 and 0 <= point["test_accuracy"] <= 1
    out = subprocess.run([*curve[:-2], str(tmp_path / "absent.pt")], capture_output=True, text=True)
    assert out.returncode == 2 and "no checkpoint file at" in out.stderr
    # --device cpu (the default, named), trained afresh: the same numbers
    args[args.index(str(tmp_path / "runs"))] = str(tmp_path / "runs-cpu")
    _run(*args, "--device", "cpu", "--json", str(tmp_path / "c.json"))
    named = json.loads((tmp_path / "c.json").read_text())["results"]
    for r, s in zip(rows, named):
        assert (r["test_accuracy"], r["test_miou"]) == (s["test_accuracy"], s["test_miou"])
        assert [h["loss"] for h in r["history"]] == [h["loss"] for h in s["history"]]


def _assert_three_coloured_panels(png: Path) -> None:
    """Three panels side by side, each with a molecule; the first two in many colours, the
    third grey with red errors."""
    import matplotlib.image as mpimg
    import numpy as np

    image = mpimg.imread(png)[..., :3]
    thirds = np.array_split(image, 3, axis=1)
    for k, panel in enumerate(thirds):
        drawn = panel[np.abs(panel - 1).sum(-1) > 0.15]  # not the white background
        assert len(drawn) > 0.02 * panel.shape[0] * panel.shape[1], k
        colours = {tuple(c) for c in np.round(drawn * 4).astype(int)}
        if k < 2:
            assert len(colours) > 10, (k, len(colours))
        else:
            red = (drawn[:, 0] > 0.5) & (drawn[:, 1] < 0.3) & (drawn[:, 2] < 0.3)
            assert red.any()


def test_readme_tables_are_those_of_the_saved_runs():
    report = RUN.with_name("report.py")
    out = subprocess.run(
        [sys.executable, str(report), "--check"], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    readme = RUN.with_name("README.md").read_text()
    assert "<!-- table:official -->" in readme and "<!-- table:validation -->" in readme


def test_every_model_gives_every_vertex_a_score_of_every_class():
    """Each network of the study, by name, on a mesh: (V, 260) logits, a gradient for every
    parameter it uses."""
    import torch

    import torch_edgevf as ev
    from torch_edgevf.learning import MeshSample, collate_meshes, compute_operators, heat_kernel_signature

    rna_run = load_script(RUN, "rna_run")  # not ``run``: PSB's has that name

    v, f = ev.icosphere(2)
    ops = compute_operators(v, f, k_edge=16, k_vertex=16, vertex_gradient=True, dtype=torch.float32)
    x = heat_kernel_signature(ops.vertex_evals, ops.vertex_evecs, count=16, log=True)
    batch = collate_meshes([MeshSample(ops, x, torch.zeros(len(v), dtype=torch.int64))])
    for name in rna_run.MODELS:
        torch.manual_seed(0)
        model = rna_run.build_model(name, 16, 8)
        logits = model(batch)
        assert logits.shape == (len(v), 260) and torch.isfinite(logits).all(), name
        torch.nn.functional.cross_entropy(logits, batch.labels).backward()
        assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in model.parameters()), name


def test_the_recommended_network_is_the_one_its_first_run_trained():
    """``edgefieldnet`` is the library's ``EdgeFieldNet`` with its per-vertex defaults (local
    fields); its seed-0 run trained the PSB study's variant without diffusion of the fields
    and without divergence and curl: the same parameters, drawn alike from a seed, give the
    same logits."""
    import torch

    import torch_edgevf as ev
    from torch_edgevf.learning import MeshSample, collate_meshes, compute_operators, heat_kernel_signature

    from study import variants  # the PSB study's modules, its folder on the path

    rna_run = load_script(RUN, "rna_run")
    v, f = ev.icosphere(2)
    ops = compute_operators(v, f, k_edge=0, k_vertex=16)
    x = heat_kernel_signature(ops.vertex_evals, ops.vertex_evecs, count=16, log=True)
    batch = collate_meshes([MeshSample(ops, x, 0)])
    torch.manual_seed(0)
    library = rna_run.build_model("edgefieldnet", 16, 16).double().eval()
    assert library.fields == "local"
    torch.manual_seed(0)
    study = variants.StudyEdgeFieldNet(
        16,
        260,
        width=16,
        vector_width=4,
        num_blocks=4,
        mlp=(16, 16),
        head="vertex",
        divergence=False,
        field_diffusion=False,
    )
    study = study.double().eval()
    assert [n for n, _ in library.named_parameters()] == [n for n, _ in study.named_parameters()]
    with torch.no_grad():
        want = study(batch)
        assert want.abs().max() > 1e-3
        torch.testing.assert_close(library(batch), want, rtol=0, atol=0)


def _basis_share(*args, timeout=600):
    """``basis_share.py`` on the shared RNA sample."""
    script = [sys.executable, str(RUN.with_name("basis_share.py"))]
    script += ["--data", str(shared_path("datasets", "rna_sample"))]
    return subprocess.run([*script, *args], capture_output=True, text=True, timeout=timeout)


def test_basis_share_is_one_in_the_span_and_small_for_gradients():
    """``basis_share.kept_share`` keeps all of a field in the span of the basis; the command
    prints a row per mesh and kind of scalars, with a share in [0, 1], and names a mesh it
    cannot read."""
    import torch

    import torch_edgevf as ev
    from torch_edgevf.learning import compute_operators

    sys.path.insert(0, str(RUN.parent))
    import basis_share

    pytest.importorskip("fast_simplification")  # the command decimates
    v, f = ev.icosphere(2)
    ops = compute_operators(v, f, k_edge=16, k_vertex=16, vertex_gradient=True)
    mass = ops.edge_mass.double()
    # a gradient field that lies in the span: the basis keeps all of it
    s = torch.randn(len(v), 2, dtype=torch.float64)
    assert bool((basis_share.kept_share(ops.gradient, mass, ops.edge_evecs, s) <= 1 + 1e-12).all())
    smooth = ops.vertex_evecs[:, 1:4]  # the sphere's l = 1 functions: their gradients are smooth
    kept = basis_share.kept_share(ops.gradient, mass, ops.edge_evecs, smooth)
    assert bool((kept > 0.99).all()), kept
    out = _basis_share("--meshes", "3CXC_9", "--target-vertices", "1500")
    assert out.returncode == 0, out.stderr
    rows = [line.split("|")[1:-1] for line in out.stdout.splitlines() if line.startswith("| 3CXC_9")]
    assert [r[2].strip() for r in rows] == ["log-HKS", "label indicators"]
    assert all(0 <= float(r[3]) <= 1 for r in rows)
    bad = _basis_share("--meshes", "NOPE")
    assert bad.returncode == 2 and "NOPE" in bad.stderr


@pytest.mark.slow
def test_readme_basis_share_table_is_what_the_command_prints():
    pytest.importorskip("fast_simplification")
    out = _basis_share("--meshes", "3CXC_9", "4P6F_RB", timeout=900)
    assert out.returncode == 0, out.stderr
    readme = RUN.with_name("README.md").read_text()
    rows = [
        line
        for line in out.stdout.splitlines()
        if line.startswith("| 3CXC_9") or line.startswith("| 4P6F_RB")
    ]
    assert len(rows) == 4
    for row in rows:
        assert "  " + row in readme, row
