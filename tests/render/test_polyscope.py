"""polyscope: what show_field registers (mock back-end), and headless screenshots that show the
field and its singularities (skipped where polyscope cannot open a context)."""

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import torch

import torch_edgevf as ev

pytest.importorskip("polyscope")

from torch_edgevf.fields.representation import face_directions, vertex_directions  # noqa: E402
from torch_edgevf.render import scene  # noqa: E402
from torch_edgevf.render.polyscope import show_field  # noqa: E402


def sphere_field(n: int = 4):
    v, f = ev.icosphere(2)
    return v, f, ev.smoothest_field(v, f, n=n)


def mean_edge_length(v, f) -> float:
    e = ev.Topology(f).edges
    return float((v[e[:, 0]] - v[e[:, 1]]).norm(dim=1).mean())


@pytest.fixture
def mock_polyscope():
    """polyscope on its mock back-end (nothing drawn): the data only. The screenshots run in
    a child process, so no other back-end is started in the test processes."""
    import polyscope as ps

    from torch_edgevf.render.polyscope import init

    ps.set_use_prefs_file(False)  # no .polyscope.ini in the working directory
    init("openGL_mock")
    ps.remove_all_structures()
    yield ps
    ps.remove_all_structures()


@pytest.mark.parametrize("at", ["faces", "vertices"])
def test_polyscope_registers_all_n_directions_and_the_singularities(mock_polyscope, at):
    ps = mock_polyscope
    v, f, z = sphere_field(4)
    out = show_field(v, f, z, 4, at=at, scale=0.5, show=False)
    count = f.shape[0] if at == "faces" else v.shape[0]
    assert out.directions.shape == (count, 4, 3) and out.at == at
    assert out.vector_names == [f"mesh direction {k}" for k in range(4)]
    assert ps.has_surface_mesh("mesh") and ps.get_surface_mesh("mesh").n_faces() == f.shape[0]
    # the registered vectors: the field's directions, of length scale * mean edge length
    d = (face_directions if at == "faces" else vertex_directions)(v, f, z, 4).numpy()
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    np.testing.assert_allclose(out.directions, d * 0.5 * mean_edge_length(v, f), rtol=1e-10, atol=1e-12)
    # the four directions turn by 90 degrees
    a, b = out.directions[:, 0], out.directions[:, 1]
    assert np.abs((a * b).sum(-1)).max() < 1e-10 * 0.25 * mean_edge_length(v, f) ** 2
    # the singularities of a cross field on a sphere: indices summing to 2, at their places
    sing = ev.singularities(v, f, z, 4)
    assert out.indices.sum() == pytest.approx(2.0) and len(out.points) == sing.num_singularities
    bary = v[f[sing.singular_faces]].mean(1).numpy()
    np.testing.assert_allclose(out.points[: len(bary)], bary)
    assert ps.has_point_cloud("mesh singularities")
    assert ps.get_point_cloud("mesh singularities").n_points() == len(out.points)


def test_polyscope_options_and_bad_input(mock_polyscope, tmp_path):
    ps = mock_polyscope
    v, f, z = sphere_field(1)
    alone = show_field(v, f, name="plain", show=False)
    assert alone.directions.shape == (f.shape[0], 0, 3) and alone.singularity_cloud is None
    assert not ps.has_point_cloud("plain singularities")
    none = show_field(v, f, z, 1, singularities=False, show=False, name="nosing")
    assert none.directions.shape == (f.shape[0], 1, 3) and len(none.points) == 0
    given = show_field(v, f, z, 1, singularities=ev.singularities(v, f, z, 1), show=False, name="given")
    assert given.indices.sum() == pytest.approx(2.0)
    # a numpy mesh, float32, and replacing a structure of the same name
    again = show_field(v.float().numpy(), f.numpy(), z.to(torch.complex64), 1, show=False, name="given")
    assert again.directions.shape == (f.shape[0], 1, 3)
    for kwargs, match in (
        ({"at": "edges"}, "at must be"),
        ({"scale": 0.0}, "scale"),
        ({"backend": "vulkan"}, "backend"),
        ({"singularities": "yes"}, "singularities"),
        ({"name": ""}, "name"),
    ):
        with pytest.raises(ValueError, match=match):
            show_field(v, f, z, 1, show=False, **kwargs)
    with pytest.raises(ValueError, match=r"z must have shape \(E,\)"):
        show_field(v, f, z[:-1], 1, show=False)
    with pytest.raises(ValueError):
        show_field(v, f, z, 0, show=False)
    other = ev.singularities(*ev.icosphere(1), ev.smoothest_field(*ev.icosphere(1), n=1), 1)
    with pytest.raises(ValueError, match="another mesh"):
        show_field(v, f, z, 1, singularities=other, show=False)


