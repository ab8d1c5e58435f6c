"""Robustness corpus: real meshes and generated bad ones.

Every mesh either yields finite operators (``EdgeOperators`` in float64), a finite
smoothest field and singularities whose indices sum to the Euler characteristic (plus the
boundary turning on meshes with boundary), or raises a ``ValueError`` whose message names
where the problem is. Anything else (another exception, NaN, a hang) fails.

The default run checks a deterministic sample (every 19th PSB mesh, the small shared
meshes, every generated case); ``-m slow`` runs the whole corpus (380 PSB meshes and all
13 shared meshes).
"""

from __future__ import annotations

import contextlib
import logging
import math
import re
import signal
import threading
from functools import lru_cache

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.mesh.diagnose import diagnose

from conftest import SHARED

MESHES = SHARED / "meshes"
PSB = SHARED / "datasets" / "psb_watertight_2k.npz"

SMALL_SHARED = ["sphere.obj", "spot_low_resolution.obj", "fish_low_resolution.obj", "torus.obj"]
ALL_SHARED = sorted(p.name for p in MESHES.glob("*.obj")) if MESHES.is_dir() else []
PSB_COUNT = 380
PSB_FAST = list(range(0, PSB_COUNT, 19))
PSB_ZERO_AREA_ID = 351  # a bearing with a zero-area face after decimation
TIME_LIMIT_S = 180  # a 2,000-face mesh takes ~3 s (40 s for the needle-rich mech meshes under load)

try:
    from torch_edgevf.fields.design import smoothest_field
except ImportError:  # pragma: no cover - design lands separately
    smoothest_field = None
try:
    from torch_edgevf.fields.singularities import singularities
except ImportError:  # pragma: no cover
    singularities = None


# --------------------------------------------------------------------------- helpers


@contextlib.contextmanager
def time_limit(seconds: float, what: str):
    """Fail (instead of hanging the suite) when the block runs longer than ``seconds``."""
    usable = hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()
    if not usable:
        yield
        return

    def handler(signum, frame):
        raise TimeoutError(f"{what} did not finish within {seconds} s (hang?)")

    old = signal.signal(signal.SIGALRM, handler)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def _values(t: torch.Tensor) -> torch.Tensor:
    return t.coalesce().values() if t.is_sparse else t


def check_pipeline(verts, faces, name: str, ns=(1,)) -> dict:
    """Operators, fields and singularities of a valid mesh: all finite and consistent.

    A ``ValueError`` propagates to the caller (which decides whether it is expected).
    """
    verts = torch.as_tensor(verts).to(torch.float64)
    with time_limit(TIME_LIMIT_S, name):
        op = ev.EdgeOperators(verts, faces, n=1)
        topo = op.topology
        for attr in (
            "mass",
            "connection_laplacian",
            "gradient",
            "curl_div",
            "laplace_beltrami",
            "vertex_mass",
            "lumped_vertex_mass",
            "face_area",
            "edge_length",
        ):
            vals = _values(getattr(op, attr))
            assert vals.dtype in (torch.float64, torch.complex128), f"{name}: {attr} is {vals.dtype}"
            assert bool(torch.isfinite(vals).all()), f"{name}: {attr} has NaN/Inf"
        assert bool((op.face_area > 0).all()), f"{name}: non-positive face area"
        assert bool((_values(op.mass) > 0).all()), f"{name}: non-positive edge mass"
        out = {"topology": topo, "fields": {}, "singularities": {}}
        for n in ns:
            if smoothest_field is not None:
                z = smoothest_field(verts, topo, n)
            else:  # until design.smoothest_field lands: any field exercises the rest
                g = torch.Generator().manual_seed(0)
                z = torch.randn(topo.num_edges, generator=g, dtype=torch.complex128)
            assert z.shape == (topo.num_edges,) and z.dtype == torch.complex128
            assert bool(torch.isfinite(z).all()), f"{name}: the n={n} field has NaN/Inf"
            if smoothest_field is not None:
                norm2 = float((_values(op.mass) * z.abs() ** 2).sum())
                assert abs(norm2 - 1) < 1e-8, f"{name}: field not M-normalised ({norm2})"
                lc = ev.connection_laplacian(verts, topo, n).coalesce()
                energy = float((z.conj() * (lc @ z[:, None])[:, 0]).sum().real)
                # PSD up to rounding: relative to the largest Rayleigh quotient of one edge
                idx = lc.indices()
                diag = lc.values()[idx[0] == idx[1]].real
                scale = float((diag / _values(op.mass)[idx[0][idx[0] == idx[1]]]).max())
                assert math.isfinite(energy) and energy >= -1e-10 * scale, (
                    f"{name}: Dirichlet energy {energy} (scale {scale:.3g})"
                )
            out["fields"][n] = z
            if singularities is not None:
                s = singularities(verts, topo, z, n)
                for t in (s.face_index, s.vertex_index):
                    assert bool(torch.isfinite(t).all())
                assert s.max_rounding_error < 1e-6, f"{name}: indices not integral ({s.max_rounding_error})"
                chi = topo.euler_characteristic
                assert s.euler_characteristic == chi
                if topo.is_closed:
                    assert s.total == chi, (
                        f"{name}: n={n} indices sum to {s.total}, Euler characteristic {chi}"
                    )
                    assert s.boundary_turning == 0
                else:
                    assert math.isclose(s.total, chi + s.boundary_turning, abs_tol=1e-9), (
                        f"{name}: n={n} indices sum to {s.total} != chi {chi} + boundary turning "
                        f"{s.boundary_turning}"
                    )
                    assert abs(s.boundary_turning * n - round(s.boundary_turning * n)) < 1e-6
                out["singularities"][n] = s
    return out


