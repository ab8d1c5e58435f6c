"""Headless renderings: the PNGs are not blank, show the mesh, and draw what they should."""

import math

import numpy as np
import pytest
import torch

import torch_edgevf as ev

pytest.importorskip("matplotlib")

from torch_edgevf import render  # noqa: E402

SIZE = 300
GLYPH = np.array(render.scene._GLYPH_COLOR)
GREEN = np.array(render.scene._POSITIVE)
RED = np.array(render.scene._NEGATIVE)


def read_png(path) -> np.ndarray:
    """(H, W, 3) floats in [0, 1]."""
    from matplotlib.image import imread

    with open(path, "rb") as fh:
        assert fh.read(8) == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    return imread(str(path))[..., :3].astype(np.float64)


def foreground(img: np.ndarray) -> np.ndarray:
    """Pixels that differ from the white background."""
    return (np.abs(img - 1.0) > 0.02).any(-1)


def near(img: np.ndarray, color, tol: float = 0.12) -> np.ndarray:
    return (np.abs(img - np.asarray(color)) < tol).all(-1)


def blobs(mask: np.ndarray, min_pixels: int = 3) -> int:
    """Connected components of ``mask`` with at least ``min_pixels`` pixels."""
    from scipy import ndimage

    labels, count = ndimage.label(mask)
    if not count:
        return 0
    return int((np.bincount(labels.ravel())[1:] >= min_pixels).sum())


def glyph_count(img: np.ndarray) -> int:
    return blobs(near(img, GLYPH, 0.12))