#: the screenshots: in a child process (polyscope starts one back-end per process), which
#: exits 3 where no back-end can open a context
SCREENSHOTS = textwrap.dedent(
    """
    import json, sys
    import torch_edgevf as ev
    from torch_edgevf.render.polyscope import init, show_field

    out = sys.argv[1]
    try:
        ps = init("auto")
    except Exception as e:  # no display, no EGL
        print(f"no context: {type(e).__name__}: {e}")
        sys.exit(3)
    v, f = ev.icosphere(2)
    z1, z4 = ev.smoothest_field(v, f, n=1), ev.smoothest_field(v, f, n=4)
    kw = dict(window_size=(480, 360), show=False)
    show_field(v, f, screenshot=f"{out}/mesh.png", **kw)
    show_field(v, f, z1, 1, singularities=False, screenshot=f"{out}/n1.png", **kw)
    show_field(v, f, z4, 4, singularities=False, screenshot=f"{out}/n4.png", **kw)
    s = show_field(v, f, z4, 4, screenshot=f"{out}/n4_sing.png", **kw)
    print(json.dumps({"singularities": len(s.points)}))
    """
)


def read_png(path) -> np.ndarray:
    from matplotlib.image import imread

    return imread(str(path))[..., :3].astype(np.float64)


def near(img, color, tol: float) -> np.ndarray:
    return (np.abs(img - np.asarray(color)) < tol).all(-1)


def test_polyscope_screenshot_shows_the_field_and_its_singularities(tmp_path):
    """Fails when the field is missing from the picture: its glyphs are the pixels that differ
    from the picture of the mesh alone."""
    pytest.importorskip("matplotlib")
    run = subprocess.run(
        [sys.executable, "-c", SCREENSHOTS, str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,  # polyscope and imgui write their settings there
    )
    if run.returncode == 3:
        pytest.skip(f"polyscope cannot open a context here: {run.stdout.strip()[-300:]}")
    assert run.returncode == 0, run.stderr[-3000:]
    assert json.loads(run.stdout.strip().splitlines()[-1])["singularities"] == 8
    mesh, n1, n4, sing = (read_png(tmp_path / f"{name}.png") for name in ("mesh", "n1", "n4", "n4_sing"))
    assert mesh.shape == (360, 480, 3)
    # the mesh is there: a large grey disc on the white background
    covered = ~near(mesh, (1.0, 1.0, 1.0), 0.02)
    assert 0.2 < covered.mean() < 0.9
    # the glyphs are there: dark pixels where the picture of the mesh alone has none, on the mesh
    diff = [np.abs(img - mesh).max(-1) > 0.1 for img in (n1, n4)]
    assert diff[0].sum() > 0.01 * covered.sum() and (diff[0] & covered).sum() > 0.8 * diff[0].sum()
    luminance = n1.mean(-1)
    assert luminance[diff[0]].mean() < min(0.5, mesh.mean(-1)[diff[0]].mean() - 0.2)
    assert abs(np.array(scene._GLYPH_COLOR).mean() - np.median(luminance[diff[0]])) < 0.25
    # all four directions: about four times the glyph pixels of one direction
    assert 2.5 < diff[1].sum() / diff[0].sum() < 6, (diff[0].sum(), diff[1].sum())
    # the singularities: green markers that the picture without them does not have, one blob
    # per marker facing the camera (8 markers in all, the ones at the outline partly hidden)
    green = [img[..., 1] - np.maximum(img[..., 0], img[..., 2]) > 0.15 for img in (n4, sing)]
    assert green[0].sum() == 0 and green[1].sum() > 200
    from scipy import ndimage

    _, blobs = ndimage.label(green[1])
    assert 4 <= blobs <= 8, blobs
