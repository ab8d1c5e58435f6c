"""The ``edgevf`` command line, run as a user runs it: a subprocess per command.

Each command is checked for its exit status, what it prints and the files it writes, on
the built-in mesh and on real meshes from ``../shared/meshes`` (skipped without them);
errors are one line on stderr with exit status 2, found before any work starts.
"""

import ast
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import edgevf, shared_path

BUILT_IN = "spot_low_resolution (built in)"
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def assert_error(result: subprocess.CompletedProcess, *fragments: str) -> str:
    """Exit 2, nothing on stdout, one line on stderr that contains every fragment."""
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("edgevf"), lines[0]
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert "Traceback" not in result.stderr
    return lines[0]


def read_png(path) -> np.ndarray:
    from matplotlib.image import imread

    return imread(str(path))[..., :3].astype(np.float64)


def blobs(mask: np.ndarray, min_pixels: int) -> int:
    from scipy import ndimage

    labels, count = ndimage.label(mask)
    return int((np.bincount(labels.ravel())[1:] >= min_pixels).sum()) if count else 0


def colour_blobs(img: np.ndarray, colour, tol: float, min_pixels: int) -> int:
    return blobs((np.abs(img - np.asarray(colour)) < tol).all(-1), min_pixels)


# --------------------------------------------------------------------------- start-up


def test_help_is_quick_and_imports_no_torch():
    """``--help`` of the program and of every subcommand, without importing torch."""
    code = (
        "import sys\n"
        "from torch_edgevf.cli import build_parser, main\n"
        "commands = [a for a in build_parser()._subparsers._group_actions[0].choices]\n"
        "for argv in [['--help'], *[[c, '--help'] for c in commands]]:\n"
        "    try:\n"
        "        main(argv)\n"
        "    except SystemExit as exc:\n"
        "        assert exc.code == 0, (argv, exc.code)\n"
        "print(sorted(commands))\n"
        "print('torch' in sys.modules, 'numpy' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    commands, imported = out.stdout.strip().splitlines()[-2:]
    assert {"demo", "design", "singularities", "param", "bench", "info"} <= set(ast.literal_eval(commands))
    assert imported == "False False", "torch or numpy imported for --help"


def test_module_help_does_not_import_torch():
    """``python -m torch_edgevf --help`` itself (the package __init__ included)."""
    out = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "torch_edgevf", "--help"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0
    assert out.stdout.startswith("usage: edgevf"), out.stdout
    imported = {line.rsplit("|", 1)[-1].strip() for line in out.stderr.splitlines() if "|" in line}
    assert "torch_edgevf.cli" in imported
    assert "torch" not in imported and "numpy" not in imported


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "args, fragments",
    [
        (["design", "-o", "out.xyz"], ["-o out.xyz", "unsupported extension", ".npz"]),
        (["design", "--png", "out.jpg"], ["--png out.jpg", ".png"]),
        (["design", "-o", "no/such/dir/f.npz"], ["no such directory"]),
        (["design", "--n", "0"], ["--n", "[1, 16]"]),
        (["bench", "--levels", "12"], ["--levels", "[0, 7]", "12"]),
        (["bench", "--levels", "two"], ["--levels", "integer"]),
        (["demo", "-k", "0"], ["-k"]),
        (["demo", "--size", "3x3"], ["--size"]),
        (["param", "--up", "w"], ["--up", "axis"]),
        (["singularities", "--view", "0,0,0"], ["--view"]),
        (["singularities", "--list", "-1"], ["--list"]),
        (["frobnicate"], ["invalid choice"]),
        (["design", "--bogus"], ["unrecognized arguments"]),
        (["design", "nope.obj"], ["nope.obj", "no such file"]),
        (["design", "mesh.xyz"], ["mesh.xyz", "extension"]),
        (["singularities", "--field", "nope.npz"], ["nope.npz", "no such file"]),
    ],
)
def test_argument_errors_are_one_line_before_any_work(tmp_path, args, fragments):
    start = time.perf_counter()
    result = edgevf(*args, cwd=tmp_path)
    assert_error(result, *fragments)
    assert not result.stdout
    assert time.perf_counter() - start < 20  # nothing designed (a design takes longer here)
    assert not list(tmp_path.iterdir()), "an error left files behind"


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