# --------------------------------------------------------------------------- shared meshes


def _shared(name: str):
    if not MESHES.is_dir():
        pytest.skip(f"{MESHES} is not available")
    return ev.load_mesh(MESHES / name)


@pytest.mark.parametrize("name", SMALL_SHARED)
def test_small_shared_mesh(name):
    mesh = _shared(name)
    res = check_pipeline(mesh.verts, mesh.faces, name, ns=(1, 4))
    topo = res["topology"]
    assert topo.num_components == 1 and topo.unreferenced_vertices.numel() == 0
    expected_chi = {"torus.obj": 0}.get(name, 2)
    assert topo.euler_characteristic == expected_chi


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in ALL_SHARED if n not in SMALL_SHARED] or ["<none>"])
def test_all_shared_meshes(name):
    if name == "<none>":
        pytest.skip(f"{MESHES} is not available")
    mesh = _shared(name)
    res = check_pipeline(mesh.verts, mesh.faces, name, ns=(1,))
    assert res["topology"].num_components == 1


# --------------------------------------------------------------------------- PSB corpus


@lru_cache(maxsize=1)
def _psb():
    if not PSB.exists():
        return None
    with np.load(PSB) as d:
        return {k: d[k] for k in d.files}


def psb_mesh(k: int):
    d = _psb()
    if d is None:
        pytest.skip(f"{PSB} is not available")
    vo, fo = d["vert_offsets"], d["face_offsets"]
    verts = torch.from_numpy(d["verts"][vo[k] : vo[k + 1]].astype(np.float64))
    faces = torch.from_numpy(d["faces"][fo[k] : fo[k + 1]])  # int32, as stored
    return verts, faces, int(d["psb_ids"][k]), int(d["euler"][k])


def _zero_area_faces(verts: torch.Tensor, faces: torch.Tensor) -> list[int]:
    """Faces with (relative) zero area, found independently of the library."""
    p = verts.numpy()[faces.numpy().astype(np.int64)]
    area2 = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    lmax = np.linalg.norm(p - p[:, [1, 2, 0]], axis=2).max(1)
    return np.flatnonzero(area2 <= 1e-12 * lmax**2).tolist()


