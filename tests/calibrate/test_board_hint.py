"""Where the ChArUco board is not found, the error says what the images show instead: markers of
another dictionary (naming it and setups.<s>.board.dictionary), or the configured markers without
corners between them (the layout: squares_x, squares_y, legacy_pattern). Issue 51: a wrong
dictionary gave "found in 0 views" and no hint."""
import cv2
import numpy as np
import pytest

from stringcast.calibrate.board_hint import board_hint
from stringcast.calibrate.calibration import detect_plane_board
from stringcast.calibrate.charuco import select_calibration_views
from stringcast.core import DataError
from stringcast.core.specs import BoardSpec

PRINTED = BoardSpec(9, 6, 0.06, 0.045, "DICT_5X5_100")    # the board in front of the camera


def _views(n=3, seed=0):
    """n views of the printed board, each a little turned and moved, on a grey wall with noise."""
    img = PRINTED.make().generateImage((330, 220), marginSize=10)
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        a = np.radians(rng.uniform(-8, 8))
        M = np.array([[np.cos(a), -np.sin(a), 40 + 10 * k], [np.sin(a), np.cos(a), 30 + 5 * k]])
        view = cv2.warpAffine(img, M, (420, 300), borderValue=150)
        out.append(np.clip(view + rng.normal(0, 3, view.shape), 0, 255).astype(np.uint8))
    return out


@pytest.mark.parametrize("configured, says", [
    (BoardSpec(9, 6, 0.06, 0.045, "DICT_4X4_50"), "looks like DICT_5X5_50, or a larger DICT_5X5 dictionary; check "
                                                   "setups.default.board.dictionary"),
    (BoardSpec(9, 6, 0.06, 0.045, "DICT_6X6_50"), "check setups.default.board.dictionary"),
    (BoardSpec(8, 6, 0.06, 0.045, "DICT_5X5_100"), "the board has more squares; check setups.default.board.squares_x"),
    (BoardSpec(9, 6, 0.06, 0.045, "DICT_5X5_100", True), "setups.default.board.legacy_pattern"),
    (BoardSpec(6, 9, 0.06, 0.045, "DICT_5X5_100"), "setups.default.board.squares_x and setups.default.board.squares_y "
                                                   "(their order too)"),
])
def test_no_board_found_says_what_the_views_show_instead(configured, says):
    with pytest.raises(DataError, match="found in 0 views") as err:
        select_calibration_views(_views(), configured.make(), "calib", dictionary=configured.dictionary,
                                 setting=lambda key: f"setups.default.board.{key}")
    assert says in str(err.value)
    with pytest.raises(DataError, match="no ChArUco board found") as err:
        detect_plane_board(_views(1)[0], configured.make(), "trial_1/video.mkv")
    assert says.split("setups.default.")[0] in str(err.value)      # the same hint, the setting unnamed


def test_no_hint_without_markers_and_none_for_the_right_board():
    wall = [np.full((400, 500), 150, np.uint8), np.random.default_rng(1).integers(0, 255, (400, 500)).astype(np.uint8)]
    assert board_hint(wall, PRINTED.make(), PRINTED.dictionary) == ""
    assert len(select_calibration_views(_views(), PRINTED.make(), "calib")) == 3
