"""Transport of n-direction fields, its direction and its stability check."""

import math
import warnings

import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.fields.representation import nth_power
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


@pytest.mark.parametrize("n, tol", [(1, 0.005), (2, 0.012), (4, 0.06)])
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
    assert err < tol, err  # 0.0021, 0.0067, 0.037 at level 3 (about a third per level)
    assert abs(float(tr.norm(z) / tr.norm(z0)) - 1) < 1e-3
    if n > 1:
        # treated as a vector field (n=1), the n-field's vector is wrong by far, and its
        # norm grows: the check warns
        with pytest.warns(TransportGrowthWarning):
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


def test_growth_warns_with_a_suggested_smoothing():
    v, topo, p, w = killing_sphere(3)
    z0 = nth_power(w, 4)
    with pytest.warns(
        TransportGrowthWarning, match=r"M_z-norm of the field grew by .*pass smoothing=0.00025 with steps=9"
    ):
        transport(v, topo, z0, w, 2 * math.pi, n=4)  # one full turn: the norm grows about 3x
    with warnings.catch_warnings():
        warnings.simplefilter("error", TransportGrowthWarning)
        transport(v, topo, z0, w, 2 * math.pi, n=4, growth_tol=None)


def test_full_turn_norm_without_smoothing_is_checked():
    """One full turn (the flow returns to the identity): unstable without regularization."""
    v, topo, p, w = killing_sphere(3)
    for n in (1, 2, 4):
        tr = Transporter(v, topo, w, n=n, growth_tol=None)
        z0 = nth_power(w, n)
        z = tr(z0, 2 * math.pi)
        expected = z0 * torch.polar(torch.ones_like(p[:, 2]), n * 2 * math.pi * p[:, 2])
        err = float(tr.norm(z - expected) / tr.norm(expected))
        growth = float(tr.norm(z) / tr.norm(z0)) - 1
        # the warning's criterion matches the error where it matters (n >= 2 at level 3)
        if n > 1:
            assert growth > 0.05 and err > 0.5, (n, growth, err)


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