def check_psb(k: int):
    verts, faces, psb_id, chi = psb_mesh(k)
    name = f"psb {psb_id}"
    zero = _zero_area_faces(verts, faces)
    if psb_id == PSB_ZERO_AREA_ID or zero:
        assert zero, f"{name}: expected a zero-area face"
        for run in (lambda: ev.EdgeOperators(verts, faces), lambda: check_pipeline(verts, faces, name)):
            with pytest.raises(ValueError, match="zero-area") as info:
                run()
            listed = {int(x) for x in re.findall(r"\d+", str(info.value).split("faces [")[-1])}
            assert set(zero) <= listed, f"{name}: message {info.value!s} does not name faces {zero}"
        return
    res = check_pipeline(verts, faces, name)
    topo = res["topology"]
    assert topo.euler_characteristic == chi, f"{name}: chi {topo.euler_characteristic}, dataset says {chi}"
    assert topo.is_closed and topo.num_components == 1


def _psb_index(psb_id: int) -> int:
    d = _psb()
    if d is None:
        pytest.skip(f"{PSB} is not available")
    return int(np.flatnonzero(d["psb_ids"] == psb_id)[0])


@pytest.mark.parametrize("k", PSB_FAST, ids=lambda k: f"psb#{k}")
def test_psb_sample(k):
    check_psb(k)


def test_psb_zero_area_face_is_named():
    k = _psb_index(PSB_ZERO_AREA_ID)
    verts, faces, _, _ = psb_mesh(k)
    with pytest.raises(ValueError, match=r"zero-area \(degenerate\) faces at faces \[1054\]"):
        ev.EdgeOperators(verts, faces)
    check_psb(k)
    assert any("faces [1054]" in p for p in diagnose(verts, faces).problems)


@pytest.mark.slow
@pytest.mark.parametrize("k", [k for k in range(PSB_COUNT) if k not in PSB_FAST], ids=lambda k: f"psb#{k}")
def test_psb_full(k):
    check_psb(k)


# --------------------------------------------------------------------------- generated meshes


def icosphere(level=1):
    return ev.icosphere(level)


def split_face(verts, faces, face: int, bary):
    """1-to-3 split of one face at the point with barycentric coordinates ``bary``."""
    v = torch.as_tensor(verts, dtype=torch.float64)
    f = torch.as_tensor(faces)
    a, b, c = f[face].tolist()
    p = (torch.tensor(bary, dtype=torch.float64)[:, None] * v[[a, b, c]]).sum(0)
    new = v.shape[0]
    v = torch.cat([v, p[None]])
    rest = torch.cat([f[:face], f[face + 1 :]])
    tri = torch.tensor([[a, b, new], [b, c, new], [c, a, new]])
    return v, torch.cat([rest, tri])


