"""A board size off by a factor is named: the still arm is found at a scale about the board's origin
(issue 51: square_mm 50 for a 60 mm board left the board check 'not checked', the sweep moved the
mapping by 102 mm with warnings, and tracking crashed). A board pose that is only shifted, or right,
names no scale."""
import dataclasses

import numpy as np
import pytest

from conftest import small_camera_config
from stringcast.calibrate.calibration import Calibration, scale_reason
from stringcast.calibrate.scale_check import arm_scale
from stringcast.core.files import read_json
from stringcast.core.joint_log import read_joint_table


@pytest.fixture(scope="module", params=["reaching", "folded"])
def still_arm(request, tmp_path_factory, config):
    """A 768 x 768 clip of the arm holding still: rest image, the lab camera's own calibration with the
    campaign's board pose, the campaign and the first posture."""
    from stringcast.calibrate.calibration import median_frame
    from stringcast.core import resolve_campaign
    from stringcast_lab import run_trial
    from stringcast.video.container import open_video

    posture = {"reaching": [0.3, -1.5, -0.4], "folded": [2.0, -1.6, -1.5]}[request.param]
    root = tmp_path_factory.mktemp(f"scale_{request.param}")
    cfg = small_camera_config(config, "sc_small")
    campaign = resolve_campaign({"string": 1, "target": 1}, cfg, "sc")
    rate = campaign.arm.controller_rate
    q = np.repeat(np.asarray(posture)[None], int(0.12 * rate), 0)
    run_trial(np.arange(len(q)) / rate, q, campaign, cfg, root / "trial_1", seed=3, motion_start_s=0.1)
    with open_video(root / "trial_1" / "video.mkv") as v:
        rest = median_frame(v, 5)
    cam = read_json(root / "trial_1" / "ground_truth.json")["camera"]
    K, dist, R, t = (np.asarray(cam[k], float) for k in ("K", "dist", "R", "tvec"))
    cal = Calibration(np.linalg.inv(K @ np.column_stack([R[:, 0], R[:, 1], t])), (int(cam["width_px"]),
                      int(cam["height_px"])), K, dist, board_to_robot=campaign.setup.board_to_robot)
    return rest, cal, campaign, read_joint_table(root / "trial_1" / "joints.csv")[1][0]


def _board_scaled(cal: Calibration, k: float) -> Calibration:
    """The calibration a board whose squares are configured k times their size gives: board coordinates
    k times the true ones, through the same board pose B."""
    B = np.asarray(cal.board_to_robot, float)
    return dataclasses.replace(cal, H_pixel_to_robot=B @ np.diag([k, k, 1.0]) @ np.linalg.inv(B) @ cal.H_pixel_to_robot)


@pytest.mark.parametrize("k", [50 / 60, 1.12])
def test_a_board_size_off_by_a_factor_is_found_as_that_scale(still_arm, settings, k):
    rest, cal, campaign, q0 = still_arm
    found = arm_scale(rest, _board_scaled(cal, k), campaign.arm, q0, settings.board_check)
    assert found is not None and found["scale"] == pytest.approx(k, rel=0.01)
    assert found["residual_mm"] <= settings.board_check.warn_mm and found["features"] > found["features_at_1"]
    reason = scale_reason(found, campaign)
    assert "setups.default.board.square_mm" in reason and f"{found['scale']:.3f}" in reason


@pytest.mark.parametrize("shift_m", [(0.0, 0.0), (0.03, -0.02)])
def test_a_right_or_shifted_board_names_no_scale(still_arm, settings, shift_m):
    rest, cal, campaign, q0 = still_arm
    H = cal.H_pixel_to_robot.copy()
    H[:2] += np.outer(shift_m, H[2])
    assert arm_scale(rest, dataclasses.replace(cal, H_pixel_to_robot=H), campaign.arm, q0,
                     settings.board_check) is None
