"""Cones of a combed cross field: indices, splitting, cancelling dipoles, boundary turns."""

import math

import numpy as np
import pytest
import torch

import torch_edgevf as ev
from torch_edgevf.fields.param import comb, dual_tree
from torch_edgevf.fields.singularities import singularities
from torch_edgevf.mesh.geometry import angle_defects
from torch_edgevf.mesh.topology import Topology
from torch_edgevf.quad.cones import (
    _retarget,
    boundary_axes,
    cancel_dipoles,
    combed_field,
    split_cones,
)


def combed(v, f, z=None):
    topo = Topology(f, v.shape[0])
    z = ev.smoothest_field(v, f, n=4) if z is None else z
    parent, parent_edge, order, _ = dual_tree(topo)
    field = combed_field(v, topo, comb(v, topo, z).angle)
    return topo, field, (parent, parent_edge, order), z


def test_indices_add_up_to_chi_and_match_the_detection():
    v, f = ev.meshes.ellipsoid((1.0, 0.8, 0.6), level=3)
    topo, field, _, z = combed(v, f)
    assert field.index.sum() == 4 * topo.euler_characteristic
    # where the field has only vertex singularities the comb finds the same ones
    s = singularities(v, topo, z, 4)
    if s.singular_faces.numel() == 0:
        assert np.array_equal(field.index, s.vertex_winding.numpy())
    # holonomy of the matchings around each vertex is -4 I (mod 4)
    edges = topo.edges.numpy()
    hol = np.zeros(topo.num_vertices, dtype=np.int64)
    np.add.at(hol, edges[:, 1], field.matching)
    np.add.at(hol, edges[:, 0], -field.matching)
    assert np.all((hol + field.index) % 4 == 0)
    assert np.abs(field.rotation).max() <= math.pi / 4 + 1e-12


@pytest.mark.slow  # the capsule of tests/quad/test_quad_mesh.py checks the split in the default lane
def test_split_cones_turns_index_one_into_four_quarters():
    import trimesh

    m = trimesh.creation.capsule(height=1.2, radius=0.5, count=[14, 14])
    v, f = torch.tensor(m.vertices), torch.tensor(m.faces, dtype=torch.int64)
    topo, field, tree, _ = combed(v, f)
    assert sorted(field.index[field.index != 0].tolist()) == [4, 4]  # the two poles
    out = split_cones(v, topo, field, tree)
    assert sorted(out.index[out.index != 0].tolist()) == [1] * 8
    poles = np.flatnonzero(field.index == 4)
    assert not out.index[poles].any()
    # the edges of the tree keep matching 0; the rotations changed near the poles only
    parent, parent_edge, _ = tree
    assert not out.matching[parent_edge[parent >= 0]].any()
    changed = np.flatnonzero(np.abs(out.rotation - field.rotation) > 1e-12)
    far = np.linalg.norm(
        v.numpy()[topo.edges.numpy()[changed]].mean(1)[:, None] - v.numpy()[poles][None], axis=2
    )
    assert far.min(1).max() < 0.6


def test_cancel_dipoles_removes_close_opposite_pairs_only():
    v, f = ev.meshes.ellipsoid((1.0, 0.8, 0.6), level=3)
    topo, field, tree, _ = combed(v, f)
    # make a dipole: +1/4 and -1/4 at two neighbouring regular vertices far from the cones
    edges = topo.edges.numpy()
    cones = np.flatnonzero(field.index)
    pos = v.numpy()
    dist = np.linalg.norm(pos[edges[:, 0], None] - pos[cones][None], axis=2).min(1)
    e = int(np.argmax(dist))
    a, b = edges[e]
    target = field.index.copy()
    target[a], target[b] = 1, -1
    rotation = field.rotation.copy()
    inside = np.zeros(topo.num_vertices, dtype=bool)
    inside[[a, b]] = True
    _retarget(topo, angle_defects(v, topo).numpy(), rotation, inside, target)
    from torch_edgevf.quad.cones import _with_rotation

    with_dipole = _with_rotation(v, topo, field, rotation, tree)
    assert with_dipole.index[a] == 1 and with_dipole.index[b] == -1
    h = float(np.linalg.norm(pos[a] - pos[b]))
    kept = cancel_dipoles(v, topo, with_dipole, tree, 0.5 * h)  # too short a distance: kept
    assert np.array_equal(kept.index, with_dipole.index)
    out = cancel_dipoles(v, topo, with_dipole, tree, 1.5 * h)
    assert np.array_equal(out.index, field.index)  # the dipole gone, the original cones kept


