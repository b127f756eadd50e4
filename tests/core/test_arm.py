import numpy as np
import pytest

from stringcast.core.arm import (JointLimitError, assert_within_limits, check_limits, forward_kinematics,
                            hand_pose, motion_start, motion_window)


def test_fk_straight_arm_reaches_along_x(campaign):
    arm = campaign.arm
    pts = forward_kinematics(arm, np.zeros(3))
    assert pts.shape == (5, 2)
    assert pts[-1] == pytest.approx([arm.reach, 0.0])
    assert hand_pose(arm, np.zeros(3)) == pytest.approx([arm.reach, 0, 0])


def test_fk_vertical_and_folded(campaign):
    arm = campaign.arm
    l1, l2, l3 = arm.link_lengths
    p = hand_pose(arm, np.array([np.pi / 2, -np.pi / 2, 0.0]))
    assert p == pytest.approx([l2 + l3 + arm.gripper, l1, 0.0])
    # batched: (K, J) -> (K, 3), and link lengths are preserved for random postures
    q = np.random.default_rng(0).uniform(-2, 2, (50, 3))
    pts = forward_kinematics(arm, q)
    seg = np.linalg.norm(np.diff(pts, axis=1), axis=-1)
    assert seg == pytest.approx(np.tile(np.r_[arm.link_lengths, arm.gripper], (50, 1)))


def test_limits_detect_speed_and_position(campaign):
    arm = campaign.arm
    dt = 1 / arm.controller_rate
    t = np.arange(0, 1, dt)
    slow = np.stack([0.5 + 0.2 * np.sin(2 * np.pi * t)] * 3, axis=1) * [1, -1, 0.5] + [0.5, 0.5, 0]
    assert check_limits(arm, slow, dt).ok
    fast = slow.copy()
    fast[:, 1] = 0.5 + 1.0 * np.sin(2 * np.pi * 2 * t)  # 12.6 rad/s > pi
    rep = check_limits(arm, fast, dt)
    assert not rep.ok and "q2 speed" in rep.describe()
    with pytest.raises(JointLimitError, match="motion.csv.*q2 speed"):
        assert_within_limits(arm, fast, dt, "motion.csv")
    out = slow.copy()
    out[:, 0] = 3.0  # above q1's maximum of 150 deg
    assert "q1 goes" in check_limits(arm, out, dt).describe()


def test_motion_start_finds_onset():
    t = np.arange(0, 1, 0.002)
    q = np.zeros((len(t), 3))
    q[t >= 0.3, 0] = 0.5 * (t[t >= 0.3] - 0.3) ** 2 * 20
    q += np.random.default_rng(1).normal(0, 2e-4, q.shape)
    assert motion_start(t, q) == pytest.approx(0.3, abs=0.02)
    with pytest.raises(ValueError, match="never moves"):
        motion_start(t, np.zeros((len(t), 3)))


def test_motion_window_finds_start_and_stop():
    t = np.arange(0, 1, 0.002)
    s = np.clip((t - 0.3) / 0.4, 0, 1)
    q = np.zeros((len(t), 3))
    q[:, 1] = 0.8 * (1 - np.cos(np.pi * s)) / 2  # moves over 0.3 .. 0.7 s
    q += np.random.default_rng(2).normal(0, 2e-4, q.shape)
    t0, t1 = motion_window(t, q)
    assert t0 == pytest.approx(0.3, abs=0.03) and t1 == pytest.approx(0.7, abs=0.03)
    with pytest.raises(ValueError, match="never moves"):
        motion_window(t, np.zeros((len(t), 3)))
