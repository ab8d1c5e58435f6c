"""torch_edgevf.learning.augment: random stretches."""

import doctest

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.learning import augment
from torch_edgevf.learning.augment import random_stretch


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
