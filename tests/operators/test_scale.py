"""Scale covariance: the operators of a well-shaped mesh at any scale the dtype can hold.

``L_c`` does not depend on the scale ``s`` of the positions, ``M_z`` is proportional to
``s^2`` and the eigenvalues of ``(L_c, M_z)`` to ``1 / s^2``; where the areas cannot be
represented in the dtype a ``ValueError`` names the scale.
"""

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import torch_edgevf as ev
from torch_edgevf.linalg import eigsh
from torch_edgevf.mesh.geometry import FaceGeometry, face_geometry

VERTS, FACES = ev.icosphere(2)
RTOL = {torch.float64: 1e-12, torch.float32: 2e-5}


def _operators(verts):
    ops = ev.EdgeOperators(verts, FACES, n=1)
    return ops.connection_laplacian.coalesce(), ops.mass.coalesce()


REFERENCE = {dt: _operators(VERTS.to(dt)) for dt in (torch.float64, torch.float32)}


def _check_covariance(dtype, exponent):
    s = 10.0**exponent
    L, M = _operators((VERTS * s).to(dtype))
    L0, M0 = REFERENCE[dtype]
    assert torch.isfinite(L.values()).all() and torch.isfinite(M.values()).all()
    assert torch.equal(L.indices(), L0.indices())
    rtol = RTOL[dtype]
    # L_c unchanged
    err = (L.values() - L0.values()).abs().max() / L0.values().abs().max()
    assert err <= rtol, (s, float(err))
    # M_z times s^2 (compared in double: s^2 M0 may not be representable in float32)
    ratio = M.values().double() / (M0.values().double() * s * s)
    assert (ratio - 1).abs().max() <= rtol, (s, float((ratio - 1).abs().max()))
    return L, M, s


@settings(max_examples=12, deadline=None, derandomize=True)
@given(st.floats(-30, 30))
def test_float64_operators_scale_covariant(exponent):
    _check_covariance(torch.float64, exponent)


@settings(max_examples=12, deadline=None, derandomize=True)
@given(st.floats(-12, 12))
def test_float32_operators_scale_covariant(exponent):
    _check_covariance(torch.float32, exponent)


@pytest.mark.parametrize("method", ["lanczos", "dense"])
@pytest.mark.parametrize(
    "dtype, exponent",
    [(torch.float64, -30), (torch.float64, 30), (torch.float32, -12), (torch.float32, 12)],
)
def test_eigenvalues_divided_by_s2(dtype, exponent, method):
    L, M, s = _check_covariance(dtype, exponent)
    L0, M0 = REFERENCE[torch.float64]
    lam0 = eigsh(L0, M0, 6, method=method).values
    lam = eigsh(L.to(torch.complex128), M.double(), 6, method=method).values
    assert torch.isfinite(lam).all()
    torch.testing.assert_close(lam * s * s, lam0, rtol=1e-10 if dtype == torch.float64 else 1e-4, atol=0)


@pytest.mark.parametrize("exponent", [-100, 100])
def test_dense_eigenvalues_at_extreme_scales(exponent):
    L, M, s = _check_covariance(torch.float64, exponent)
    L0, M0 = REFERENCE[torch.float64]
    lam = eigsh(L, M, 6, method="dense").values
    torch.testing.assert_close(lam * s * s, eigsh(L0, M0, 6, method="dense").values, rtol=1e-10, atol=0)


def test_extreme_scales_bit_identical_for_powers_of_two():
    # the per-face scaling is by powers of two: exact
    base = face_geometry(VERTS, FACES)
    for k in (-300, -120, 120, 300):
        s = math.ldexp(1.0, k)
        g = face_geometry(VERTS * s, FACES)
        assert torch.equal(g.lengths, base.lengths * s)
        if abs(k) < 150:
            assert torch.equal(g.double_area, base.double_area * s * s)
            assert torch.equal(g.dots, base.dots * s * s)


@pytest.mark.parametrize(
    "dtype, s, kind",
    [(torch.float64, 1e160, "overflow"), (torch.float64, 1e-160, "underflow")]
    + [(torch.float32, 1e20, "overflow"), (torch.float32, 1e-20, "underflow")],
)
def test_unrepresentable_scale_raises_naming_it(dtype, s, kind):
    with pytest.raises(ValueError, match=rf"edge lengths of about .*e[+-]\d+ are out of the range.*{kind}"):
        ev.EdgeOperators((VERTS * s).to(dtype), FACES, n=1)


def test_degenerate_faces_found_at_any_scale():
    v = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]], dtype=torch.float64)
    f = torch.tensor([[0, 1, 2], [0, 3, 1]])  # the second face is flat (collinear corners)
    for s in (1e-120, 1.0, 1e120):
        with pytest.raises(ValueError, match=r"zero-area \(degenerate\) faces at faces \[1\]"):
            face_geometry(v * s, f)


def test_from_lengths_scale_covariant():
    base = face_geometry(VERTS, FACES)
    for s in (1e-100, 1e100):
        g = FaceGeometry.from_lengths(base.lengths * s)
        ref = FaceGeometry.from_lengths(base.lengths)
        torch.testing.assert_close(g.double_area / (s * s), ref.double_area, rtol=1e-13, atol=0)
        torch.testing.assert_close(g.dots / (s * s), ref.dots, rtol=1e-13, atol=0)
    with pytest.raises(ValueError, match="overflow"):
        FaceGeometry.from_lengths(base.lengths * 1e160)


def test_gradients_at_large_and_small_scales():
    for s in (1e-100, 1e100):
        v = (VERTS * s).requires_grad_()
        area = face_geometry(v, FACES).double_area.sum()
        (g,) = torch.autograd.grad(area, v)
        v0 = VERTS.clone().requires_grad_()
        (g0,) = torch.autograd.grad(face_geometry(v0, FACES).double_area.sum(), v0)
        torch.testing.assert_close(g / s, g0, rtol=1e-12, atol=1e-14)


def test_info_reports_operators_out_of_range(tmp_path, capsys):
    from torch_edgevf.cli import main
    from torch_edgevf.mesh.diagnose import diagnose

    assert diagnose(VERTS * 1e100, FACES).ok
    assert "out of the range" in " ".join(diagnose(VERTS * 1e160, FACES).problems)
    path = tmp_path / "huge.obj"
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in (VERTS * 1e160).tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in FACES.tolist()]
    path.write_text("\n".join(lines) + "\n")
    main(["info", str(path)])
    out = capsys.readouterr().out
    assert "no problems found" not in out
    assert "out of the range of torch.float64" in out
