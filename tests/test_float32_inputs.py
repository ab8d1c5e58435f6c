"""Single-precision inputs: results in the input's precision, no warnings that only rounding causes."""

import logging

import torch

import torch_edgevf as ev


def test_curvature_aligned_field_in_float32_logs_no_indefinite_warning(caplog):
    """L_c is positive definite on Spot; complex64 pivots are real only to float32 rounding."""
    mesh = ev.default_mesh(dtype=torch.float32)
    with caplog.at_level(logging.WARNING, logger="torch_edgevf"):
        z = ev.curvature_aligned_field(mesh.verts, mesh.faces, n=4)
    assert z.dtype == torch.complex64 and torch.isfinite(z).all()
    assert not [r for r in caplog.records if "indefinite" in r.getMessage()], caplog.text
    # a truly indefinite system still warns (lam far above the first eigenvalue)
    with caplog.at_level(logging.WARNING, logger="torch_edgevf"):
        ev.FieldDesigner(mesh.verts, mesh.faces, 4).aligned(z, lam=200.0)
    assert any("indefinite" in r.getMessage() for r in caplog.records)


def test_parametrize_follows_the_input_dtype():
    v, f = ev.icosphere(2)
    z = ev.smoothest_field(v, f, 4)
    double = ev.parametrize(v, f, z)
    single = ev.parametrize(v.float(), f, z.to(torch.complex64))
    assert double.uv.dtype == double.verts.dtype == torch.float64 and double.z.dtype == torch.complex128
    assert single.uv.dtype == single.verts.dtype == single.translations.dtype == torch.float32
    assert single.z.dtype == torch.complex64
    assert single.uv.shape == double.uv.shape
    # solved in float64 either way: the single-precision result is the rounded double one
    # up to what the float32 input changes
    assert (single.uv.double() - double.uv).abs().max() < 1e-3 * double.uv.abs().max()
