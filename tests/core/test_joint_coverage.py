"""The joint log's coverage of the video: a log that starts at the motion's start or ends before the
video is taken as the arm still outside it; one that misses part of the motion is refused."""
import numpy as np
import pytest

from stringcast.core import DataError, check_joint_coverage, end_speed_shares, joint_log_span

QD_MAX = np.radians([180.0, 180.0, 180.0])  # rad/s


def _log(rate=500.0, rest_s=0.2, move_s=0.5, after_s=0.2, noise=2e-4, seed=1):
    """A 3-joint log: still, a smooth move (zero speed at both ends, peak ~1.9 rad/s on joint 2), still."""
    t = np.arange(0.0, rest_s + move_s + after_s, 1 / rate)
    s = np.clip((t - rest_s) / move_s, 0, 1)
    ramp = s - np.sin(2 * np.pi * s) / (2 * np.pi)  # a cycloid: speed 0 at both ends
    q = np.outer(ramp, [0.3, 0.6, -0.4]) + np.random.default_rng(seed).normal(0, noise, (len(t), 3))
    return t, q


def test_end_speed_shares_tell_a_still_end_from_a_moving_one():
    t, q = _log()
    first, last = end_speed_shares(t, q, QD_MAX, 0.02)
    assert first < 0.02 and last < 0.02  # still: the noise (2e-4 rad) reads as under 2 % of the limit
    i = np.searchsorted(t, 0.2)  # exactly at the motion's start: still there (a quadratic, not a line)
    assert end_speed_shares(t[i:], q[i:], QD_MAX, 0.02)[0] < 0.05
    i = np.searchsorted(t, 0.45)  # mid motion: 2.4 rad/s on joint 2 at the middle
    first, _ = end_speed_shares(t[i:], q[i:], QD_MAX, 0.02)
    assert first == pytest.approx(0.6 * 2 / 0.5 / QD_MAX[1], rel=0.05)


def test_a_log_starting_at_the_motions_start_is_extended_and_says_so(tmp_path):
    t, q = _log()
    i = np.searchsorted(t, 0.2)
    frames = 0.05 + np.arange(400) / 500.0  # 0.05 .. 0.848 s: 0.15 s before the log's start
    out = check_joint_coverage(t[i:], frames, tmp_path / "joints.csv", q_joints=q[i:], qd_max=QD_MAX)
    assert out["extended"] is True and out["starts_after_video_s"] == pytest.approx(t[i] - 0.05)
    assert out["ends_before_video_s"] == 0.0 and out["first_speed_share"] < 0.05
    j = np.searchsorted(t, 0.75)  # and one that ends after the motion, before the video
    out = check_joint_coverage(t[i:j], frames, tmp_path / "joints.csv", q_joints=q[i:j], qd_max=QD_MAX)
    assert out["extended"] and out["ends_before_video_s"] == pytest.approx(0.848 - t[j - 1])
    covered = check_joint_coverage(t, frames, tmp_path / "joints.csv", q_joints=q, qd_max=QD_MAX)
    assert covered["extended"] is False and covered["starts_after_video_s"] == 0.0


def test_a_log_missing_part_of_the_motion_is_refused_naming_the_file(tmp_path):
    t, q = _log()
    frames = 0.05 + np.arange(400) / 500.0
    p = tmp_path / "joints.csv"
    i = np.searchsorted(t, 0.4)
    with pytest.raises(DataError, match=r"joints.csv: .*0\.3500 s before it have no joint data; the log starts with "
                                        r"the arm moving \(\d+% of its speed limit"):
        check_joint_coverage(t[i:], frames, p, q_joints=q[i:], qd_max=QD_MAX)
    j = np.searchsorted(t, 0.5)
    with pytest.raises(DataError, match=r"joints.csv: .*after it have no joint data; the log ends with the arm moving"):
        check_joint_coverage(t[:j], frames, p, q_joints=q[:j], qd_max=QD_MAX)
    with pytest.raises(DataError, match=r"before it have no joint data$"):  # without the joints: every frame in the log
        check_joint_coverage(t[i:], frames, p)


def test_joint_log_span_opens_when_the_log_was_extended():
    t = np.arange(0.1, 0.9, 0.002)
    assert joint_log_span(t, None) == (t[0], t[-1])
    assert joint_log_span(t, {"extended": False, "starts_after_video_s": 0.0}) == (t[0], t[-1])
    assert joint_log_span(t, {"extended": True, "starts_after_video_s": 0.05}) == (-np.inf, np.inf)
