"""ChArUco detection and camera intrinsics (the calibration stage's first half).

* :func:`detect_charuco`: ``cv2.aruco.CharucoDetector.detectBoard`` on the grey image,
  and on the inverted one for boards printed white-on-black.
* :func:`pose_descriptors` + :func:`select_views`: a clip of a board waved in front of the
  lens holds hundreds of near-identical views; calibration needs *different* ones (board
  near every part of the image, near and far, tilted several ways: Zhang 2000). Each view's
  board-to-image homography gives a pose descriptor without knowing the intrinsics yet, and
  greedy farthest-point sampling in that space keeps at most ``max_views`` of them.
* :func:`select_calibration_views` (``board.matchImagePoints`` on each frame's corners, then
  :func:`select_views`) + :func:`fit_views` (``cv2.calibrateCameraExtended``: OpenCV >= 4.7
  has no Python ``calibrateCameraCharuco``; views whose own reprojection RMS exceeds
  ``max(3 x median, 0.5 px)`` (motion blur, a false corner) are dropped and the calibration
  repeated, at most 3 times) = :func:`calibrate_intrinsics`. The fit keeps what judging it
  needs (:mod:`stringcast.calibrate.quality`): the standard deviations, per-view errors,
  poses and the corners used.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from collections.abc import Iterable

import cv2
import numpy as np

from stringcast.core import DataError
from .board_hint import board_hint

MIN_VIEW_CORNERS = 6
"""ChArUco corners a calibration view needs to be used."""
MAX_VIEWS = 40
"""Views kept for ``cv2.calibrateCamera`` by default (its cost grows with the views)."""


def detect_charuco(image: np.ndarray, board, invert: bool | None = None, upscale: int = 1
                   ) -> tuple[np.ndarray, np.ndarray]:
    """ChArUco chessboard corners in a grey image.

    Args:
        image: (H, W) uint8 or uint16 (scaled to 8 bit) grey image.
        board: ``cv2.aruco.CharucoBoard``.
        invert: True/False forces the polarity; None tries the plain image, then the
            inverted one if the plain one gives fewer than :data:`MIN_VIEW_CORNERS`.
        upscale: detect on the image enlarged this many times (``cv2.INTER_CUBIC``), the
            corners mapped back: a board far away has markers of 2-3 px per bit, too few
            for the ArUco bit sampling at scale 1, yet decodable once enlarged.

    Returns:
        corners (N, 2) float64 px (sub-pixel, distorted image), ids (N,) int; N may be 0.
    """
    img = image if image.dtype == np.uint8 else cv2.convertScaleAbs(image, alpha=255.0 / max(1, int(image.max())))
    if upscale != 1:
        img = cv2.resize(img, None, fx=upscale, fy=upscale, interpolation=cv2.INTER_CUBIC)
    det = cv2.aruco.CharucoDetector(board)
    best = (np.zeros((0, 2)), np.zeros(0, int))
    for inv in ((False, True) if invert is None else (invert,)):
        cc, ci, _, _ = det.detectBoard(255 - img if inv else img)
        if ci is not None and len(ci) > len(best[1]):
            best = (cc.reshape(-1, 2).astype(float), ci.ravel().astype(int))
        if len(best[1]) >= MIN_VIEW_CORNERS:
            break
    if upscale != 1:   # pixel centres: x = (x_up + 0.5) / s - 0.5
        best = ((best[0] + 0.5) / upscale - 0.5, best[1])
    return best


def pose_descriptors(obj: list[np.ndarray], img: list[np.ndarray], board, image_size: tuple[int, int]) -> np.ndarray:
    """One pose descriptor per view, from its board-plane -> pixel homography.

    With H = K [r1 r2 t] (up to scale), the image of the board's centre and its apparent
    size say where and how near the board is; the perspective row H[2, :2] / H[2, 2] times
    the board's size is the depth change across the board relative to its distance, i.e.
    the tilt about the image axes (``cv2.findHomography``, least squares).

    Args:
        obj: per view (N_v, 1, 3) board points, m (z = 0). img: per view (N_v, 1, 2) px.
        board: ``cv2.aruco.CharucoBoard``. image_size: (width, height) px.

    Returns:
        (V, 5): centre u / width, centre v / height, log apparent size, tilt x, tilt y
        (all dimensionless).
    """
    w, h = image_size
    bw, bh = np.asarray(board.getChessboardSize(), float) * board.getSquareLength()
    centre = np.array([[[bw / 2, bh / 2]]])
    quad = np.array([[[0, 0]], [[bw, 0]], [[bw, bh]], [[0, bh]]], float)
    out = np.zeros((len(obj), 5))
    for k, (o, i) in enumerate(zip(obj, img)):
        H, _ = cv2.findHomography(o.reshape(-1, 3)[:, :2].astype(np.float64), i.reshape(-1, 2).astype(np.float64), 0)
        if H is None:
            out[k] = np.nan
            continue
        c = cv2.perspectiveTransform(centre, H).ravel()
        q = cv2.perspectiveTransform(quad, H).reshape(-1, 2)
        area = 0.5 * abs(np.dot(q[:, 0], np.roll(q[:, 1], -1)) - np.dot(q[:, 1], np.roll(q[:, 0], -1)))
        out[k] = [c[0] / w, c[1] / h, 0.5 * np.log(max(area, 1.0) / (w * h)),
                  H[2, 0] / H[2, 2] * bw, H[2, 1] / H[2, 2] * bh]
    return out


def select_views(descriptors: np.ndarray, n_corners: np.ndarray, max_views: int) -> np.ndarray:
    """Indices of at most ``max_views`` views spread over pose space (greedy farthest point).

    Starts from the view with the most corners; each next view is the one farthest (in the
    descriptors standardised by their spread) from all views chosen so far, ties broken by
    corner count. Views with a NaN descriptor are never chosen.

    Args:
        descriptors: (V, D) from :func:`pose_descriptors`. n_corners: (V,) corners per view.
        max_views: at most this many indices are returned.

    Returns:
        (min(V_ok, max_views),) int indices in increasing order.
    """
    d = np.asarray(descriptors, float)
    ok = np.flatnonzero(np.all(np.isfinite(d), axis=1))
    if len(ok) <= max_views:
        return ok
    z = (d[ok] - d[ok].mean(axis=0)) / np.maximum(d[ok].std(axis=0), 1e-9)
    score = np.asarray(n_corners, float)[ok]
    chosen = [int(np.argmax(score))]
    dist = np.linalg.norm(z - z[chosen[0]], axis=1)
    while len(chosen) < max_views:
        nxt = int(np.argmax(dist + 1e-6 * score))
        chosen.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(z - z[nxt], axis=1))
    return np.sort(ok[chosen])


@dataclass(frozen=True)
class Views:
    """Calibration views: the board's points and their detected corners, view by view.

    Attributes:
        object_points: per view (N_v, 1, 3) float32 board points, m (z = 0).
        image_points: per view (N_v, 1, 2) float32 detected corners, px (distorted image).
        image_size: (width, height) px. found: views with the board before any selection.
        names: a name per view (for messages), e.g. ``frame 12``.
    """

    object_points: tuple
    image_points: tuple
    image_size: tuple[int, int]
    found: int = 0
    names: tuple[str, ...] = ()

    def __post_init__(self):
        if len(self.object_points) != len(self.image_points):
            raise ValueError("Views: object_points and image_points must have one entry per view")
        if not self.names:
            object.__setattr__(self, "names", tuple(f"view {k}" for k in range(len(self.object_points))))

    def __len__(self) -> int:
        return len(self.object_points)

    def plus(self, obj: np.ndarray, img: np.ndarray, name: str) -> Views:
        """These views and one more (e.g. the trial's board in the swing plane)."""
        return Views((*self.object_points, np.asarray(obj, np.float32).reshape(-1, 1, 3)),
                     (*self.image_points, np.asarray(img, np.float32).reshape(-1, 1, 2)),
                     self.image_size, self.found + 1, (*self.names, name))


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics with OpenCV's 5-term distortion (k1, k2, p1, p2, k3).

    Attributes:
        K: (3, 3) camera matrix, px. dist: (5,). rms_px: reprojection RMS of the views used.
        n_views: views used. image_size: (width, height) px. views_rejected: views dropped
        as reprojection outliers. views_found: views with the board found (before selection).
        std: (9,) OpenCV's standard deviations of (fx, fy, cx, cy, k1, k2, p1, p2, k3)
            (``cv2.calibrateCameraExtended``, 0 for a held parameter), or None.
        per_view_rms_px: (n_views,) each used view's reprojection RMS, px.
        rvecs, tvecs: (n_views, 3) the used views' board poses (Rodrigues; m), or None.
        views: the :class:`Views` used (after outlier rejection), or None.
        flags: the ``cv2.calibrateCamera`` flags of the fit.
    """

    K: np.ndarray
    dist: np.ndarray
    rms_px: float
    n_views: int
    image_size: tuple[int, int]
    views_rejected: int = 0
    views_found: int = 0
    std: np.ndarray | None = None
    per_view_rms_px: tuple[float, ...] = ()
    rvecs: np.ndarray | None = field(default=None, repr=False)
    tvecs: np.ndarray | None = field(default=None, repr=False)
    views: Views | None = field(default=None, repr=False)
    flags: int = 0

    def __post_init__(self):
        if np.shape(self.K) != (3, 3) or np.shape(self.dist) != (5,):
            raise ValueError(f"Intrinsics: K must be (3, 3) and dist (5,), got {np.shape(self.K)}, {np.shape(self.dist)}")


HINT_FRAMES = (0, 10, 20)
"""The frames (counting those given) kept for :func:`~stringcast.calibrate.board_hint.board_hint` where too
few views are found."""


def select_calibration_views(frames: Iterable[np.ndarray], board, source: str = "calibration frames",
                             invert: bool | None = None, min_views: int = 3, max_views: int = MAX_VIEWS, *,
                             dictionary: str | None = None, setting=None) -> Views:
    """The board's corners in each frame where it shows, at most ``max_views`` views kept.

    Each frame: :func:`detect_charuco`, ``board.matchImagePoints``; a view needs
    :data:`MIN_VIEW_CORNERS` corners, not collinear. Then :func:`select_views` keeps at most
    ``max_views`` spread over pose space.

    Args:
        frames: iterable of (H, W) grey images (all the same size), read once.
        board: ``cv2.aruco.CharucoBoard`` (sizes in m). source: named in errors.
        invert: board polarity (see :func:`detect_charuco`). min_views: the fewest usable views.
        dictionary, setting: the board's dictionary name and ``key -> str``, where the board's ``key`` is
            configured (``setups.<s>.board.<key>``; None: ``board.<key>``), for the hint at what the frames show instead where too few views
            are found (:func:`~stringcast.calibrate.board_hint.board_hint`).

    Returns:
        :class:`Views`, named by frame (``frame k``, k counting the frames given).

    Raises:
        DataError: fewer than ``min_views`` usable views (with the hint), or frames of different sizes.
    """
    obj, img, names, size, unseen = [], [], [], None, []
    for k, frame in enumerate(frames):
        if size is None:
            size = (frame.shape[1], frame.shape[0])
        elif (frame.shape[1], frame.shape[0]) != size:
            raise DataError(f"{source}: frame {k} is {frame.shape[1]}x{frame.shape[0]}, the first was {size[0]}x{size[1]}")
        corners, ids = detect_charuco(frame, board, invert)
        if len(ids) < MIN_VIEW_CORNERS:
            if k in HINT_FRAMES:
                unseen.append(frame)
            continue
        o, i = board.matchImagePoints(corners.astype(np.float32).reshape(-1, 1, 2), ids.reshape(-1, 1))
        if o is None or len(o) < MIN_VIEW_CORNERS or board.checkCharucoCornersCollinear(ids.reshape(-1, 1)):
            continue
        obj.append(o.astype(np.float32))
        img.append(i.astype(np.float32))
        names.append(f"frame {k}")
    if len(obj) < min_views:
        hint = board_hint(unseen, board, dictionary, *(() if setting is None else (setting,))) \
            if len(obj) == 0 or unseen else ""
        raise DataError(f"{source}: the ChArUco board was found in {len(obj)} views with >= {MIN_VIEW_CORNERS} "
                        f"corners; camera calibration needs at least {min_views}" + (f": {hint}" if hint else ""))
    pick = select_views(pose_descriptors(obj, img, board, size), np.array([len(o) for o in obj]), max_views)
    return Views(tuple(obj[k] for k in pick), tuple(img[k] for k in pick), (int(size[0]), int(size[1])),
                 len(obj), tuple(names[k] for k in pick))


def fit_views(views: Views, flags: int = 0, min_views: int = 3) -> Intrinsics:
    """``cv2.calibrateCameraExtended`` on the views, dropping reprojection outliers.

    Views whose own reprojection RMS exceeds ``max(3 x median, 0.5 px)`` (motion blur, a
    false corner) are dropped and the fit repeated (at most 3 times, keeping >= ``min_views``).

    Args:
        views: :class:`Views`. flags: ``cv2.calibrateCamera`` flags (``CALIB_FIX_K3``,
            ``CALIB_FIX_PRINCIPAL_POINT``: held at ((w - 1) / 2, (h - 1) / 2), ...).
        min_views: the fewest views kept.

    Returns:
        :class:`Intrinsics` with the standard deviations, per-view errors, poses and views used.
    """
    obj, img = views.object_points, views.image_points
    keep = np.arange(len(obj))
    for _ in range(4):
        rms, K, dist, rv, tv, std, _, per_view = cv2.calibrateCameraExtended(
            [obj[k] for k in keep], [img[k] for k in keep], views.image_size, None, None, flags=flags)
        per_view = per_view.ravel()
        bad = per_view > max(3.0 * float(np.median(per_view)), 0.5)
        if not bad.any() or len(keep) - bad.sum() < min_views:
            break
        keep = keep[~bad]
    sd = np.asarray(std, float).ravel()
    used = Views(tuple(obj[k] for k in keep), tuple(img[k] for k in keep), views.image_size, views.found,
                 tuple(views.names[k] for k in keep))
    return Intrinsics(np.asarray(K, float), np.asarray(dist, float).ravel()[:5], float(rms), len(keep),
                      views.image_size, len(obj) - len(keep), views.found, np.r_[sd[:8], sd[8:9]],
                      tuple(float(e) for e in per_view), np.asarray(rv, float).reshape(-1, 3),
                      np.asarray(tv, float).reshape(-1, 3), used, int(flags))


def calibrate_intrinsics(frames: Iterable[np.ndarray], board, source: str = "calibration frames",
                         invert: bool | None = None, min_views: int = 3, max_views: int = MAX_VIEWS,
                         flags: int = 0) -> Intrinsics:
    """Camera matrix and distortion from views of a ChArUco board (``cv2.calibrateCameraExtended``):
    :func:`select_calibration_views` then :func:`fit_views`, as they are (no judgement; the
    calibration stage judges the fit with :mod:`stringcast.calibrate.quality`).

    Args:
        frames: iterable of (H, W) grey images (all the same size), read once.
        board: ``cv2.aruco.CharucoBoard`` (square sizes in m).
        source: name used in error messages (the folder or file).
        invert: board polarity (see :func:`detect_charuco`).
        min_views: views with >= :data:`MIN_VIEW_CORNERS` corners needed.
        max_views: at most this many views, chosen for pose diversity (:func:`select_views`).
        flags: ``cv2.calibrateCamera`` flags, e.g. ``cv2.CALIB_FIX_K3`` for an ordinary
            (not wide-angle) lens, where a free k3 fits the views' noise, not the lens.

    Raises:
        DataError: fewer than ``min_views`` usable views, or frames of different sizes.
    """
    return fit_views(select_calibration_views(frames, board, source, invert, min_views, max_views), flags, min_views)
