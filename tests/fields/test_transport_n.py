"""Transport of n-direction fields, its direction and its stability check."""

import functools
import math
import warnings

import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.fields import nth_power
from torch_edgevf.fields.transport import Transporter, TransportGrowthWarning, transport
from torch_edgevf.mesh.topology import Topology

EZ = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)


def killing_sphere(level):
    """Icosphere, edge midpoints on the sphere, and the rotation field ``w = e_z x p``."""
    v, f = ev.icosphere(level)
    topo = Topology(f)
    e = topo.edges
    p = (v[e[:, 0]] + v[e[:, 1]]) / 2
    p = p / p.norm(dim=1, keepdim=True)
    w = ev.edges_from_vectors(v, topo, torch.linalg.cross(EZ.expand_as(p), p))
    return v, topo, p, w


@pytest.mark.parametrize("n, tol", [(1, 0.004), (2, 0.01), (4, 0.04)])
def test_n_field_along_killing_field_turns_by_n_t_cos_theta(n, tol):
    """The representation vector of an n-direction field turns by n t cos(theta) (holonomy)."""
    v, topo, p, w = killing_sphere(3)
    tr = Transporter(v, topo, w, n=n)
    z0 = nth_power(w, n)
    t = 0.5
    with warnings.catch_warnings():
        warnings.simplefilter("error", TransportGrowthWarning)  # stable over this time
        z = tr(z0, t)
    expected = z0 * torch.polar(torch.ones_like(p[:, 2]), n * t * p[:, 2])
    err = float(tr.norm(z - expected) / tr.norm(expected))
    assert err < tol, err  # 0.0017, 0.0052, 0.023 at level 3 (thesis scheme: 0.0021, 0.0067, 0.037)
    assert abs(float(tr.norm(z) / tr.norm(z0)) - 1) < 1e-3
    if n > 1:
        # treated as a vector field (n=1), the n-field's vector is wrong by far
        wrong = transport(v, topo, z0, w, t)
        assert float(tr.norm(wrong - expected) / tr.norm(expected)) > 10 * err


@pytest.mark.parametrize("n", [1, 2, 4])
def test_converges_with_the_mesh(n):
    errs = []
    for level in (2, 3):
        v, topo, p, w = killing_sphere(level)
        tr = Transporter(v, topo, w, n=n)
        z0 = nth_power(w, n)
        z = tr(z0, 0.5)
        expected = z0 * torch.polar(torch.ones_like(p[:, 2]), n * 0.5 * p[:, 2])
        errs.append(float(tr.norm(z - expected) / tr.norm(expected)))
    assert errs[1] < 0.5 * errs[0], errs


def _bump(p, center, width=0.3):
    """A localized tangent field: e_z-projected, concentrated at ``center``."""
    tangent = EZ - p[:, 2:3] * p
    weight = torch.exp(-((p - center) ** 2).sum(1) / width**2)
    return tangent * weight[:, None]


def _centroid(tr, p, z):
    m = tr.mass * z.abs() ** 2
    c = (m[:, None] * p).sum(0) / m.sum()
    return math.atan2(float(c[1]), float(c[0]))


@pytest.mark.parametrize("direction, sign", [("backward", -1), ("forward", 1)])
def test_direction(direction, sign):
    """backward (default): the field moves against w; forward: along w."""
    v, topo, p, w = killing_sphere(3)
    center = torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)
    z0 = ev.edges_from_vectors(v, topo, _bump(p, center))
    tr = Transporter(v, topo, w, direction=direction)
    t = math.pi / 4
    z = tr(z0, t)
    # w = e_z x p turns counter-clockwise about z: following w for t adds t to the longitude
    assert abs(_centroid(tr, p, z) - sign * t) < 0.05, _centroid(tr, p, z)
    if direction == "backward":
        assert torch.allclose(z, transport(v, topo, z0, w, t))
    else:
        back = Transporter(v, topo, w)
        assert torch.allclose(z, back(z0, -t))


