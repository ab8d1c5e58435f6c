"""Boundary labels of the integer-grid map: stairs and ears (torch_edgevf.quad.corners)."""

import numpy as np

from torch_edgevf.quad.corners import boundary_loops, relabel_loops


def test_boundary_loops_follow_the_edges():
    a = np.array([0, 1, 2, 5, 6, 7, 8])
    b = np.array([1, 2, 0, 6, 7, 8, 5])
    loops = boundary_loops(a, b)
    assert sorted(len(x) for x in loops) == [3, 4]
    for loop in loops:
        assert np.array_equal(b[loop], a[np.roll(loop, -1)])


def test_a_short_stair_is_turned_away():
    # four convex corners two quads apart, and a concave and a convex corner 0.1 apart
    n0 = np.array([1, 2, 1, 2, 1, 3, 1, 1])
    length = np.array([2, 2, 2, 2, 2, 0.1, 2, 2])
    fan = np.full(8, 3)
    delta, turns = relabel_loops([np.arange(8)], n0, length, np.zeros(8), fan)
    assert turns.tolist() == [1, 2, 1, 2, 1, 2, 2, 1]
    assert np.abs(delta).sum() == 1 and delta[5] != 0
    assert turns.sum() == n0.sum()


def test_the_tip_of_an_ear_gets_one_quarter_turn():
    # vertex 2 has one triangle: its angle in the map must be below two quarter turns
    n0 = np.array([1, 1, 2, 2, 1, 1, 2, 2])
    length = np.full(8, 2.0)
    fan = np.array([3, 3, 1, 3, 3, 3, 3, 3])
    _, turns = relabel_loops([np.arange(8)], n0, length, np.zeros(8), fan)
    assert turns[2] == 1 and (turns >= 1).all() and turns.sum() == n0.sum()
    # with enough triangles nothing changes
    delta, turns = relabel_loops([np.arange(8)], n0, length, np.zeros(8), np.full(8, 3))
    assert not delta.any() and np.array_equal(turns, n0)
