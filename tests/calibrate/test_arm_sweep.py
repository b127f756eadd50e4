"""The arm sweep: the calibration's plane-mapping error seen by the arm's links at several postures."""
import numpy as np
import pytest

from conftest import small_camera_config
from stringcast.calibrate.arm_sweep import sweep_rows
from stringcast.core.files import read_json
from stringcast.core.joint_log import read_joint_table

POSTURES = ([0.3, -1.5, -0.4], [2.0, -1.6, -1.5], [1.2, -0.6, -0.9], [0.6, -2.2, 0.5])


def _bent(truth: dict, D: np.ndarray):
    """The lab camera's own calibration, its plane points moved by the robot-plane homography D."""
    from stringcast.calibrate.calibration import Calibration

    cam = truth["camera"]
    K, dist, R, t = (np.asarray(cam[k], float) for k in ("K", "dist", "R", "tvec"))
    H = D @ np.linalg.inv(K @ np.column_stack([R[:, 0], R[:, 1], t]))
    return Calibration(H / H[2, 2], (int(cam["width_px"]), int(cam["height_px"])), K, dist)


@pytest.fixture(scope="module")
def postures(tmp_path_factory, config):
    """Four 768 x 768 clips of the arm holding still, one per posture: [(rest image, q, truth)], campaign."""
    from stringcast.calibrate.calibration import median_frame
    from stringcast.core import resolve_campaign
    from stringcast_lab import run_trial
    from stringcast.video.container import open_video

    cfg = small_camera_config(config, "sw_small")
    campaign = resolve_campaign({"string": 1, "target": 1}, cfg, "sw")
    rate = campaign.arm.controller_rate
    out = []
    for i, p in enumerate(POSTURES):
        q = np.repeat(np.asarray(p)[None], int(0.08 * rate), 0)
        trial = tmp_path_factory.mktemp(f"sweep_{i}") / "trial_1"
        run_trial(np.arange(len(q)) / rate, q, campaign, cfg, trial, seed=i, motion_start_s=0.06)
        with open_video(trial / "video.mkv") as v:
            rest = median_frame(v, 5)
        t_j, q_log = read_joint_table(trial / "joints.csv")
        out.append((rest, t_j, q_log, read_json(trial / "ground_truth.json")))
    return out, campaign


def _rows(postures, D, settings):
    shots, campaign = postures
    rows = []
    for k, (img, t_j, q_log, truth) in enumerate(shots):
        r = sweep_rows([(0, img)], _bent(truth, D), campaign.arm, np.array([t_j[0]]), t_j, q_log, settings.board_check)
        r[:, 0] = k
        rows.append(r)
    return np.concatenate(rows)


def test_a_bent_mapping_is_measured_row_by_row(postures, settings):
    """A mapping bent by a homography (up to ~6 mm over the arm's reach): each row reads the bend
    along its link's normal, n . e(p), to 0.5 mm (median); the true mapping reads near zero."""
    D = np.array([[1.004, 0.002, 0.003], [-0.001, 0.997, -0.002], [0.003, -0.002, 1.0]])
    rows = _rows(postures, D, settings)
    assert len(np.unique(rows[:, 0])) == len(POSTURES) and np.all(np.abs(rows[:, 6]) < 0.1)   # still (the log's encoder noise)
    p = rows[:, 1:3]
    bent = np.c_[p, np.ones(len(p))] @ D.T
    e_true = bent[:, :2] / bent[:, 2:] - p
    along = np.sum(e_true * rows[:, 3:5], axis=1)
    miss = np.abs(rows[:, 5] - along)
    print(f"rows {len(rows)}: true |e| max {np.abs(e_true).max() * 1000:.1f} mm, rows off by {np.median(miss) * 1000:.2f} "
          f"mm (median), p90 {np.percentile(miss, 90) * 1000:.2f}")
    assert np.max(np.linalg.norm(e_true, axis=1)) > 0.004 and np.ptp(along) > 0.004
    assert np.median(miss) < 0.0005 and np.percentile(miss, 90) < 0.0015
    straight = _rows(postures, np.eye(3), settings)
    assert np.median(np.abs(straight[:, 5])) < 0.0005


def test_point_motions_are_the_reference_point_by_point(config):
    """The rows' velocities: every material point's motion at once equals it point by point, on
    postures of the lab arm and on points near and between its links. A point beyond a joint, on
    the outside of its bend, is equally near both links (the joint is the nearest point of each):
    which one carries it is rounding's choice, so there it must be carried by one of the two."""
    from stringcast.calibrate.arm_sweep import point_motion_reference, point_motions
    from stringcast.core import forward_kinematics, resolve_campaign

    def link_distances(mid, pts):                        # (n, S) distance of each point to each link
        a, ab = mid[:-1], np.diff(mid, axis=0)
        u = np.clip(np.einsum("nsk,sk->ns", pts[:, None] - a, ab) / np.sum(ab * ab, axis=1), 0, 1)
        return np.linalg.norm(pts[:, None] - a - u[..., None] * ab, axis=-1)

    arm = resolve_campaign({"string": 1, "target": 1}, config, "pm").arm
    rng = np.random.default_rng(3)
    tied = 0
    for q in POSTURES:
        q = np.asarray(q)
        mid = forward_kinematics(arm, q)
        ends = tuple(forward_kinematics(arm, q + d) for d in rng.normal(0, 0.02, (2, len(q))))
        s, u = rng.integers(0, len(mid) - 1, 40), rng.uniform(-0.1, 1.1, (40, 1))
        pts = mid[s] + u * (mid[s + 1] - mid[s]) + rng.normal(0, 0.02, (40, 2))
        got = point_motions(mid, ends, pts)
        assert got.shape == (40, 2)
        d = link_distances(mid, pts)
        near = d - d.min(axis=1, keepdims=True) < 1e-9  # the nearest link(s) of each point
        clear = near.sum(axis=1) == 1
        for p, g, links in zip(pts[~clear], got[~clear], near[~clear]):
            carried = [point_motion_reference(mid[k:k + 2], tuple(e[k:k + 2] for e in ends), p)
                       for k in np.flatnonzero(links)]          # p's motion on each of its nearest links
            assert any(np.allclose(g, c, rtol=1e-12, atol=1e-15) for c in carried)
        tied += np.sum(~clear)
        want = np.array([point_motion_reference(mid, ends, p) for p in pts[clear]])
        assert np.abs(want).max() > 1e-4
        np.testing.assert_allclose(got[clear], want, rtol=1e-12, atol=1e-15)
    assert tied > 0                                      # the outside of a bend is exercised