def random_field(ne: int, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.complex(
        torch.randn(ne, generator=g, dtype=torch.float64), torch.randn(ne, generator=g, dtype=torch.float64)
    )


def assert_shows_mesh(img: np.ndarray):
    h, w = img.shape[:2]
    assert img.reshape(-1, 3).std(0).max() > 0.1, "image is (nearly) blank"
    distinct = np.unique((img.reshape(-1, 3) * 255).round().astype(np.int64), axis=0)
    assert len(distinct) >= 20, f"only {len(distinct)} distinct colours"
    fg = foreground(img)
    centre = fg[int(0.35 * h) : int(0.65 * h), int(0.35 * w) : int(0.65 * w)]
    assert centre.mean() > 0.95, f"mesh covers only {centre.mean():.0%} of the image centre"
    rows, cols = np.flatnonzero(fg.any(1)), np.flatnonzero(fg.any(0))
    assert (rows[-1] - rows[0]) / h > 0.8 and (cols[-1] - cols[0]) / w > 0.8, (
        f"bounding box of the drawing spans {(rows[-1] - rows[0]) / h:.0%} x {(cols[-1] - cols[0]) / w:.0%}"
    )


@pytest.fixture(scope="module")
def sphere():
    v, f = ev.icosphere(2)
    topo = ev.Topology(f, v.shape[0])
    return v, f, topo


@pytest.mark.parametrize("n", [1, 4])
def test_field_png_shows_mesh_and_glyphs(sphere, tmp_path, n):
    v, f, topo = sphere
    z = random_field(topo.num_edges, seed=n)
    out = render.render_field(v, f, z, tmp_path / f"field{n}.png", n=n, size=SIZE)
    assert out == tmp_path / f"field{n}.png" and out.exists()
    img = read_png(out)
    assert img.shape[:2] == (SIZE, SIZE)
    assert_shows_mesh(img)
    bare = read_png(render.render_mesh(v, f, tmp_path / "bare.png", size=SIZE))
    assert_shows_mesh(bare)
    # about one glyph per visible face (160) at this size: each one a separate blob
    assert glyph_count(img) > 80 and glyph_count(bare) == 0, (glyph_count(img), glyph_count(bare))


def test_smoothest_field_png(sphere, tmp_path):
    design = pytest.importorskip("torch_edgevf.fields.design")
    v, f, _ = sphere
    z = design.smoothest_field(v, f, 2)
    img = read_png(render.render_field(v, f, z, tmp_path / "line.png", n=2, size=SIZE, elev=35, azim=10))
    assert_shows_mesh(img)


def test_back_face_glyphs_are_culled(tmp_path):
    """A flat grid seen from above carries glyphs; seen from below, none."""
    v, f = ev.meshes.grid(6, 6)
    topo = ev.Topology(f, v.shape[0])
    z = torch.ones(topo.num_edges, dtype=torch.complex128)
    above = read_png(render.render_field(v, f, z, tmp_path / "above.png", size=SIZE, elev=90, azim=0))
    below = read_png(render.render_field(v, f, z, tmp_path / "below.png", size=SIZE, elev=-90, azim=0))
    assert glyph_count(above) > 30
    assert glyph_count(below) == 0
    assert foreground(below).mean() > 0.5, "the back side of the grid itself is still drawn"


def naive_face_directions(v, topo, z, n):
    """psi(b) = sum_k 1/3 u_k^n z_k in the face frame, then its n angle roots, in 3D."""
    v = v.numpy()
    out = np.zeros((topo.num_faces, n, 3))
    for t, face in enumerate(topo.faces.tolist()):
        p = v[face]
        normal = np.cross(p[1] - p[0], p[2] - p[0])
        normal /= np.linalg.norm(normal)
        xt = (p[1] - p[0]) / np.linalg.norm(p[1] - p[0])
        yt = np.cross(normal, xt)
        w = 0
        for k in range(3):
            e = int(topo.face_edges[t, k])
            i, j = topo.edges[e].tolist()
            xe = (v[j] - v[i]) / np.linalg.norm(v[j] - v[i])
            u = complex(xe @ xt, xe @ yt)
            w += (u**n) * complex(z[e]) / 3
        for k in range(n):
            root = abs(w) * np.exp(1j * (np.angle(w) + 2 * math.pi * k) / n)
            out[t, k] = root.real * xt + root.imag * yt
    return out


@pytest.mark.parametrize("n", [1, 2, 4])
def test_glyph_directions_match_naive_barycenter_formula(n):
    from conftest import perturbed_icosphere

    v, f = perturbed_icosphere(1, 0.05, seed=3)
    topo = ev.Topology(f, v.shape[0])
    z = random_field(topo.num_edges, seed=7)
    got = render.face_glyph_directions(v, topo, z, n).numpy()
    np.testing.assert_allclose(got, naive_face_directions(v, topo, z, n), atol=1e-12)


def test_singularities_png_colours_by_sign(sphere, tmp_path):
    v, f, topo = sphere
    rng = np.random.default_rng(0)
    fi = np.zeros(topo.num_faces)
    vi = np.zeros(topo.num_vertices)
    fi[rng.choice(topo.num_faces, 30, replace=False)] = 1.0
    vi[rng.choice(topo.num_vertices, 30, replace=False)] = -1.0
    img = read_png(
        render.render_singularities(
            v, f, tmp_path / "s.png", torch.from_numpy(fi), torch.from_numpy(vi), size=SIZE
        )
    )
    assert_shows_mesh(img)
    assert near(img, GREEN).mean() > 1e-3 and near(img, RED).mean() > 1e-3


def test_singularities_of_a_field(sphere, tmp_path):
    sing = pytest.importorskip("torch_edgevf.fields.singularities")
    v, f, topo = sphere
    z = random_field(topo.num_edges, seed=1)
    s = sing.singularities(v, f, z, 1)
    assert (s.face_index > 0).any() and (s.face_index < 0).any()
    img = read_png(
        render.render_singularities(v, f, tmp_path / "s.png", s.face_index, s.vertex_index, z=z, size=SIZE)
    )
    assert blobs(near(img, GREEN), 10) >= 1 and blobs(near(img, RED), 10) >= 1
    assert glyph_count(img) > 50


def test_hidden_singularity_is_not_drawn(sphere, tmp_path):
    v, f, topo = sphere
    cam = render.Camera(elev=0, azim=0)
    normal = ev.face_normals(v, f).numpy() @ cam.view
    facing, away = int(np.argmax(normal)), int(np.argmin(normal))
    for face, expect in ((facing, True), (away, False)):
        fi = torch.zeros(topo.num_faces, dtype=torch.float64)
        fi[face] = 1.0
        img = read_png(render.render_singularities(v, f, tmp_path / f"{face}.png", fi, camera=cam, size=SIZE))
        assert (near(img, GREEN).sum() > 20) == expect, (face, expect)


def test_parametrization_checkerboard(tmp_path):
    v, f = ev.meshes.grid(8, 8)
    uv = v[:, :2][f]  # (F, 3, 2)
    img = read_png(
        render.render_parametrization(
            v, f, uv, tmp_path / "p.png", scale=4, subdivide=3, elev=90, azim=-90, size=SIZE
        )
    )
    fg = foreground(img)
    assert fg.mean() > 0.7
    # the light squares are shaded white-ish but not background white; the dark ones blue
    dark = img[..., 2] > img[..., 0] + 0.2
    frac = dark[fg].mean()
    assert 0.35 < frac < 0.65, f"dark squares cover {frac:.0%} of the grid, expected about half"
    # a 4 x 4 checkerboard: along the middle row the colour changes about 4 times
    row = dark[SIZE // 2 + 7, :][fg[SIZE // 2 + 7, :]]
    changes = int(np.abs(np.diff(row.astype(int))).sum())
    assert 3 <= changes <= 6, changes


def test_parametrization_marks_its_flipped_faces_in_red(tmp_path):
    """A face whose (u, v) triangle is reversed is drawn whole in red; none elsewhere, and
    none with ``flipped_color=None``."""
    v, f = ev.meshes.grid(8, 8)
    uv = v[:, :2][f].clone()  # (F, 3, 2)

    def red(uv, name, **options) -> int:  # pixels whose red channel dominates (shaded red)
        out = tmp_path / name
        img = read_png(
            render.render_parametrization(
                v, f, uv, out, scale=4, subdivide=2, elev=90, azim=-90, size=SIZE, **options
            )
        )
        return int(((img[..., 0] > img[..., 1] + 0.3) & (img[..., 0] > img[..., 2] + 0.3)).sum())

    assert red(uv, "plain.png") == 0
    flipped = uv.clone()
    flipped[:10] = flipped[:10, [0, 2, 1]]  # 10 faces reversed
    assert red(flipped, "flipped.png") > 10 * 20  # about 10 faces' worth of pixels
    assert red(flipped, "unmarked.png", flipped_color=None) == 0


def test_parametrization_on_sphere_shows_mesh(sphere, tmp_path):
    v, f, _ = sphere
    vv = v.numpy()
    uv = np.stack(
        [np.arctan2(vv[:, 1], vv[:, 0]) / math.pi, np.arccos(np.clip(vv[:, 2], -1, 1)) / math.pi], -1
    )
    img = read_png(
        render.render_parametrization(v, f, uv[f.numpy()], tmp_path / "p.png", subdivide=1, size=SIZE)
    )
    assert_shows_mesh(img)


def test_float32_numpy_inputs(tmp_path):
    v, f = ev.icosphere(1, dtype=torch.float32)
    out = render.render_mesh(v.numpy(), f.numpy().astype(np.int32), tmp_path / "m.png", size=64, edges=True)
    assert_shows_mesh(read_png(out))


def test_errors(sphere, tmp_path):
    v, f, topo = sphere
    with pytest.raises(ValueError, match="uv must have shape"):
        render.render_parametrization(v, f, torch.zeros(topo.num_faces, 2), tmp_path / "x.png")
    with pytest.raises(ValueError, match="face_index must have shape"):
        render.render_singularities(v, f, tmp_path / "x.png", torch.zeros(3))
    with pytest.raises(ValueError, match="size"):
        render.render_mesh(v, f, tmp_path / "x.png", size=3)
    with pytest.raises(ValueError, match="elev"):
        render.render_mesh(v, f, tmp_path / "x.png", elev=float("nan"))
    with pytest.raises(ValueError, match="z must have shape"):
        render.render_field(v, f, torch.zeros(5, dtype=torch.complex128), tmp_path / "x.png")
    bad = v.clone()
    bad[4, 1] = float("nan")
    with pytest.raises(ValueError, match=r"vertices \[4\]"):
        render.render_mesh(bad, f, tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()


def test_parametrization_from_param_module(sphere, tmp_path):
    param = pytest.importorskip("torch_edgevf.fields.param")
    design = pytest.importorskip("torch_edgevf.fields.design")
    v, f, _ = sphere
    result = param.parametrize(v, f, design.smoothest_field(v, f, 4))
    img = read_png(
        render.render_parametrization(
            result.verts, result.faces, result.uv, tmp_path / "p.png", scale=1.0, size=SIZE
        )
    )
    assert_shows_mesh(img)
    fg = foreground(img)
    dark = (img[..., 2] > img[..., 0] + 0.2)[fg].mean()
    assert 0.2 < dark < 0.8, f"checkerboard dark squares cover {dark:.0%}"


# --------------------------------------------------------------------------- view, density, checker


def terrain(flip: bool = False):
    """A bumpy 24 x 24 height field over the xz plane, facing +y (or -y when flipped)."""
    v, f = ev.meshes.grid(24, 24, size=(2.0, 2.0))
    x, y = v[:, 0] - 1, v[:, 1] - 1
    h = 0.3 * torch.exp(-4 * (x**2 + y**2))
    v = torch.stack([x, h, -y], 1)  # y up; (x, y, 0) -> (x, 0, -y) keeps the normal pointing up
    if flip:
        f = f[:, [0, 2, 1]]
    return v, f


@pytest.mark.parametrize("flip", [False, True])
def test_terrain_is_seen_from_the_side_it_faces(tmp_path, flip):
    v, f = terrain(flip)
    cam = render.choose_camera(v, f)
    facing = ev.face_normals(v, f).mean(0).numpy()
    assert cam.view @ facing > 0.5, (cam.view, facing)
    topo = ev.Topology(f, v.shape[0])
    z = torch.ones(topo.num_edges, dtype=torch.complex128)
    img = read_png(render.render_field(v, f, z, tmp_path / "t.png", size=SIZE))
    assert glyph_count(img) > 50


def test_closed_mesh_stands_upright_y_up():
    """OBJ meshes are y up: Spot (built in) stands on its feet, seen from 25 degrees above."""
    mesh = ev.default_mesh()
    cam = render.choose_camera(mesh.verts, mesh.faces)
    np.testing.assert_allclose(cam.upward @ [0.0, 1.0, 0.0], math.cos(math.radians(25)), atol=1e-9)
    assert abs(cam.elev - 25) < 1e-9
    # the chosen side shows at least as much front-facing area as every other azimuth tried
    cross = np.cross(
        *(
            mesh.verts.numpy()[mesh.faces.numpy()][:, k] - mesh.verts.numpy()[mesh.faces.numpy()][:, 0]
            for k in (1, 2)
        )
    )
    areas = [np.maximum(cross @ render.Camera(25, a, (0, 1, 0)).view, 0).sum() for a in range(0, 360, 15)]
    assert np.maximum(cross @ cam.view, 0).sum() >= max(areas) - 1e-12


def test_explicit_up_and_view():
    v, f = ev.icosphere(1)
    cam = render.choose_camera(v, f, up="z", view="x")
    np.testing.assert_allclose(cam.view, [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(cam.upward, [0, 0, 1], atol=1e-12)
    cam = render.choose_camera(v, f, up=(0, 0, 2), view=(1, 1, 1))
    np.testing.assert_allclose(cam.view, np.ones(3) / math.sqrt(3), atol=1e-12)
    cam = render.choose_camera(v, f, up="-y", elev=10, azim=30)
    assert (cam.elev, cam.azim) == (10, 30)
    with pytest.raises(ValueError, match="either view or elev/azim"):
        render.choose_camera(v, f, view="x", elev=10)
    with pytest.raises(ValueError, match="up must be"):
        render.choose_camera(v, f, up="w")
    with pytest.raises(ValueError, match="view must be"):
        render.choose_camera(v, f, view=(0, 0, 0))


def test_rectangular_size(tmp_path):
    v, f = ev.icosphere(1)
    img = read_png(render.render_mesh(v, f, tmp_path / "m.png", size=(200, 120)))
    assert img.shape[:2] == (120, 200)
    with pytest.raises(ValueError, match="size"):
        render.render_mesh(v, f, tmp_path / "x.png", size=(200,))


def test_glyph_density_follows_the_screen_not_the_mesh(tmp_path):
    """20k faces: about one glyph per 14 x 14 pixels, not a glyph per face (a dark texture)."""
    v, f = ev.icosphere(5)
    topo = ev.Topology(f, v.shape[0])
    z = random_field(topo.num_edges, seed=2)
    img = read_png(render.render_field(v, f, z, tmp_path / "dense.png", size=SIZE))
    disc = foreground(img).sum()
    count = glyph_count(img)
    assert 0.3 * disc / 14**2 < count < 1.5 * disc / 14**2, (count, disc / 14**2)
    assert near(img, GLYPH, 0.12)[foreground(img)].mean() < 0.25
    every = read_png(render.render_field(v, f, z, tmp_path / "every.png", size=SIZE, glyph_spacing=None))
    assert near(every, GLYPH, 0.2)[foreground(every)].mean() > near(img, GLYPH, 0.2)[foreground(img)].mean()
    coarse = read_png(render.render_field(v, f, z, tmp_path / "coarse.png", size=SIZE, glyph_spacing=28))
    assert glyph_count(coarse) < 0.5 * count
    with pytest.raises(ValueError, match="glyph_spacing"):
        render.render_field(v, f, z, tmp_path / "x.png", glyph_spacing=1)


def checker_period(dark: np.ndarray) -> float:
    """Pixels per checker square along the rows of ``dark``, from the peak of their mean spectrum."""
    x = dark.astype(np.float64) - dark.mean(axis=1, keepdims=True)
    spectrum = np.abs(np.fft.rfft(x, axis=1)).mean(axis=0)
    spectrum[:2] = 0
    return x.shape[1] / int(np.argmax(spectrum)) / 2


@pytest.mark.parametrize("uv_scale", [0.02, 1.0, 37.0])
def test_checker_scale_follows_the_uv_range(tmp_path, uv_scale):
    """Whatever the uv units, about 15 regular squares across, both colours in equal parts."""
    v, f = ev.meshes.grid(30, 30)
    uv = (uv_scale * v[:, :2])[f]
    scale = render.checker_scale(v, f, uv)
    assert 10 <= scale * uv_scale <= 20, scale
    img = read_png(render.render_parametrization(v, f, uv, tmp_path / "p.png", view="z", up="y", size=SIZE))
    fg = foreground(img)
    dark = img[..., 2] > img[..., 0] + 0.2
    assert 0.4 < dark[fg].mean() < 0.6
    rows, cols = np.flatnonzero(fg.any(1)), np.flatnonzero(fg.any(0))
    block = dark[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]
    expected = block.shape[1] / (scale * uv_scale)  # pixels per square
    for period in (checker_period(block), checker_period(block.T)):
        assert abs(period - expected) < 0.1 * expected, (period, expected)


def test_checker_scale_is_an_integer_or_its_inverse():
    v, f = ev.meshes.grid(4, 4)
    for s in (0.003, 0.3, 3.0, 300.0):
        scale = render.checker_scale(v, f, (s * v[:, :2])[f])
        assert scale == round(scale) or 1 / scale == round(1 / scale), scale
