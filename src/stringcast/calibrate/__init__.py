"""Camera calibration: intrinsics from a ChArUco clip, the board's pose in the trial's video
(pixel <-> swing-plane homography), and the still-arm check of the board-to-robot transform
(the paper's Fig. 2, 'camera calibration').
"""
from .board_check import check_board_to_robot
from .calibration import Calibration, run_calibration

__all__ = ["Calibration", "check_board_to_robot", "run_calibration"]
