"""Why the ChArUco board was not found: what the images show instead (a hint for the error message).

When no view of the board is found (the campaign's ``calib/`` views, or a trial's first frames),
"found in 0 views" leaves the user to guess among a wrong dictionary, a wrong layout or no board
at all. :func:`board_hint` looks at a few of the images once more (only then: it costs a few
detections per image):

* the ArUco markers of the configured dictionary (``cv2.aruco.ArucoDetector``): where at least
  :data:`MIN_MARKERS` are found but no chessboard corners are interpolated between them, the
  board's layout is not the configured one: its markers' ids beyond the configured board's
  (``squares_x * squares_y / 2`` markers) say it has more squares; otherwise the squares' count or
  order, or the legacy pattern (OpenCV's boards before 4.6 with an even row count), is off;
* otherwise, in the first image, the markers of each predefined family (``DICT_4X4_250`` ...
  ``DICT_7X7_250``, the original ArUco and the AprilTag dictionaries; OpenCV's smaller predefined
  dictionaries are the first 50 or 100 markers of the 250-marker ones; the 1000-marker ones, which
  take 0.5-1 s an image to match, are not tried): the family with the most markers, at least
  :data:`MIN_MARKERS` and more than the configured dictionary's, and the smallest of its
  dictionaries that holds every id seen, is what the board looks like.

Nothing is said where neither is seen (no board in view, or too small or blurred to decode).
"""
from __future__ import annotations

from collections.abc import Iterable

import cv2
import numpy as np

MIN_MARKERS = 4
"""Markers an image must show before a dictionary or a layout is named (one or two can be chance)."""
FAMILIES = ("DICT_4X4_250", "DICT_5X5_250", "DICT_6X6_250", "DICT_7X7_250", "DICT_ARUCO_ORIGINAL",
            "DICT_APRILTAG_16h5", "DICT_APRILTAG_25h9", "DICT_APRILTAG_36h11", "DICT_ARUCO_MIP_36h12")
"""The predefined dictionaries tried, one per family (the 250-marker ones hold the 50- and 100-marker ones)."""


def _markers(image: np.ndarray, dictionary) -> np.ndarray:
    """The ids (K,) of the ArUco markers of ``dictionary`` in a grey uint8 image; the inverted image
    is searched too where the plain one shows fewer than :data:`MIN_MARKERS` (a white-on-black board)."""
    det = cv2.aruco.ArucoDetector(dictionary, cv2.aruco.DetectorParameters())
    best = np.zeros(0, int)
    for img in (image, 255 - image):
        _, ids, _ = det.detectMarkers(img)
        if ids is not None and len(ids) > len(best):
            best = ids.ravel().astype(int)
        if len(best) >= MIN_MARKERS:
            break
    return best


def _smallest(family: str, ids: np.ndarray) -> str:
    """The smallest predefined dictionary of a ``DICT_<n>X<n>_250`` family holding every id, or the family."""
    if not family.endswith("_250"):
        return family
    top = int(ids.max()) if len(ids) else 0
    return family.replace("_250", f"_{next(size for size in (50, 100, 250) if top < size)}")


def _grey8(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim == 3:
        img = img[..., 0] if img.shape[2] == 1 else cv2.cvtColor(img[..., :3], cv2.COLOR_BGR2GRAY)
    if img.dtype != np.uint8:
        img = cv2.convertScaleAbs(img, alpha=255.0 / max(1.0, float(np.nanmax(img))))
    return img


def _board_key(key: str) -> str:
    return f"board.{key}"


def board_hint(images: Iterable[np.ndarray], board, dictionary: str | None = None, setting=_board_key) -> str:
    """What a few images where the board was not found show instead, for an error message ("" if nothing).

    Args:
        images: a few (H, W) grey images (any dtype) where no board was found.
        board: the configured ``cv2.aruco.CharucoBoard``. dictionary: its dictionary's name (for the
            message). setting: ``key -> str``, where the board's ``key`` is configured
            (``setups.<s>.board.<key>``: :meth:`~stringcast.core.specs.Campaign.setup_setting`), named in the hint.

    Returns:
        One sentence naming what was seen and the setting to check, or "".
    """
    images = [_grey8(im) for im in images]
    if not images:
        return ""
    sx, sy = board.getChessboardSize()
    n_board = len(board.getIds())
    own = max((_markers(im, board.getDictionary()) for im in images), key=len)
    if len(own) >= MIN_MARKERS:
        name = dictionary or "the configured dictionary"
        if int(own.max()) >= n_board:
            return (f"{len(own)} markers of {name} are seen, with ids up to {int(own.max())}, but a {sx} x {sy} board "
                    f"has ids 0-{n_board - 1} only: the board has more squares; check {setting('squares_x')} and "
                    f"{setting('squares_y')}")
        return (f"{len(own)} markers of {name} are seen (ids {int(own.min())}-{int(own.max())}) but no chessboard "
                f"corners between them: the layout differs from the configured {sx} x {sy} squares; check "
                f"{setting('squares_x')} and {setting('squares_y')} (their order too) and {setting('legacy_pattern')}")
    best, best_ids = None, np.zeros(0, int)
    for family in FAMILIES:
        ids = _markers(images[0], cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, family)))
        if len(ids) > len(best_ids):
            best, best_ids = family, ids
    if best is None or len(best_ids) < MIN_MARKERS:
        return ""
    looks = _smallest(best, best_ids)
    if dictionary is not None and looks == dictionary:
        return ""
    family = best.removesuffix("_250")
    which = (f"{looks}, or a larger {family} dictionary" if looks != best and looks != family else looks)
    return (f"{len(best_ids)} ArUco markers of the {family} family are seen (ids {int(best_ids.min())}-"
            f"{int(best_ids.max())}), none of {dictionary or 'the configured dictionary'}: the board's dictionary looks "
            f"like {which}; check {setting('dictionary')}")


__all__ = ["board_hint"]
