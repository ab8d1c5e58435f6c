"""``edgevf quad``, run as a user runs it (a subprocess), on meshes written by the library."""

import numpy as np
import pytest
from test_cli import assert_error, edgevf, read_png

import torch_edgevf as ev
from torch_edgevf.quad.mesh import quad_mesh_report

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


@pytest.fixture(scope="module")
def ellipsoid_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("mesh") / "ellipsoid.obj"
    ev.save_mesh(path, *ev.meshes.ellipsoid((1.0, 0.8, 0.6), level=2))
    return path


def test_quad_writes_a_quad_mesh_and_its_picture(tmp_path, ellipsoid_file):
    result = edgevf(
        "quad",
        ellipsoid_file,
        "-o",
        "q.obj",
        "--quads",
        "150",
        "--png",
        "q.png",
        "--size",
        "400x300",
        "-q",
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"quad mesh of {ellipsoid_file}: ")
    assert "Euler characteristic 2" in result.stdout
    lines = (tmp_path / "q.obj").read_text().splitlines()
    faces = [line.split()[1:] for line in lines if line.startswith("f ")]
    verts = [line for line in lines if line.startswith("v ")]
    assert faces and all(len(f) == 4 for f in faces)
    assert 100 < len(faces) < 200 and len(verts) == len(faces) + 2  # a sphere: V - F = 2
    quads = np.array(faces, dtype=np.int64) - 1
    report = quad_mesh_report(np.loadtxt([v[2:] for v in verts]), quads)
    assert report.closed and report.manifold
    assert f"{report.irregular.size} irregular" in result.stdout
    img = read_png(tmp_path / "q.png")
    assert 0.2 < (np.abs(img - 1) > 0.02).any(-1).mean() < 0.95


@pytest.mark.parametrize(
    "args, fragments",
    [
        (["--quads", "10", "--edge-length", "0.1"], ["not allowed with"]),
        (["--quads", "0"], ["--quads", ">= 1"]),
        (["--edge-length", "-2"], ["positive"]),
        (["--sharp-angle", "200"], ["[0, 180)"]),
        (["-o", "q.stl"], ["-o q.stl", "unsupported extension"]),
        (["--field", "vortex"], ["invalid choice"]),
    ],
)
def test_quad_argument_errors(tmp_path, ellipsoid_file, args, fragments):
    assert_error(edgevf("quad", ellipsoid_file, *args, cwd=tmp_path), *fragments)


def test_quad_refuses_an_open_mesh_without_the_boundary_option(tmp_path, capsys):
    from torch_edgevf.cli import main

    path = tmp_path / "grid.obj"
    ev.save_mesh(path, *ev.meshes.grid(5, 5))
    assert main(["quad", str(path), "-o", str(tmp_path / "q.obj"), "-q"]) == 2  # in this process
    err = capsys.readouterr().err
    assert err.startswith("edgevf: error: the mesh is open") and "boundary='hard'" in err
    assert not (tmp_path / "q.obj").exists()
