import numpy as np
import pytest

from stringcast.estimate.evaluation import evaluation_value, per_point_errors
from stringcast.estimate import evaluation as ev


def _tracks(F=30, n=6, seed=0):
    rng = np.random.default_rng(seed)
    tracked = rng.normal(0.0, 0.2, (F, n, 2))
    valid = np.ones((F, n), bool)
    return tracked, valid


def test_identical_paths_give_zero():
    tracked, valid = _tracks()
    assert evaluation_value(tracked, valid, tracked.copy(), w=0.1) == 0.0
    assert np.all(per_point_errors(tracked, valid, tracked) == 0.0)


@pytest.mark.parametrize("w", [0.0, 0.1, 0.5])
def test_constant_offset_gives_known_value(w):
    tracked, valid = _tracks(n=7)
    d = 0.013
    shift = d * np.array([0.6, -0.8])                     # |shift| = d
    sim = tracked + shift
    n = tracked.shape[1]
    expected = d * sum(1 + w * (i - 1) for i in range(1, n + 1)) / n
    assert evaluation_value(tracked, valid, sim, w) == pytest.approx(expected, rel=1e-12)
    assert per_point_errors(tracked, valid, sim) == pytest.approx(np.full(n, d), rel=1e-12)


def test_distance_uses_x_minus_x_and_y_minus_y():
    # one point, one frame: offset (3, 4) mm -> 5 mm (not a mix of x and y)
    tracked = np.array([[[0.1, 0.2]]])
    sim = tracked + [[[0.003, 0.004]]]
    assert evaluation_value(tracked, np.ones((1, 1), bool), sim, 0.1) == pytest.approx(0.005)


def test_invalid_entries_are_ignored():
    tracked, valid = _tracks(F=20, n=5)
    sim = tracked + [0.0, 0.01]
    valid[3, 2] = valid[7, 4] = valid[0, 0] = False
    tracked_bad = tracked.copy()
    tracked_bad[~valid] = np.nan                          # garbage where invalid
    sim_bad = sim.copy()
    sim_bad[~valid] = 1e6
    assert evaluation_value(tracked_bad, valid, sim_bad, 0.1) == pytest.approx(
        evaluation_value(tracked, np.ones_like(valid), sim, 0.1))
    # the mean is over the valid frames only: a big error at an invalid frame changes nothing
    e_i = per_point_errors(tracked_bad, valid, sim_bad)
    assert e_i == pytest.approx(np.full(5, 0.01))


def test_point_without_data_left_out_of_sum_and_n():
    tracked, valid = _tracks(F=10, n=4)
    sim = tracked + [0.02, 0.0]
    valid[:, 1] = False                                   # point 2 never tracked
    sim[:, 1] = np.nan
    w = 0.2
    expected = 0.02 * ((1 + 0 * w) + (1 + 2 * w) + (1 + 3 * w)) / 3
    assert evaluation_value(tracked, valid, sim, w) == pytest.approx(expected)
    e_i = per_point_errors(tracked, valid, sim)
    assert np.isnan(e_i[1]) and e_i[[0, 2, 3]] == pytest.approx([0.02] * 3)


def test_tip_errors_weigh_more():
    tracked, valid = _tracks(n=8)
    near, far = tracked.copy(), tracked.copy()
    near[:, 0] += [0.01, 0.0]                             # error at point 1
    far[:, -1] += [0.01, 0.0]                             # the same error at the tip
    e_near = evaluation_value(tracked, valid, near, 0.1)
    e_far = evaluation_value(tracked, valid, far, 0.1)
    assert e_far > e_near > 0
    assert e_far / e_near == pytest.approx(1 + 0.1 * 7)
    assert evaluation_value(tracked, valid, far, 0.0) == pytest.approx(e_near)


def test_batch_and_non_finite_candidate():
    tracked, valid = _tracks(n=5)
    sims = np.stack([tracked + [0.0, 0.01], tracked + [0.02, 0.0], tracked.copy()])
    sims[2, 4, 3] = np.nan                                # a blown-up candidate
    E = evaluation_value(tracked, valid, sims, 0.1)
    assert E.shape == (3,)
    assert E[0] == pytest.approx(evaluation_value(tracked, valid, sims[0], 0.1))
    assert E[1] == pytest.approx(2 * E[0])
    assert E[2] == np.inf
    e_i = per_point_errors(tracked, valid, sims)
    assert e_i.shape == (3, 5) and e_i[2, 3] == np.inf and e_i[2, 0] == 0.0
    # a non-finite value at an invalid entry does not matter
    valid[4, 3] = False
    assert np.isfinite(evaluation_value(tracked, valid, sims, 0.1)[2])


def test_bad_inputs_raise():
    tracked, valid = _tracks(n=3)
    with pytest.raises(ValueError, match="simulated"):
        evaluation_value(tracked, valid, tracked[:, :2], 0.1)
    with pytest.raises(ValueError, match="valid"):
        evaluation_value(tracked, valid[:, :2], tracked, 0.1)
    with pytest.raises(ValueError, match="no valid"):
        evaluation_value(tracked, np.zeros_like(valid), tracked, 0.1)
    with pytest.raises(ValueError, match="w must"):
        evaluation_value(tracked, valid, tracked, -1.0)


@pytest.mark.parametrize("n", [1, 2, 7, 10])
def test_kernel_equals_numpy_reference_bit_for_bit(n):
    """The numba E_i kernel is the NumPy reference's result exactly (same sums in the same order),
    with invalid frames, a point with no frame, and a candidate blown up (NaN) at a valid frame."""
    rng = np.random.default_rng(n)
    F, B = 333, 37
    tr = rng.normal(size=(F, n, 2))
    va = rng.random((F, n)) > 0.3
    va[:, n - 1] = False if n > 2 else va[:, n - 1]          # one point with no valid frame
    sim = tr[None] + rng.normal(scale=0.01, size=(B, F, n, 2))
    f_bad = int(np.flatnonzero(va[:, 0])[0])
    sim[5, f_bad, 0, 1] = np.nan
    batch = ev._per_point(tr, va, sim)
    assert np.array_equal(batch, ev._per_point_reference(tr, va, sim), equal_nan=True)
    assert np.isinf(batch[5, 0]) and np.isfinite(batch[4, 0])
    assert np.array_equal(ev._per_point(tr, va, sim[3]), ev._per_point_reference(tr, va, sim[3]), equal_nan=True)
