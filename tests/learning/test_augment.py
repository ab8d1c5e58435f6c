"""torch_edgevf.learning.augment: random stretches and smooth warps."""

import doctest

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.learning import augment
from torch_edgevf.learning.augment import random_stretch, random_warp


def _pair_distances(v):
    v = np.asarray(v, dtype=np.float64)
    return np.linalg.norm(v[:, None] - v[None], axis=-1)[np.triu_indices(len(v), 1)]


def test_docstring_example_runs():
    assert doctest.testmod(augment, raise_on_error=True).attempted >= 1


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_torch_in_torch_out_dtype_kept_input_untouched(dtype):
    v, _ = ev.icosphere(2)
    v = (v * torch.tensor([2.0, 1.0, 0.5], dtype=v.dtype) + 3.0).to(dtype)
    before = v.clone()
    w = random_stretch(v, np.random.default_rng(0))
    assert isinstance(w, torch.Tensor) and w.dtype == dtype and w.shape == v.shape
    torch.testing.assert_close(v, before, rtol=0, atol=0)
    assert abs(float(w.norm(dim=1).max()) - 1.0) < 1e-6
    torch.testing.assert_close((w.amax(0) + w.amin(0)) / 2, torch.zeros(3, dtype=dtype), rtol=0, atol=1e-6)


def test_stretch_is_reproducible_non_rigid_and_bounded():
    v = np.random.default_rng(0).standard_normal((40, 3))
    w = random_stretch(v, np.random.default_rng(7), max_factor=1.5, unit_sphere=False)
    np.testing.assert_array_equal(
        w, random_stretch(v, np.random.default_rng(7), max_factor=1.5, unit_sphere=False)
    )
    assert not np.allclose(w, random_stretch(v, np.random.default_rng(8), max_factor=1.5, unit_sphere=False))
    np.testing.assert_allclose(w.mean(0), 0.0, atol=1e-12)  # the centroid stays at the origin
    ratio = _pair_distances(w) / _pair_distances(v)
    assert ratio.min() >= 1 / 1.5 - 1e-12 and ratio.max() <= 1.5 + 1e-12  # singular values of the map
    assert ratio.max() / ratio.min() > 1.05  # not a similarity
    same = random_stretch(v, np.random.default_rng(7), max_factor=1.0, unit_sphere=False)
    np.testing.assert_allclose(_pair_distances(same), _pair_distances(v))  # factor 1: a rigid motion


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(max_factor=0.5), "max_factor must be a finite number >= 1"),
        (dict(max_factor=float("inf")), "max_factor"),
        (dict(rng=0), "rng must be a numpy.random.Generator"),
        (dict(verts=np.zeros((4, 2))), "shape \\(N, 3\\)"),
        (dict(verts=np.array([[0.0, 0, 0], [np.nan, 0, 0]])), "vertex 1"),
    ],
)
def test_bad_arguments_are_named(kwargs, message):
    args = dict(verts=np.eye(3), rng=np.random.default_rng(0), max_factor=1.25)
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        random_stretch(**args)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_warp_torch_in_torch_out_dtype_kept_input_untouched(dtype):
    v, _ = ev.icosphere(2)
    v = (v * 2.0 + 1.0).to(dtype)
    before = v.clone()
    w = random_warp(v, np.random.default_rng(0))
    assert isinstance(w, torch.Tensor) and w.dtype == dtype and w.shape == v.shape
    torch.testing.assert_close(v, before, rtol=0, atol=0)
    assert abs(float(w.norm(dim=1).max()) - 1.0) < 1e-6


@pytest.mark.parametrize("strain", [0.1, 0.3, 0.6])
def test_warp_changes_lengths_within_its_strain_and_differently_from_place_to_place(strain):
    rng = np.random.default_rng(1)
    v = rng.uniform(-1, 1, (300, 3))
    w = random_warp(v, np.random.default_rng(5), strain=strain, unit_sphere=False)
    np.testing.assert_array_equal(
        w, random_warp(v, np.random.default_rng(5), strain=strain, unit_sphere=False)
    )
    # the displacement is strain-Lipschitz: every distance changes by a factor in [1 - s, 1 + s]
    ratio = _pair_distances(w) / _pair_distances(v)
    assert ratio.min() >= 1 - strain - 1e-12 and ratio.max() <= 1 + strain + 1e-12
    assert ratio.max() - ratio.min() > strain / 3  # a real change of proportions
    # not an affine map (which a stretch is): the best affine fit leaves a residual
    a = np.c_[v, np.ones(len(v))]
    residual = w - a @ np.linalg.lstsq(a, w, rcond=None)[0]
    assert np.linalg.norm(residual, axis=1).max() > 0.1 * strain / (2 * np.pi / 2.0)


def test_warp_of_zero_strain_is_the_identity_and_seeds_differ():
    v = np.random.default_rng(2).standard_normal((30, 3))
    np.testing.assert_allclose(random_warp(v, np.random.default_rng(0), strain=0.0, unit_sphere=False), v)
    a = random_warp(v, np.random.default_rng(0), unit_sphere=False)
    assert not np.allclose(a, random_warp(v, np.random.default_rng(1), unit_sphere=False))


def test_warped_mesh_keeps_its_faces_oriented():
    v, f = ev.icosphere(3)
    v, f = v.numpy(), f.numpy()
    w = random_warp(v, np.random.default_rng(3), strain=0.3)
    n0 = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n1 = np.cross(w[f[:, 1]] - w[f[:, 0]], w[f[:, 2]] - w[f[:, 0]])
    cos = (n0 * n1).sum(1) / np.linalg.norm(n0, axis=1) / np.linalg.norm(n1, axis=1)
    assert cos.min() > 0.5


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(strain=1.0), "strain must be a number in \\[0, 1\\)"),
        (dict(strain=-0.1), "strain"),
        (dict(strain=float("nan")), "strain"),
        (dict(waves=0), "waves must be an integer >= 1"),
        (dict(waves=2.0), "waves"),
        (dict(wavelength=0.0), "wavelength must be a finite positive number"),
        (dict(wavelength=float("inf")), "wavelength"),
        (dict(rng=0), "rng must be a numpy.random.Generator"),
        (dict(verts=np.zeros((4, 2))), "shape \\(N, 3\\)"),
        (dict(verts=np.array([[0.0, 0, 0], [0, np.inf, 0]])), "vertex 1"),
    ],
)
def test_warp_bad_arguments_are_named(kwargs, message):
    args = dict(verts=np.eye(3), rng=np.random.default_rng(0))
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        random_warp(**args)