def test_boundary_turns_of_a_square_and_gauss_bonnet():
    v, f = ev.meshes.grid(8, 6)
    v = v.clone()
    v[:, 2] = 0.05 * torch.sin(4 * v[:, 0])
    topo = Topology(f, v.shape[0])
    bnd = torch.nonzero(topo.boundary_edges).flatten()
    from torch_edgevf.fields.design import FieldDesigner

    z = FieldDesigner(v, topo, 4).constrained(
        direction_edges=bnd, directions=torch.ones(bnd.numel(), dtype=torch.complex128)
    )
    _, field, _, _ = combed(v, f, z)
    axes = boundary_axes(v, topo, field)
    bv = topo.boundary_vertices.numpy()
    turns = axes.turns[bv]
    corners = np.flatnonzero(bv & (axes.turns != 2))
    assert sorted(turns.tolist()).count(1) == 4 and set(turns.tolist()) == {1, 2}
    xy = v.numpy()[corners, :2]
    assert np.allclose(np.sort(np.round(xy, 9), axis=0), [[0, 0], [0, 0], [1, 1], [1, 1]])
    interior = ~bv
    total = field.index[interior].sum() + (2 - axes.turns[bv]).sum()
    assert total == 4 * topo.euler_characteristic
    # every boundary edge runs along u or v: its label is that of its neighbours on a side
    assert set(axes.axis.tolist()) == {0, 1}


@pytest.mark.parametrize("seed", [0, 1])
def test_retarget_changes_only_what_it_is_asked(seed):
    v, f = ev.meshes.ellipsoid((1.0, 0.8, 0.6), level=2)
    topo, field, tree, _ = combed(v, f)
    from torch_edgevf.quad.cones import _rings

    rng = np.random.default_rng(seed)
    a = int(rng.choice(np.flatnonzero(field.index == 0)))
    ring = _rings(topo, a, 2)
    b = int(rng.choice(np.flatnonzero((ring == 2) & (field.index == 0))))
    vs = np.array([a, b])
    target = field.index.copy()
    target[vs[0]], target[vs[1]] = 1, -1
    rotation = field.rotation.copy()
    inside = np.zeros(topo.num_vertices, dtype=bool)
    inside[vs] = True
    ring = topo.edges.numpy()
    touching = np.isin(ring, vs).any(1)
    inside[ring[touching].ravel()] = True
    _retarget(topo, angle_defects(v, topo).numpy(), rotation, inside, target)
    from torch_edgevf.quad.cones import _indices

    assert np.array_equal(_indices(v, topo, rotation), target)


def test_split_cones_keeps_the_directions_outside_the_split():
    # the trimesh capsule's faces start at a pole: the root of the dual tree is where the
    # rotations change, and its kept angle must not turn the field elsewhere
    import trimesh

    m = trimesh.creation.capsule(height=1.2, radius=0.5, count=[14, 14])
    v, f = torch.tensor(m.vertices), torch.tensor(m.faces, dtype=torch.int64)
    topo, field, tree, _ = combed(v, f)
    out = split_cones(v, topo, field, tree)
    same = (out.rotation == field.rotation)[topo.face_edges.numpy()].all(1)
    assert same.sum() > 0.5 * topo.num_faces
    turn = np.angle(np.exp(4j * (out.angle - field.angle))) / 4
    assert np.abs(turn[same]).max() < 1e-9