@functools.cache
def full_turn(level, n, scheme="upwind", growth_tol=0.05):
    """Relative M_z error against z0 exp(i n 2 pi cos theta) and M_z-norm ratio after one
    full turn (t = 2 pi) of z0 = w^n along the rotation w = e_z x p."""
    v, topo, p, w = killing_sphere(level)
    tr = Transporter(v, topo, w, n=n, scheme=scheme, growth_tol=growth_tol)
    z0 = nth_power(w, n)
    z = tr(z0, 2 * math.pi)
    expected = z0 * torch.polar(torch.ones_like(p[:, 2]), n * 2 * math.pi * p[:, 2])
    return float(tr.norm(z - expected) / tr.norm(expected)), float(tr.norm(z) / tr.norm(z0))


@pytest.mark.parametrize("n", [1, 2, 4])
def test_full_turn_keeps_the_field_at_level_4(n):
    """The issue's criterion at icosphere 5 (norm within 5%, error <= 0.1), scaled to level 4
    with the required order 1: norm within 10%, error <= 0.2.  Measured at level 4: errors
    0.009 / 0.036 / 0.18, norms 1.000 / 0.999 / 0.944 (the thesis scheme: norms 1.33 / 3.3 /
    9.8, errors 0.92 / 3.2 / 9.8)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", TransportGrowthWarning)
        err, norm = full_turn(4, n)
    assert err < 0.2, err
    assert 0.9 < norm <= 1 + 1e-9, norm


def test_full_turn_converges_at_second_order():
    """From level 3 to 4 the full-turn error falls about 4x (n = 1, 2; n = 4 is unresolved at
    level 3: its wavelength at the end is about two edges)."""
    for n in (1, 2):
        coarse, _ = full_turn(3, n)
        fine, _ = full_turn(4, n)
        assert math.log2(coarse / fine) > 1.5, (n, coarse, fine)  # orders 2.0, 2.2


def test_thesis_scheme_blows_up_over_a_full_turn_and_warns_with_a_suggested_smoothing():
    """One full turn (the flow returns to the identity): the thesis scheme is unstable."""
    v, topo, p, w = killing_sphere(3)
    z0 = nth_power(w, 4)
    with pytest.warns(
        TransportGrowthWarning, match=r"M_z-norm of the field grew by .*pass smoothing=0.00025 with steps=9"
    ):
        transport(v, topo, z0, w, 2 * math.pi, n=4, scheme="thesis")  # the norm grows about 3x
    with warnings.catch_warnings():
        warnings.simplefilter("error", TransportGrowthWarning)
        transport(v, topo, z0, w, 2 * math.pi, n=4, growth_tol=None, scheme="thesis")
    for n in (2, 4):
        err, norm = full_turn(3, n, scheme="thesis", growth_tol=None)
        assert norm > 1.05 and err > 0.5, (n, norm, err)


@pytest.mark.parametrize("bad", [0, -1, 1.5, "2", True])
def test_invalid_n_raises(bad):
    v, topo, p, w = killing_sphere(1)
    with pytest.raises(ValueError, match="n must be an integer >= 1"):
        Transporter(v, topo, w, n=bad)


def test_invalid_direction_and_growth_tol_raise():
    v, topo, p, w = killing_sphere(1)
    with pytest.raises(ValueError, match="direction"):
        Transporter(v, topo, w, direction="along")
    with pytest.raises(ValueError, match="growth_tol"):
        Transporter(v, topo, w, growth_tol=-1.0)


def test_covariant_derivative_n_uses_r_to_the_n():
    v, topo, p, w = killing_sphere(2)
    D1 = ev.covariant_derivative(v, topo, w).coalesce()
    assert torch.equal(ev.covariant_derivative(v, topo, w, 1).coalesce().values(), D1.values())
    D2 = ev.covariant_derivative(v, topo, w, 2).coalesce()
    assert torch.equal(D2.indices(), D1.indices())
    # same magnitudes (|r| = 1), other phases
    torch.testing.assert_close(D2.values().abs(), D1.values().abs())
    assert not torch.allclose(D2.values(), D1.values())
