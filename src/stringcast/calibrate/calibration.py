"""Camera calibration: ChArUco intrinsics, judged, and the pixel -> swing-plane homography.

* Intrinsics (optional, from a ``calib/`` clip or image folder of the board in varied 3D
  poses): :mod:`stringcast.calibrate.charuco` (``CharucoDetector.detectBoard``,
  ``board.matchImagePoints``, views chosen for pose diversity, ``cv2.calibrateCameraExtended``).
  A long clip is sampled to at most ``calibration.max_candidate_frames`` frames first.
  :mod:`stringcast.calibrate.intrinsics` judges the fit (standard deviations, coverage of the
  image, tilt variety: :mod:`stringcast.calibrate.quality`), holds the principal point, k3
  or k2 the views do not determine, or fails, saying which shots to add.
* The trial's board (in the swing plane, seen in every trial) checks the calib/ intrinsics
  (its reprojection error against its own noise and the views'), then joins the views as
  one more for the final fit (``calibration.board_view``).
* Plane homography (every trial): the board lies in the swing plane. Its ChArUco corners,
  detected in the median of the first few trial frames and undistorted with
  ``cv2.undistortPoints(P=K)`` when intrinsics exist, give the board-plane -> pixel
  homography; composed with the configured ``board_to_robot`` transform it maps undistorted
  pixels to robot-frame (x, y) in m. ``cv2.findHomography`` (RANSAC 3 px) picks the inlier
  corners. With intrinsics, the homography is the board's pose, H = K [r1 r2 t]
  (``cv2.solvePnP`` with ``SOLVEPNP_IPPE``, refined by ``cv2.solvePnPRefineLM``): 6 degrees of
  freedom instead of 8. The board covers a corner of the swing plane, and a free 8-DOF fit
  extrapolates its perspective terms badly: on a lab trial the plane was up to 2.8 mm off
  (mean 1.0 mm) across the image with the free fit, 1.2 mm (mean 0.35 mm) with the pose.
  Without intrinsics the free fit on the inliers is used, the lens distortion is not
  corrected and the reprojection error shows it (verdict ``warn``).

``calibration.json`` carries the verdict (``ok`` / ``warn`` / ``fail`` and its reasons): the
intrinsics' judgement, the board view's check, the board's reprojection error and corners,
and the still-arm check of the board-to-robot transform
(:func:`stringcast.calibrate.board_check.check_board_to_robot`).

Boards printed inverted (white markers on black) are found by trying the inverted image
when the plain one gives no corners.

Errors: :class:`~stringcast.core.files.DataError` naming the file (no board, too few corners,
too few views, image size mismatch).
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from stringcast.core import (BoardCheckSettings, CalibrationSettings, DataError, TrialFiles, Verdict,
                             read_joint_table)
from stringcast.video import open_video

from .board_check import check_board_to_robot
from .board_hint import board_hint
from .calib_views import camera_flags, find_calib_views, read_calib_views, read_campaign_intrinsics, single_threaded_opencv
from .charuco import Intrinsics, calibrate_intrinsics, detect_charuco
from .scale_check import arm_scale
from .intrinsics import board_view_check, judged_intrinsics
from .intrinsics_spread import mapping_modes
from .mapping import Calibration, apply_homography

__all__ = ["Calibration", "Intrinsics", "calibrate_intrinsics", "detect_charuco", "median_frame", "plane_homography",
           "run_calibration", "single_threaded_opencv"]

MIN_PLANE_CORNERS = 8
"""ChArUco corners the plane homography needs."""


def detect_plane_board(image: np.ndarray, board, source: str = "image", invert: bool | None = None,
                       campaign=None) -> tuple[np.ndarray, np.ndarray]:
    """The board's corners (N, 2) px and ids (N,) in a trial image (:func:`detect_charuco`).

    When fewer than half the board's corners are found, the image is searched again enlarged
    2x (a board far from the camera: markers too small to decode at scale 1); the search
    that finds more wins.

    Raises:
        DataError: fewer than :data:`MIN_PLANE_CORNERS` corners, naming ``source``, and with no
            corner at all what the image shows instead (:func:`~stringcast.calibrate.board_hint.board_hint`,
            the settings named from ``campaign`` where given).
    """
    corners, ids = detect_charuco(image, board, invert)
    sx, sy = board.getChessboardSize()
    if len(ids) < (sx - 1) * (sy - 1) / 2:
        enlarged = detect_charuco(image, board, invert, upscale=2)
        if len(enlarged[1]) > len(ids):
            corners, ids = enlarged
    if len(ids) < MIN_PLANE_CORNERS:
        hint = ""
        if len(ids) == 0:
            hint = board_hint([image], board, *(() if campaign is None else (
                campaign.setup.board.dictionary, lambda key: campaign.setup_setting(f"board.{key}"))))
        raise DataError(f"{source}: {'no ChArUco board found' if len(ids) == 0 else f'only {len(ids)} board corners found'}"
                        f" (the plane homography needs >= {MIN_PLANE_CORNERS})" + (f": {hint}" if hint else ""))
    return corners, ids


def plane_homography(image: np.ndarray, board, board_to_robot: np.ndarray, intrinsics: Intrinsics | None = None,
                     source: str = "image", invert: bool | None = None,
                     detection: tuple[np.ndarray, np.ndarray] | None = None) -> Calibration:
    """Fit the pixel -> robot-frame homography of the swing plane from the board in one image.

    Args:
        image: (H, W) grey frame with the ChArUco board lying in the swing plane.
        board: ``cv2.aruco.CharucoBoard`` (sizes in m). board_to_robot: (3, 3) board -> robot.
        intrinsics: undistort the corners first (``cv2.undistortPoints``, P = K) if given.
        source: named in errors. detection: the board's (corners, ids) in ``image`` if
            already found (:func:`detect_plane_board`).

    Returns:
        :class:`Calibration` with the reprojection error (robot -> pixel of the corners vs detected).

    Raises:
        DataError: fewer than :data:`MIN_PLANE_CORNERS` corners, or a degenerate fit.
    """
    size = (image.shape[1], image.shape[0])
    if intrinsics is not None and tuple(intrinsics.image_size) != size:
        raise DataError(f"{source}: image is {size[0]}x{size[1]} but the intrinsics are for "
                        f"{intrinsics.image_size[0]}x{intrinsics.image_size[1]}")
    corners, ids = detection if detection is not None else detect_plane_board(image, board, source, invert)
    board_xy = np.asarray(board.getChessboardCorners(), float)[ids, :2]
    K = None if intrinsics is None else intrinsics.K
    dist = None if intrinsics is None else intrinsics.dist
    probe = Calibration(np.eye(3), size, K, dist)
    und = probe.undistort(corners)
    H_b2p, inl = cv2.findHomography(board_xy, und, cv2.RANSAC, 3.0)
    if H_b2p is None:
        raise DataError(f"{source}: the board corners give no homography (degenerate detection)")
    inl = inl.ravel().astype(bool)
    H_b2p = (cv2.findHomography(board_xy[inl], und[inl], 0)[0] if intrinsics is None
             else _pose_homography(board_xy[inl], corners[inl], K, dist))
    if H_b2p is None:
        raise DataError(f"{source}: the board corners give no homography (degenerate detection)")
    B = np.asarray(board_to_robot, float)
    H = B @ np.linalg.inv(H_b2p)
    H = H / H[2, 2]
    cal = Calibration(H, size, K, dist, n_corners=int(inl.sum()), board_to_robot=B,
                      corner_ids=tuple(int(i) for i in ids[inl]))
    robot_xy = apply_homography(B, board_xy[inl])
    err = float(np.sqrt(np.mean(np.sum((cal.robot_to_pixel(robot_xy) - corners[inl]) ** 2, axis=1))))
    object.__setattr__(cal, "reprojection_error_px", err)
    return cal


def _pose_homography(board_xy: np.ndarray, corners: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray | None:
    """Board plane (N, 2) m -> undistorted px homography K [r1 r2 t] from the board's pose.

    ``cv2.solvePnP`` (``SOLVEPNP_IPPE``, planar) on the distorted corners (N, 2) px, then
    ``cv2.solvePnPRefineLM``. Returns None when the pose cannot be found."""
    obj = np.c_[board_xy, np.zeros(len(board_xy))].astype(np.float64)
    img = np.ascontiguousarray(corners, np.float64).reshape(-1, 1, 2)
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        return None
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvec, tvec)
    R = cv2.Rodrigues(rvec)[0]
    return K @ np.c_[R[:, :2], tvec.reshape(3)]


def median_frame(video, n: int = 5) -> np.ndarray:
    """Pixel-wise median of the first ``n`` frames of a :class:`~stringcast.video.container.VideoReader`."""
    frames = [f for _, (_, f) in zip(range(min(n, video.n_frames)), video)]
    return np.median(np.stack(frames), axis=0).astype(video.dtype)


def run_calibration(trial: TrialFiles | str | Path, calib_dir: str | Path | None, campaign, out_json: str | Path,
                    n_median: int = 5, intrinsics_json: str | Path | None = None, *, board_check: BoardCheckSettings,
                    calibration: CalibrationSettings = CalibrationSettings()) -> Calibration:
    """Calibrate one trial and write ``calibration.json`` (reproducibly: single-threaded OpenCV).

    Intrinsics from ``calib_dir`` (if given: the ``calib/`` folder, or the campaign's views found
    in it once, ``calib_views.npz`` of :func:`~stringcast.calibrate.calib_views.write_calib_views`), judged
    (:func:`~stringcast.calibrate.intrinsics.judged_intrinsics`);
    the trial's board (in the median of the first ``n_median`` trial frames, where the arm
    and string hang still before the motion) checks them and joins the views; then the plane
    homography. The configured board-to-robot transform is checked against the still arm
    in that image at the joint log's first posture
    (:func:`stringcast.calibrate.board_check.check_board_to_robot`; ``board_check`` in the
    file, a warning above ``board_check.warn_mm``). The file's ``verdict`` gathers them.
    OpenCV runs single-threaded throughout, so the result is reproducible
    (:func:`~stringcast.calibrate.calib_views.single_threaded_opencv`).

    Parameters
    ----------
    trial : TrialFiles or path
        The trial's video and joint log (:class:`~stringcast.core.TrialFiles`; a folder: its
        files by the data contract's names).
    calib_dir : path or None
        The ``calib/`` folder, or the ``calib_views.npz`` file of its views; None: no intrinsics, the
        homography only (lens distortion not corrected, a ``warn``).
    campaign : Campaign
        The resolved campaign (the setup's board and ``board_to_robot``, the arm).
    out_json : path
        Where to write ``calibration.json``.
    n_median : int
        Trial frames, from the first, whose pixel-wise median (:func:`median_frame`) shows the board.
    intrinsics_json : path, optional
        The campaign's views' own intrinsics, fitted once
        (``intrinsics.json`` of :func:`~stringcast.calibrate.calib_views.write_campaign_intrinsics`),
        read instead of refitted; None: fitted here. The result is the same.
    board_check : BoardCheckSettings
        Board-check settings (:class:`~stringcast.core.BoardCheckSettings`); the
        check looks for the arm's outline (``campaign.arm``).
    calibration : CalibrationSettings
        Intrinsics settings (:class:`~stringcast.core.CalibrationSettings`;
        its defaults when not given).

    Returns
    -------
    Calibration
        The trial's mapping with its verdict, as written to ``out_json``.

    Raises
    ------
    DataError
        No board / too few corners in the trial frames or the calibration views,
        mismatched image sizes, or an ``intrinsics_json`` made from other views or settings
        (the file is named).
    """
    with single_threaded_opencv():
        return _run_calibration(TrialFiles.of(trial), calib_dir, campaign, out_json, n_median, board_check, calibration,
                                intrinsics_json)


def _intrinsics(calib_dir: Path, board, campaign, image: np.ndarray, detection, source: str, st: CalibrationSettings,
                intrinsics_json: Path | None = None):
    """(Intrinsics, their measures, the board view's check or None, verdict) from calib/ (the views'
    own fit read from ``intrinsics_json`` if given) and the trial's board."""
    calib = Path(calib_dir)
    views, where = read_calib_views(calib) if calib.is_file() else find_calib_views(calib, board, st, campaign)
    flags = camera_flags(campaign)
    size = (image.shape[1], image.shape[0])
    if tuple(views.image_size) != size:
        raise DataError(f"{source}: image is {size[0]}x{size[1]} but the calibration views in {where} are "
                        f"{views.image_size[0]}x{views.image_size[1]}")
    if intrinsics_json is not None:
        intr, quality, verdict = read_campaign_intrinsics(intrinsics_json, views, campaign, st)
    else:
        intr, quality, verdict = judged_intrinsics(views, flags, st)
    if not st.board_view:
        return intr, quality, None, verdict
    corners, ids = detection
    obj, img = board.matchImagePoints(corners.astype(np.float32).reshape(-1, 1, 2), ids.reshape(-1, 1))
    check, problem = board_view_check(intr, obj, img, st)
    intr, quality, verdict = judged_intrinsics(views.plus(obj, img, "trial board"), flags, st)
    check["included"] = True
    if problem:
        verdict = verdict.add("warn", f"intrinsics: {problem}")
    return intr, quality, check, verdict


def _run_calibration(trial: TrialFiles, calib_dir, campaign, out_json, n_median: int,
                     board_check: BoardCheckSettings, st: CalibrationSettings, intrinsics_json=None) -> Calibration:
    setup = campaign.setup
    board = setup.board.make()
    vpath = trial.video
    with open_video(vpath) as video:
        img = median_frame(video, n_median)
    source = f"{vpath} (median of the first {n_median} frames)"
    detection = detect_plane_board(img, board, source, campaign=campaign)
    intr, quality, check, verdict = None, None, None, Verdict()
    if calib_dir is not None:
        intr, quality, check, verdict = _intrinsics(Path(calib_dir), board, campaign, img, detection, source, st,
                                                    None if intrinsics_json is None else Path(intrinsics_json))
    else:
        verdict = verdict.add("warn", "no calib/ views: homography only, lens distortion is not corrected; "
                                      "film the board in varied poses into calib/ for intrinsics")
    cal = plane_homography(img, board, setup.board_to_robot, intr, source, detection=detection)
    n_all = (setup.board.squares_x - 1) * (setup.board.squares_y - 1)
    if cal.reprojection_error_px > setup.reprojection_warn_px:
        verdict = verdict.add("warn", f"board reprojection error {cal.reprojection_error_px:.2f} px exceeds "
                                      f"{setup.reprojection_warn_px:.2f} px")
    if cal.n_corners < 0.5 * n_all:
        verdict = verdict.add("warn", f"only {cal.n_corners} of {n_all} board corners used: the board is partly "
                                      "hidden; clear the view of the board")
    spread = _intrinsics_spread(img, board, setup.board_to_robot, cal, quality, detection, source)
    board_doc, verdict = _board_check(trial.joints, img, cal, campaign, board_check, verdict, spread)
    warnings = list(verdict.reasons)
    if intr is not None and intr.views_rejected:
        warnings.append(f"intrinsics: {intr.views_rejected} calibration views rejected (reprojection outliers)")
    cal = Calibration(cal.H_pixel_to_robot, cal.image_size, cal.K, cal.dist, cal.reprojection_error_px,
                      cal.n_corners, cal.board_to_robot, None if intr is None else intr.rms_px,
                      None if intr is None else intr.n_views, tuple(warnings), cal.corner_ids,
                      None if intr is None else intr.views_found, board_doc, quality, check, verdict)
    cal.to_json(out_json)
    return cal


def _intrinsics_spread(img, board, board_to_robot, cal: Calibration, quality: dict | None, detection, source: str):
    """``points -> (N, 2, M) m``: the modes of how the intrinsics' uncertainty moves where ``cal`` maps plane
    points (:func:`~stringcast.calibrate.intrinsics_spread.mapping_modes`, the homography refitted to the
    trial's board under each change); None without intrinsics or their covariance."""
    if cal.K is None or not quality or quality.get("covariance") is None:
        return None
    free = quality.get("free_fit") if quality.get("held") else None
    if free is not None and free.get("covariance") is None:
        return None
    size = tuple(cal.image_size)

    def refit(K, dist):
        return plane_homography(img, board, board_to_robot, Intrinsics(K, dist, 0.0, 0, size), source,
                                detection=detection)

    return lambda points: mapping_modes(points, cal, quality["covariance"], refit, free)


def _weak_intrinsics(verdict: Verdict) -> str | None:
    """Why the calibration found its intrinsics undetermined, in a clause, where its verdict so far has an
    intrinsics warning (parameters held, deviations over their limits, poor coverage, the trial's board
    off them), or None: where it has, their stated deviations are no bound on their error."""
    if any(r.startswith("intrinsics: ") for r in verdict.reasons):
        return "the calibration's intrinsics warning: the views do not determine them well"
    return None


def _board_check(joints: Path, rest_image: np.ndarray, cal: Calibration, campaign, board_check: BoardCheckSettings,
                 verdict: Verdict, spread=None) -> tuple[dict | None, Verdict]:
    """The board-to-robot check at the joint log's first (rest) posture (None without a
    joints.csv), with the intrinsics' ``spread`` to tell their error from the board pose's
    (:func:`~stringcast.calibrate.board_check.check_board_to_robot`), and the verdict with what it found."""
    if not joints.exists():
        return None, verdict.add("warn", f"{joints} missing: the board-to-robot transform was not checked against the arm")
    _, q = read_joint_table(joints, n_joints=campaign.arm.n_joints, arm_name=campaign.arm.name)
    grey = rest_image if rest_image.ndim == 2 else cv2.cvtColor(rest_image, cv2.COLOR_BGR2GRAY)
    board = check_board_to_robot(grey.astype(np.float64), cal, campaign.arm, q[0], board_check, spread,
                                 _weak_intrinsics(verdict))
    found = Verdict.from_dict(board.get("verdict"))
    if board["residual_mm"] is None or board["residual_mm"] > board_check.warn_mm:
        board["arm_scale"] = arm_scale(grey.astype(np.float64), cal, campaign.arm, q[0], board_check)
        if board["arm_scale"] is not None:
            verdict = verdict.add("warn", scale_reason(board["arm_scale"], campaign))
    for reason in found.reasons:
        verdict = verdict.add(found.status, f"board-to-robot check: {reason}")
    return board, verdict


def scale_reason(found: dict, campaign) -> str:
    """The verdict's reason for the arm seen at a scale (:func:`~stringcast.calibrate.scale_check.arm_scale`),
    naming the board's square size (and what it would be)."""
    k, b = found["scale"], campaign.setup.board
    return (f"board-to-robot check: the still arm is seen scaled by {k:.3f} about the board's origin against its "
            f"forward kinematics ({found['features']} of its features found there, {found['features_at_1']} where "
            f"the forward kinematics put them; {found['residual_mm']:.1f} mm off at that scale): every length "
            f"through the board is off by that factor; check {campaign.setup_setting('board.square_mm')} (and "
            f"marker_mm, in the same ratio): the arm fits squares of {b.square * 1000 / k:.1f} mm, not "
            f"{b.square * 1000:g}")
