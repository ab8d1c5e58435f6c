"""The parts the study's networks share (experiments/psb_classification/variants_common.py):
the eigenvalue features of ``spectrum``, against the sphere's analytic spectra."""

import numpy as np
import pytest
import torch
import trimesh

from torch_edgevf.learning import batching, precompute

from conftest import perturbed_icosphere
from study import one_batch, sample, variants_common


@pytest.fixture(scope="module")
def mesh():
    v, f = perturbed_icosphere(2, 0.08, seed=3)
    return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)


@pytest.mark.parametrize("radius", [1.0, 3.7])
def test_spectrum_features_of_the_sphere_are_the_analytic_ones(radius):
    """On the round sphere of any radius the eigenvalues of ``L_c`` (n = 1) are
    ``(l (l + 1) - 1) / r^2``, ``l >= 1``, of complex multiplicity ``2 l + 1``: the
    features are ``log(0.01 + 2 (l (l + 1) - 1) / (i + 1))`` (the area is ``4 pi r^2``).
    Those of the Laplacian are ``l (l + 1) / r^2`` of multiplicity ``2 l + 1``, ``l >= 0``:
    past the constant mode the features are ``log(0.01 + l (l + 1) / i)``."""
    m = trimesh.creation.icosphere(subdivisions=3, radius=radius)
    ops = precompute.compute_operators(np.asarray(m.vertices), np.asarray(m.faces), k_edge=15, k_vertex=16)
    ones = torch.ones(len(m.vertices), 1, dtype=torch.float64)
    batch = batching.collate_meshes([batching.MeshSample(ops, ones, 0)])
    got = variants_common.spectrum_features(batch, 15)
    mu = np.repeat([1.0, 5.0, 11.0], [3, 5, 7])
    assert got.shape == (1, 15) and got.dtype == torch.float64
    np.testing.assert_allclose(got[0].numpy(), np.log(0.01 + 2 * mu / np.arange(1, 16)), atol=0.01)
    got = variants_common.spectrum_features(batch, 15, "laplacian")
    ll = np.repeat([2.0, 6.0, 12.0], [3, 5, 7])
    # the cotangent eigenvalues of this sphere are within 2% of the analytic ones
    np.testing.assert_allclose(got[0].numpy(), np.log(0.01 + ll / np.arange(1, 16)), atol=0.025)
    with pytest.raises(ValueError, match=r"at least 17 eigenpairs of the vertex Laplacian.*k_vertex=17"):
        variants_common.spectrum_features(batch, 16, "laplacian")
    with pytest.raises(ValueError, match="operator must be one of"):
        variants_common.spectrum_features(batch, 4, "hodge")


def test_spectrum_features_are_per_mesh_and_differentiable(mesh):
    """In a batch of two meshes each row is that mesh's own (the same as alone), and
    the features have float64 gradients in the eigenvalues and the masses."""
    v, f = mesh
    v2, f2 = perturbed_icosphere(1, 0.1, seed=9)
    alone = [variants_common.spectrum_features(one_batch(*m), 12) for m in ((v, f), (v2, f2))]
    both = batching.collate_meshes([sample(v, f), sample(v2, f2)])
    torch.testing.assert_close(variants_common.spectrum_features(both, 12), torch.cat(alone))
    evals = both.edge_evals.detach().clone().requires_grad_(True)
    mass = both.vertex_mass.detach().clone().requires_grad_(True)

    def features(e, m):
        both.edge_evals, both.vertex_mass = e, m
        return variants_common.spectrum_features(both, 12)

    assert torch.autograd.gradcheck(features, (evals, mass))


def test_spectrum_features_need_the_eigenpairs(mesh):
    with pytest.raises(ValueError, match="spectrum=17 needs at least 17 eigenpairs of L_c, the batch has 16"):
        variants_common.spectrum_features(one_batch(*mesh), 17)
