"""Joint motions (paper Section V): Bezier velocity curves (eq. 1), joint paths, postures."""
import numpy as np
import pytest
from scipy.interpolate import BPoly

from stringcast.plan import motion as mo
from stringcast.core import ConfigError, resolve_campaign


def test_eq1_control_points():
    rng = np.random.default_rng(1)
    T, n, a = 0.9, 6, 40.0
    v = mo.sample_control_points(rng, T, 3, n, a, 200)
    assert v.shape == (200, 3, n)
    assert np.all(v[..., -1] == 0)
    steps = np.diff(np.concatenate([np.zeros((200, 3, 1)), v[..., :-1]], axis=-1), axis=-1)
    assert np.all(np.abs(steps) <= a * T / n + 1e-12)
    assert np.abs(steps).max() > 0.8 * a * T / n  # the whole +-alpha range is used


def test_bezier_matches_scipy_bernstein_and_integrates():
    rng = np.random.default_rng(2)
    cp = rng.normal(size=(3, 6))
    cp[:, -1] = 0
    T = 0.7
    t = np.linspace(0, T, 51)
    v = mo.bezier_velocity(cp, T, t)
    assert v.shape == (51, 3)
    for j in range(3):
        ref = BPoly(np.concatenate([[0.0], cp[j]])[:, None], [0.0, T])(t)
        np.testing.assert_allclose(v[:, j], ref, atol=1e-12)
    assert np.allclose(v[0], 0) and np.allclose(v[-1], 0)
    dq, qd = mo.joint_paths(cp, T, 500.0)
    # the integral of a Bernstein polynomial over [0, T] is T/(N+1) per control point
    np.testing.assert_allclose(dq[-1], T * cp.sum(axis=1) / 7, rtol=1e-4, atol=1e-6)
    assert dq.shape == (round(T * 500) + 1, 3) and np.all(dq[0] == 0)


def test_postures_keep_string_above_floor(campaign):
    rng = np.random.default_rng(3)
    margin = 0.05
    qs = mo.sample_postures(campaign, rng, 20, margin)
    from stringcast.core.arm import forward_kinematics

    pts = forward_kinematics(campaign.arm, qs)
    assert np.all(pts[:, -1, 1] - campaign.string.length >= campaign.arm.floor_y + margin)
    assert np.all((qs >= campaign.arm.q_min) & (qs <= campaign.arm.q_max))
    assert len(np.unique(qs[:, 0])) == 20


def test_no_posture_for_too_long_string(config):
    camp = resolve_campaign({"string": {"length_mm": 4000, "n_points": 10}, "target": 1}, config, "long")
    with pytest.raises(ConfigError, match="floor"):
        mo.sample_postures(camp, np.random.default_rng(0), 4, 0.05)


def test_hanging_string_clear_of_the_arm(config):
    """hang_clearance: the exact segment distance agrees with a dense brute force, and a posture whose
    gripper points up (the string hanging down over the wrist, hidden behind the arm) is refused."""
    from stringcast.core.arm import forward_kinematics
    from stringcast.core import resolve_campaign

    camp = resolve_campaign({"string": 5, "target": 3}, config, "t")
    q = np.random.default_rng(0).uniform(camp.arm.q_min, camp.arm.q_max, (60, 3))
    pts = forward_kinematics(camp.arm, q)
    top, bottom = pts[:, -1] - [0.0, 0.06], pts[:, -1] - [0.0, camp.string.length]
    d = mo._vertical_clearance(top, bottom, pts)
    s = np.linspace(0, 1, 600)[:, None]
    for i in range(len(q)):
        v = top[i] + s * (bottom[i] - top[i])
        brute = min(np.linalg.norm(v[:, None] - (pts[i, k] + s * (pts[i, k + 1] - pts[i, k]))[None], axis=-1).min()
                    for k in range(pts.shape[1] - 1))
        assert d[i] == pytest.approx(brute, abs=1e-3)
    up = np.array([0.6, 0.9, 0.0])      # wrist above the elbow, gripper pointing up and back over the forearm
    down = np.array([0.5, -1.0, -0.3])  # gripper pointing down and out: the string hangs free
    assert mo.postures_ok(camp, up, 0.05) and not mo.postures_ok(camp, up, 0.05, clearance=0.06)
    assert mo.postures_ok(camp, down, 0.05, clearance=0.06)


def test_valid_curves_keep_the_arm_inside_its_limits(campaign):
    """Every kept curve is inside the position, speed and acceleration limits from its posture (checked
    by arm.check_limits, independently of the fast pre-test); curves too fast for the arm are dropped;
    a posture no curve fits from gives nothing."""
    from stringcast.core.arm import check_limits

    arm, rate, T = campaign.arm, campaign.arm.controller_rate, 0.6
    rng = np.random.default_rng(4)
    postures = mo.sample_postures(campaign, rng, 8, 0.05)
    cps = mo.sample_control_points(rng, T, arm.n_joints, 6, 40.0, 200)
    kept = mo.valid_curves(arm, cps, T, rate, postures, rng)
    assert 0 < len(kept) <= 200
    for _cp, q0, q, i in kept:
        np.testing.assert_array_equal(q0, postures[i])
        np.testing.assert_allclose(q[0], q0)
        rep = check_limits(arm, q, 1.0 / rate)
        assert rep.ok and rep.velocity.max() <= 1.0 - mo.LIMIT_MARGIN and rep.acceleration.max() <= 1.0
    _, qd = mo.joint_paths(cps, T, rate)
    too_fast = cps * (2 * np.max(arm.qd_max) / np.abs(qd).max(axis=(1, 2)))[:, None, None]   # peak 2x the limit
    assert mo.valid_curves(arm, too_fast, T, rate, postures, rng) == []
    at_the_limit = np.repeat(arm.q_max[None], 2, axis=0)       # any positive swing leaves the box
    up = np.abs(cps[:20])
    assert mo.valid_curves(arm, up, T, rate, at_the_limit, rng) == []


@pytest.mark.parametrize("shape, T", [((3, 4), 0.3), ((5, 3, 4), 0.51), ((2, 7, 3, 6), 0.77)])
def test_joint_paths_integrate_as_scipys_cumulative_trapezoid_bit_for_bit(shape, T):
    """dq of joint_paths is scipy.integrate.cumulative_trapezoid(qd, t, initial=0) exactly (it is written
    out in NumPy only to keep SciPy's optimizers out of the plan job's imports)."""
    from scipy.integrate import cumulative_trapezoid

    cp = np.random.default_rng(len(shape)).normal(size=shape) * 3
    dq, qd = mo.joint_paths(cp, T, 500.0)
    t, _ = mo.time_grid(T, 500.0)
    assert dq.shape == qd.shape and np.all(dq[..., 0, :] == 0)
    assert np.array_equal(dq, cumulative_trapezoid(qd, t, axis=-2, initial=0.0))