def mobius(n: int = 12):
    """A triangulated Moebius strip (non-orientable)."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    verts = []
    for s in (-0.3, 0.3):
        verts.append(
            np.stack(
                [(1 + s * np.cos(t / 2)) * np.cos(t), (1 + s * np.cos(t / 2)) * np.sin(t), s * np.sin(t / 2)],
                1,
            )
        )
    v = np.concatenate(verts)
    faces = []
    for i in range(n):
        j = (i + 1) % n
        lo_i, hi_i = i, n + i
        lo_j, hi_j = (j, n + j) if j else (n, 0)  # the twist swaps the two sides
        faces += [[lo_i, lo_j, hi_i], [hi_i, lo_j, hi_j]]
    return torch.from_numpy(v), torch.tensor(faces)


def test_mobius_is_rejected_as_non_orientable():
    v, f = mobius()
    with pytest.raises(ValueError, match=r"inconsistent face orientation.*faces involved \[\d"):
        check_pipeline(v, f, "mobius")


def _case_non_manifold_edge():
    v, f = icosphere()
    a, b = f[0, 0].item(), f[0, 1].item()
    v = torch.cat([v, torch.tensor([[0.0, 0.0, 3.0]], dtype=v.dtype)])
    f = torch.cat([f, torch.tensor([[a, b, v.shape[0] - 1]])])
    return (
        v,
        f,
        rf"non-manifold edges.*\({min(a, b)}, {max(a, b)}\).*faces involved \[[^\]]*\b{f.shape[0] - 1}\b",
    )


def _case_non_manifold_vertex():
    """Two closed icosphere-level-0 shells glued at one vertex."""
    v, f = ev.icosphere(0)
    nv = v.shape[0]
    v2 = v + torch.tensor([2.0, 0.0, 0.0], dtype=v.dtype)
    f2 = f + nv
    f2[f2 == nv + 0] = 0  # identify vertex 0 of the second copy with vertex 0 of the first
    return torch.cat([v, v2]), torch.cat([f, f2]), r"non-manifold vertices.*vertices \[0\]"


def _case_bowtie():
    v = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], dtype=torch.float64)
    return v, torch.tensor([[0, 1, 2], [0, 3, 4]]), r"non-manifold vertices.*vertices \[0\]"


def _case_zero_area():
    v, f = icosphere()
    v = v.clone()
    a, b, c = f[4].tolist()
    v[c] = 0.5 * (v[a] + v[b])  # collinear corners
    return v, f, r"zero-area.*faces \[[^\]]*\b4\b"


def _case_coincident():
    v, f = icosphere()
    v = v.clone()
    v[f[4, 2]] = v[f[4, 0]]  # two corners at the same place
    return v, f, r"zero-area.*faces \[[^\]]*\b4\b"


def _case_duplicated_face():
    v, f = icosphere()
    return v, torch.cat([f, f[3:4]]), rf"duplicated faces.*\[3, {f.shape[0]}\]"


def _case_duplicated_face_flipped():
    v, f = icosphere()
    return v, torch.cat([f, f[3:4].flip(1)]), rf"duplicated faces.*\[3, {f.shape[0]}\]"


def _case_nan():
    v, f = icosphere()
    v = v.clone()
    v[5, 2] = float("nan")
    return v, f, r"NaN or Inf.*vertices \[5\]"


def _case_inf():
    v, f = icosphere()
    v = v.clone()
    v[7, 0] = float("inf")
    return v, f, r"NaN or Inf.*vertices \[7\]"


def _case_flipped():
    v, f = icosphere()
    f = f.clone()
    f[7] = f[7].flip(0)
    return v, f, r"inconsistent face orientation.*faces involved \[[^\]]*\b7\b"


def _case_out_of_range():
    v, f = icosphere()
    f = f.clone()
    f[9, 1] = v.shape[0] + 3
    return v, f, r"out-of-range.*faces \[9\]"


def _case_negative():
    v, f = icosphere()
    f = f.clone()
    f[2, 0] = -1
    return v, f, r"negative.*faces \[2\]"


def _case_repeated_index():
    v, f = icosphere()
    f = f.clone()
    f[6, 2] = f[6, 0]
    return v, f, r"repeat a vertex.*faces \[6\]"


def _case_float_faces():
    v, f = icosphere()
    return v, f.to(torch.float64), r"integer dtype"


def _case_empty():
    v, _ = icosphere()
    return v, torch.zeros(0, 3, dtype=torch.int64), r"empty"


BAD = {
    "non_manifold_edge": _case_non_manifold_edge,
    "non_manifold_vertex": _case_non_manifold_vertex,
    "bowtie": _case_bowtie,
    "zero_area": _case_zero_area,
    "coincident_corners": _case_coincident,
    "duplicated_face": _case_duplicated_face,
    "duplicated_face_flipped": _case_duplicated_face_flipped,
    "nan_coordinate": _case_nan,
    "inf_coordinate": _case_inf,
    "flipped_face": _case_flipped,
    "out_of_range_index": _case_out_of_range,
    "negative_index": _case_negative,
    "repeated_index": _case_repeated_index,
    "float_faces": _case_float_faces,
    "empty": _case_empty,
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_mesh_raises_value_error_naming_location(case):
    v, f, pattern = BAD[case]()
    with pytest.raises(ValueError, match=pattern):
        check_pipeline(v, f, case)
    # every operator entry point fails the same clear way, before any numerical work
    for fn in (lambda: ev.connection_laplacian(v, f, 1), lambda: ev.laplace_beltrami(v, f)):
        with pytest.raises(ValueError, match=pattern):
            fn()


@pytest.mark.parametrize("case", BAD)
def test_geometry_and_diagnose_report_bad_mesh(case):
    """The geometry entry points and diagnose() never crash: ValueError / a listed problem."""
    v, f, pattern = BAD[case]()
    diagnosis = diagnose(v, f)
    assert not diagnosis.ok and any(re.search(pattern, p) for p in diagnosis.problems), diagnosis.problems
    if case in (
        "non_manifold_edge",
        "non_manifold_vertex",
        "bowtie",
        "duplicated_face",
        "duplicated_face_flipped",
        "flipped_face",
    ):
        ev.face_areas(v, f)  # purely topological problems: per-face geometry is still defined
    else:
        with pytest.raises(ValueError):
            ev.face_areas(v, f)


def _needle_cap():
    """A face split at a point 1e-7 from an edge: a cap with an angle near 180 degrees."""
    v, f = icosphere(1)
    return split_face(v, f, 0, [0.5 - 5e-8, 0.5 - 5e-8, 1e-7])


def _needle_short_edge():
    """A face split at a point 1e-6 from a corner: needles with a very short edge."""
    v, f = icosphere(1)
    return split_face(v, f, 0, [1 - 2e-6, 1e-6, 1e-6])


def _single_needle():
    v = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0.5, 1e-6, 0]], dtype=torch.float64)
    return v, torch.tensor([[0, 1, 2]])


def _isolated_vertices():
    v, f = icosphere(1)
    extra = torch.tensor([[5.0, 5, 5], [0, 0, 0]], dtype=v.dtype)
    return torch.cat([v[:3], extra[:1], v[3:], extra[1:]]), torch.where(f >= 3, f + 1, f)


def _components():
    v, f = icosphere(1)
    g, gf = ev.meshes.grid(3, 3)
    parts_v = [v, v * 0.5 + 3, g + torch.tensor([0.0, 0.0, -4.0], dtype=g.dtype)]
    parts_f, offset = [], 0
    for pv, pf in zip(parts_v, [f, f, gf]):
        parts_f.append(pf + offset)
        offset += pv.shape[0]
    return torch.cat(parts_v), torch.cat(parts_f)


def _grid():
    return ev.meshes.grid(5, 5)


def _cylinder():
    return ev.meshes.cylinder(n_around=12, n_along=4)


def _hemisphere():
    v, f = icosphere(2)
    keep = (v[f][:, :, 2] > -1e-9).all(1)
    f = f[keep]
    v2, f2, _ = ev.remove_unreferenced_vertices(v, f)
    return v2, f2


def _tiny():
    v, f = icosphere(1)
    return v * 1e-9, f


def _huge():
    v, f = icosphere(1)
    return v * 1e9, f


def _float32():
    v, f = icosphere(1)
    return v.to(torch.float32), f.to(torch.int32)


GOOD = {
    "needle_cap": (_needle_cap, {"chi": 2}),
    "needle_short_edge": (_needle_short_edge, {"chi": 2}),
    "single_needle": (_single_needle, {"chi": 1}),
    "isolated_vertices": (_isolated_vertices, {"chi": 2, "unreferenced": [3, 43]}),
    "several_components": (_components, {"chi": 5, "components": 3}),
    "grid_boundary": (_grid, {"chi": 1}),
    "cylinder_two_boundaries": (_cylinder, {"chi": 0}),
    "hemisphere": (_hemisphere, {"chi": 1}),
    "tiny_scale": (_tiny, {"chi": 2}),
    "huge_scale": (_huge, {"chi": 2}),
    "float32_int32_input": (_float32, {"chi": 2}),
}


@pytest.mark.parametrize("case", list(GOOD))
def test_valid_but_awkward_mesh_gives_finite_results(case):
    build, expect = GOOD[case]
    v, f = build()
    need = singularities is not None
    res = check_pipeline(v, f, case, ns=(1, 4) if need else (1,))
    topo = res["topology"]
    assert topo.euler_characteristic == expect["chi"]
    assert topo.num_components == expect.get("components", 1)
    assert topo.unreferenced_vertices.tolist() == expect.get("unreferenced", [])
    if not need:
        pytest.skip("torch_edgevf.fields.singularities is not available yet: index sums not checked")


def test_isolated_vertices_documented_behaviour():
    """Unreferenced vertices are kept: zero rows and columns in the vertex operators."""
    v, f = _isolated_vertices()
    op = ev.EdgeOperators(v, f)
    iso = [3, 43]
    for m in (op.laplace_beltrami, op.vertex_mass, op.lumped_vertex_mass):
        dense = m.to_dense()
        assert bool((dense[iso] == 0).all()) and bool((dense[:, iso] == 0).all())
    assert bool((op.gradient.to_dense()[:, iso] == 0).all())
    if singularities is not None:
        z = smoothest_field(v, f, 1)
        s = singularities(v, f, z, 1)
        assert s.vertex_index[iso].tolist() == [0.0, 0.0]


def test_needle_operators_are_large_but_finite():
    """The cap's obtuse angle gives a cotangent of about -1e7: finite, and still PSD."""
    v, f = _needle_cap()
    op = ev.EdgeOperators(v, f, n=1)
    dense = op.connection_laplacian.to_dense()
    assert bool(torch.isfinite(dense).all())
    assert float(dense.abs().max()) > 1e5  # the degeneracy is really there
    evals = torch.linalg.eigvalsh(dense)
    assert float(evals.min()) > -1e-8 * float(evals.max())