TETRA = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"


@pytest.mark.parametrize(
    "name, text, fragments",
    [
        ("garbage.obj", "this is not a mesh\n\x00\x01\n", ["garbage.obj"]),
        ("nan.obj", TETRA.replace("v 1 0 0", "v nan 0 0"), ["nan.obj", "not finite"]),
        (
            "fin.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nf 1 2 3\nf 2 1 4\nf 1 2 5\n",
            ["non-manifold"],
        ),
    ],
)
def test_bad_mesh_files_are_one_line_errors(tmp_path, name, text, fragments):
    mesh = write(tmp_path / name, text)
    result = edgevf("design", mesh, "-o", tmp_path / "f.npz", cwd=tmp_path)
    assert_error(result, *fragments)
    assert not (tmp_path / "f.npz").exists()


# --------------------------------------------------------------------------- the built-in mesh


def test_demo_on_the_built_in_mesh(tmp_path):
    result = edgevf("demo", "-k", "2", "--png", "demo.png", "--size", "400x300", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert f"mesh: {BUILT_IN}, 829 vertices, 1654 faces" in out
    assert "smallest eigenvalues of (L, M_v):" in out
    assert "smoothest cross field: 55 singularities" in out and "indices sum to 2" in out
    assert "wrote demo.png" in out
    assert "[1/4" in result.stderr and "[4/4" in result.stderr  # progress without -q
    img = read_png(tmp_path / "demo.png")
    assert img.shape[:2] == (300, 400)
    # the singularities it counts are marked: positive green, negative red
    from torch_edgevf import render

    assert colour_blobs(img, render.scene._POSITIVE, 0.12, 8) >= 3
    assert colour_blobs(img, render.scene._NEGATIVE, 0.12, 8) >= 3
    assert colour_blobs(img, render.scene._GLYPH_COLOR, 0.12, 3) > 100


@pytest.mark.parametrize("where", ["before", "after"])
def test_design_quiet_before_or_after_the_command(tmp_path, where):
    quiet = ["-q", "design"] if where == "before" else ["design", "-q"]
    result = edgevf(*quiet, "--n", "2", "-o", "f.txt", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""  # -q: no progress messages, wherever it stands
    assert result.stdout.strip() == "wrote f.txt: 2481 edges, n = 2"
    from torch_edgevf.io import load_field

    data = load_field(tmp_path / "f.txt")
    assert data.n == 2 and data.z.shape == (2481,) and data.faces.shape == (1654, 3)
    if where == "before":
        return
    # the saved field's singularities, listed and drawn (--png used to fail on the argument order)
    result = edgevf("singularities", "--field", "f.txt", "--list", "3", "--png", "s.png", "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.strip().splitlines()
    assert "singularities" in lines[0] and "indices sum to 2" in lines[0]
    assert len(lines) == 5 and all(line.startswith(("  face ", "  vertex ")) for line in lines[1:4])
    assert lines[4] == "wrote s.png"
    from torch_edgevf import render

    img = read_png(tmp_path / "s.png")
    assert colour_blobs(img, render.scene._POSITIVE, 0.12, 8) >= 1
    assert colour_blobs(img, render.scene._NEGATIVE, 0.12, 8) >= 1
    assert colour_blobs(img, render.scene._GLYPH_COLOR, 0.12, 3) > 100


def test_bench_names_the_meshes(tmp_path):
    result = edgevf("bench", "--levels", "0", "1", "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    rows = [line for line in result.stdout.splitlines() if line.startswith("| ") and "---" not in line]
    assert [r.split("|")[1].strip() for r in rows[1:]] == [BUILT_IN, "icosphere level 0", "icosphere level 1"]
    assert rows[1].split("|")[2].strip() == "1654" and rows[3].split("|")[2].strip() == "80"


def test_info_on_the_built_in_mesh(tmp_path):
    result = edgevf("info", "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip()


# --------------------------------------------------------------------------- real meshes


def test_design_on_a_real_mesh_with_a_chosen_view(tmp_path):
    mesh = shared_path("meshes", "fish_low_resolution.obj")
    result = edgevf(
        "design", mesh, "-o", "fish.npz", "--png", "fish.png", "--view", "z", "--up", "y", cwd=tmp_path
    )
    assert result.returncode == 0, result.stderr
    assert f"on {mesh}" in result.stderr  # the progress names the mesh
    assert "wrote fish.npz" in result.stdout and "wrote fish.png" in result.stdout
    from torch_edgevf import render
    from torch_edgevf.io import load_field

    data = load_field(tmp_path / "fish.npz")
    assert data.faces.shape == (1886, 3) and data.n == 4
    img = read_png(tmp_path / "fish.png")
    assert img.shape[:2] == (600, 800)
    assert colour_blobs(img, render.scene._GLYPH_COLOR, 0.12, 3) > 100


def test_param_on_a_real_mesh_is_a_checkerboard(tmp_path):
    mesh = shared_path("meshes", "fish_low_resolution.obj")
    result = edgevf("param", mesh, "--png", "p.png", "--size", "400x300", "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"parametrization of {mesh}: ")
    img = read_png(tmp_path / "p.png")
    fg = (np.abs(img - 1) > 0.02).any(-1)
    dark = (img[..., 2] > img[..., 0] + 0.2) & fg
    assert 0.3 < dark[fg].mean() < 0.7
    # regular squares, not aliased noise: a few dozen of them, holding nearly all dark pixels
    assert blobs(dark, 30) > 15
    from scipy import ndimage

    labels, _ = ndimage.label(dark)
    sizes = np.bincount(labels.ravel())[1:]
    assert sizes[sizes >= 30].sum() > 0.9 * sizes.sum()
    # the title names the flipped faces, which are drawn in red
    flipped = int(result.stdout.split(" flipped faces")[0].rsplit(" ", 1)[-1])
    red = ((img[..., 0] > img[..., 1] + 0.3) & (img[..., 0] > img[..., 2] + 0.3)).sum()
    assert (red > 0) == (flipped > 0), (flipped, red)
    assert (img[:24] < 0.5).all(-1).any()  # text in the title strip


def test_pictures_have_a_title_with_a_legend_and_each_command_builds_its_topology_once(tmp_path, monkeypatch):
    """``design`` and ``singularities`` (in this process): the picture's title names the
    field and the colours of the singularities; the mesh's :class:`Topology` is built once
    for the whole command (checks, design, singularities and picture)."""
    from torch_edgevf import render
    from torch_edgevf.cli import main
    from torch_edgevf.mesh import topology

    titles, built = [], []
    real = render.render_singularities
    monkeypatch.setattr(
        render, "render_singularities", lambda *a, **k: titles.append(k["title"]) or real(*a, **k)
    )
    init = topology.Topology.__init__
    monkeypatch.setattr(
        topology.Topology, "__init__", lambda self, *a, **k: built.append(1) or init(self, *a, **k)
    )
    for argv in (
        [
            "design",
            "-q",
            "--n",
            "2",
            "-o",
            str(tmp_path / "f.npz"),
            "--png",
            str(tmp_path / "d.png"),
            "--size",
            "200x150",
        ],
        ["singularities", "-q", "--png", str(tmp_path / "s.png"), "--size", "200x150"],
    ):
        built.clear()
        assert main(argv) == 0
        assert len(built) == 1, (argv[0], len(built))
    assert titles == [
        "smoothest 2-direction field; singularities: index > 0 green, < 0 red",
        "smoothest 4-direction field; singularities: index > 0 green, < 0 red",
    ]


@pytest.mark.slow
def test_glyphs_on_the_23k_face_spot_are_not_a_texture(tmp_path):
    mesh = shared_path("meshes", "spot.obj")
    result = edgevf("design", mesh, "-o", "spot.npz", "--png", "spot.png", "-q", cwd=tmp_path, timeout=600)
    assert result.returncode == 0, result.stderr
    from torch_edgevf import render

    img = read_png(tmp_path / "spot.png")
    fg = (np.abs(img - 1) > 0.02).any(-1)
    glyph = (np.abs(img - np.asarray(render.scene._GLYPH_COLOR)) < 0.12).all(-1)
    assert blobs(glyph, 3) > 300
    assert glyph[fg].mean() < 0.2
