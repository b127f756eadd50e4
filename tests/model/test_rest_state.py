"""The estimation's initial state: hidden rest points filled with rest-length segments (rest_state.py)."""
import math

import numpy as np
import pytest

from stringcast.model.rest_state import fill_rest_pose, folded_points

L0 = 0.03


def _arc_chain(n, turn, start_dir=-math.pi / 2, grasp=(0.1, 0.5)):
    """(n, 2): points 1..n of a chain of L0 segments from ``grasp``, each turning by ``turn`` rad."""
    angles = start_dir + turn * np.arange(n)
    return np.asarray(grasp) + np.cumsum(L0 * np.column_stack([np.cos(angles), np.sin(angles)]), axis=0)


def _segments(grasp, p):
    return np.linalg.norm(np.diff(np.vstack([grasp, p]), axis=0), axis=1)


@pytest.mark.parametrize("turn", [0.15, -0.3])
def test_hidden_points_below_the_grasp_are_recovered_on_an_arc(turn):
    grasp = np.array([0.1, 0.5])
    truth = _arc_chain(10, turn, start_dir=-0.4, grasp=grasp)
    known = truth.copy()
    known[:3] = np.nan                                   # points 1-3 hidden at rest (by the gripper, say)
    p, filled = fill_rest_pose(grasp, -0.4, known, L0)
    assert filled == (1, 2, 3)
    np.testing.assert_allclose(_segments(grasp, p), L0, rtol=1e-9)   # no segment starts stretched or squeezed
    np.testing.assert_allclose(p, truth, atol=1e-9)     # an arc of equal chords is the fill's own shape
    np.testing.assert_array_equal(p[3:], known[3:])    # tracked points are kept


def test_the_arc_bulges_to_the_side_of_the_hand_direction():
    grasp = np.array([0.0, 0.0])
    known = np.full((4, 2), np.nan)
    known[3] = (0.0, -0.1)                              # 4 segments of 30 mm across a 100 mm chord
    left, _ = fill_rest_pose(grasp, -math.pi / 2 - 0.5, known, L0)
    right, _ = fill_rest_pose(grasp, -math.pi / 2 + 0.5, known, L0)
    assert np.all(left[:3, 0] < 0) and np.all(right[:3, 0] > 0)
    np.testing.assert_allclose(left[:, 0], -right[:, 0], atol=1e-12)
    for p in (left, right):
        np.testing.assert_allclose(_segments(grasp, p), L0, rtol=1e-9)


def test_a_stretched_gap_is_filled_on_the_line_and_a_hidden_tail_hangs_down():
    grasp = np.array([0.0, 0.0])
    known = np.full((5, 2), np.nan)
    known[2] = (0.0, -0.095)                           # 3 segments across 95 mm > 3 l0: evenly on the line
    p, filled = fill_rest_pose(grasp, 0.0, known, L0)
    assert filled == (1, 2, 4, 5)
    np.testing.assert_allclose(p[:2], [[0, -0.095 / 3], [0, -0.19 / 3]], atol=1e-12)
    np.testing.assert_allclose(p[3:], [[0, -0.095 - L0], [0, -0.095 - 2 * L0]], atol=1e-12)


def test_nothing_hidden_changes_nothing_and_bad_shapes_are_refused():
    grasp = np.array([0.1, 0.5])
    truth = _arc_chain(6, 0.2, grasp=grasp)
    p, filled = fill_rest_pose(grasp, 0.0, truth, L0)
    assert filled == () and np.array_equal(p, truth)
    with pytest.raises(ValueError, match="known"):
        fill_rest_pose(grasp, 0.0, truth[:, :1], L0)
    with pytest.raises(ValueError, match="l0"):
        fill_rest_pose(grasp, 0.0, truth, 0.0)


def test_a_point_folded_within_its_segment_is_named_and_the_next_measured_from_the_point_kept():
    """Point 1 sits 10 mm from the grasp (the string folds over inside the gripper's segment): named; point 2,
    two segments below the grasp, is then measured from the grasp and kept; a hidden point is never named."""
    grasp = np.array([0.1, 0.5])
    known = _arc_chain(6, 0.0, grasp=grasp)
    assert folded_points(grasp, known, L0, 0.9) == ()
    known[0] = grasp + (0.0, -0.01)
    known[3] = np.nan
    assert folded_points(grasp, known, L0, 0.9) == (1,)
    known[5] = known[4] + (0.005, -0.02)              # 20.6 mm below point 5: folded too, the last point
    assert folded_points(grasp, known, L0, 0.9) == (1, 6)
    assert folded_points(grasp, known, L0, 0.3) == ()
    with pytest.raises(ValueError, match="min_share"):
        folded_points(grasp, known, L0, 1.5)
