"""The calibration board's outline in the image: where a skeleton walk's end may not be the string's.

The ChArUco board stands in the swing plane and is seen in every trial. Its squares and its
markers' cells are dark and light, so a string of either shade vanishes against one of them:
a walk that stops over the board may stop where the string crosses a square of its own shade,
not at its tip (generalization seed 10: string 4's end hung over a black square at rest, and
taken as the tip it put points 7-15 105 mm up the string). Over the board an end is therefore
the tip only where the walk's length agrees with L
(:meth:`~stringcast.track.frame_tracker.FrameTracker.track`), and a stretch beyond the arm that
ends there is not taken. The board's pose is known from the calibration (``board_to_robot`` and
the pixel <-> plane mapping), so its outline is drawn from that, not guessed from the image.
"""
from __future__ import annotations

import cv2
import numpy as np

from stringcast.calibrate import Calibration
from stringcast.core import BoardSpec


def board_outline_px(cal: Calibration, board: BoardSpec, per_side: int = 16) -> np.ndarray | None:
    """The board's squares' outline in the image, as a contour for ``cv2.pointPolygonTest``.

    Args:
        cal: the trial's calibration; its ``board_to_robot`` (3, 3) maps board-frame m to the
            robot frame, :meth:`Calibration.robot_to_pixel` maps on into (distorted) image px.
        board: the board's layout (:class:`~stringcast.core.BoardSpec`; ``squares_x`` x
            ``squares_y`` squares of ``square`` m, OpenCV's board frame).
        per_side: points per side (lens distortion bends the sides).

    Returns:
        (4 per_side, 1, 2) float32 contour, image px (x, y); None when the calibration has no
        ``board_to_robot``.
    """
    if cal.board_to_robot is None:
        return None
    w, h = board.squares_x * board.square, board.squares_y * board.square
    u = np.linspace(0.0, 1.0, per_side, endpoint=False)[:, None]
    corners = np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]])
    rim = np.concatenate([c0 + u * (c1 - c0) for c0, c1 in zip(corners, np.roll(corners, -1, axis=0))])
    q = np.column_stack([rim, np.ones(len(rim))]) @ np.asarray(cal.board_to_robot, float).T
    px = cal.robot_to_pixel(q[:, :2] / q[:, 2:])
    return px.astype(np.float32).reshape(-1, 1, 2)


def over_board(outline: np.ndarray | None, xy_px, margin_px: float) -> bool:
    """Whether the image point ``xy_px`` (x, y) lies on the board or within ``margin_px`` of
    its outline (``cv2.pointPolygonTest``, signed distance); False without an outline."""
    if outline is None:
        return False
    return cv2.pointPolygonTest(outline, (float(xy_px[0]), float(xy_px[1])), True) > -margin_px