def test_smoothest_field_converges_on_needle_rich_psb_mesh(caplog):
    """PSB 325 (mech) has faces of relative area 1e-8: the eigensolver must still converge."""
    if smoothest_field is None:
        pytest.skip("torch_edgevf.fields.design is not available")
    k = _psb_index(325)
    verts, faces, _, _ = psb_mesh(k)
    with caplog.at_level(logging.WARNING, logger="torch_edgevf"):
        z = smoothest_field(verts, faces, 1)
    assert bool(torch.isfinite(z).all())
    stalls = [r.getMessage() for r in caplog.records if "did not converge" in r.getMessage()]
    assert not stalls, stalls


def _cap_pencil(depth: float):
    """The cotangent Laplacian and lumped mass of icosphere 3 with one face split at a point
    ``depth`` (barycentric) from an edge: a cap face whose obtuse angle's cotangent is
    about ``-1 / depth``, at the new vertex 642."""
    v, f = ev.icosphere(3)
    v, f = split_face(v, f, 0, [0.5, 0.5 - depth, depth])
    topo = ev.Topology(f, num_vertices=len(v))
    return ev.cotan_laplacian(v, topo), ev.vertex_mass(v, topo, lumped=True).values()


@pytest.mark.parametrize("method", ["dense", "lanczos"])
def test_eigsh_on_a_moderate_cap_is_accurate(method):
    L, m = _cap_pencil(1e-7)
    values = ev.linalg.eigsh(L, m, 16, method=method).values
    assert abs(float(values[0])) < 1e-6 and abs(float(values[1]) - 2.0) < 1e-4  # l(l+1) on the sphere


def test_eigsh_refuses_pairs_that_are_not_eigenpairs():
    """Cotangent weights of 1e13 beside tiny masses: LAPACK's dense solver returns pairs
    with residuals of a thousandth of the spectrum, silently. eigsh raises, naming the cap's
    vertex and the remedy, instead of returning them."""
    L, m = _cap_pencil(1e-13)
    with pytest.raises(ValueError, match=r"residual of .* none are returned\. Rows \[642,.*repair the mesh"):
        ev.linalg.eigsh(L, m, 16, method="dense")


def test_eigsh_raises_when_lanczos_does_not_converge():
    v, f = ev.icosphere(3)
    topo = ev.Topology(f, num_vertices=len(v))
    L, m = ev.cotan_laplacian(v, topo), ev.vertex_mass(v, topo, lumped=True).values()
    with pytest.raises(ValueError, match="did not converge in 1 restarts .* raise maxiter or tol"):
        ev.linalg.eigsh(L, m, 16, method="lanczos", maxiter=1, ncv=20)
    assert ev.linalg.eigsh(L, m, 16, method="lanczos").values.shape == (16,)  # the default converges
