"""Camera calibration: intrinsics from a ChArUco clip, the board's pose in the trial's video
(pixel <-> swing-plane homography), and the still-arm check of the board-to-robot transform
(the paper's Fig. 2, 'camera calibration'; the clip's views found once per campaign,
:mod:`.calib_views`), and the mapping refined by the arm's sweep of a
trial (its link rows, :mod:`.arm_sweep`; the fit, :mod:`.refine`).
"""
from typing import TYPE_CHECKING

from stringcast.core import lazy_exports

if TYPE_CHECKING:
    from .arm_sweep import sweep_rows
    from .board_check import check_board_to_robot
    from .calib_views import write_calib_views, write_campaign_intrinsics
    from .calibration import run_calibration
    from .mapping import Calibration
    from .refine import PARAMETERS, board_corner_points, mapping_standard_error, refine_mapping

__getattr__, __dir__ = lazy_exports(__name__, {
    "sweep_rows": ".arm_sweep",
    "check_board_to_robot": ".board_check",
    "write_calib_views": ".calib_views",
    "write_campaign_intrinsics": ".calib_views",
    "Calibration": ".mapping",
    "run_calibration": ".calibration",
    "PARAMETERS": ".refine",
    "board_corner_points": ".refine",
    "mapping_standard_error": ".refine",
    "refine_mapping": ".refine",
})

__all__ = ["PARAMETERS", "Calibration", "board_corner_points", "check_board_to_robot", "mapping_standard_error",
           "refine_mapping", "run_calibration", "sweep_rows", "write_calib_views",
           "write_campaign_intrinsics"]
