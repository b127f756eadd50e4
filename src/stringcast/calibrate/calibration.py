"""Camera calibration: ChArUco intrinsics and the pixel -> swing-plane homography.

* Intrinsics (optional, from a ``calib/`` clip or image folder of the board in varied 3D
  poses): :mod:`stringcast.calibrate.charuco` (``CharucoDetector.detectBoard``,
  ``board.matchImagePoints``, views chosen for pose diversity, ``cv2.calibrateCameraExtended``).
  A long clip is sampled to at most ``calibration.max_candidate_frames`` frames first.
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
  corrected and the reprojection error shows it.

Boards printed inverted (white markers on black) are found by trying the inverted image
when the plain one gives no corners.

Errors: :class:`~stringcast.core.files.DataError` naming the file (no board, too few corners,
too few views, image size mismatch).
"""
from __future__ import annotations

import math
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from .charuco import Intrinsics, calibrate_intrinsics, detect_charuco
from stringcast.core import (BoardCheckSettings, DataError, find_video, read_joint_table, read_json,
                             write_json)
from stringcast.video import FRAME_SUFFIXES, open_video
from .board_check import check_board_to_robot

MAX_CANDIDATE_FRAMES = 240
"""A calibration clip is sampled evenly to at most this many frames for board detection."""
MIN_PLANE_CORNERS = 8
"""ChArUco corners the plane homography needs."""
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)


def _f(a):
    return None if a is None else np.asarray(a, float).tolist()


@dataclass(frozen=True)
class Calibration:
    """Pixel <-> robot-frame mapping of the swing plane for one trial.

    Attributes:
        H_pixel_to_robot: (3, 3) homography from undistorted pixels to robot (x, y), m.
        image_size: (width, height) px.
        K: (3, 3) camera matrix or None; dist: (5,) or None (homography only).
        reprojection_error_px: RMS of the board corners, robot -> pixel vs detected.
        n_corners: board corners used. board_to_robot: (3, 3) board-frame -> robot (m).
        intrinsics_rms_px, intrinsics_views, intrinsics_views_found: from
            :func:`~stringcast.calibrate.charuco.calibrate_intrinsics`, if any (views used / with the board).
        warnings: human-readable problems worth reporting.
        board_check: the board-to-robot transform checked against the arm at rest
            (``residual_mm``, ``dx_mm``, ``dy_mm``, ...), or None when not checked.
    """

    H_pixel_to_robot: np.ndarray
    image_size: tuple[int, int]
    K: np.ndarray | None = None
    dist: np.ndarray | None = None
    reprojection_error_px: float = math.nan
    n_corners: int = 0
    board_to_robot: np.ndarray | None = None
    intrinsics_rms_px: float | None = None
    intrinsics_views: int | None = None
    warnings: tuple[str, ...] = ()
    corner_ids: tuple[int, ...] = field(default=(), repr=False)
    intrinsics_views_found: int | None = None
    board_check: dict | None = None

    def __post_init__(self):
        H = np.asarray(self.H_pixel_to_robot, float)
        if H.shape != (3, 3) or not np.all(np.isfinite(H)) or abs(np.linalg.det(H)) < 1e-300:
            raise ValueError(f"Calibration: H_pixel_to_robot must be a finite invertible (3, 3), got {H.shape}")
        if (self.K is None) != (self.dist is None):
            raise ValueError("Calibration: K and dist go together (both or neither)")
        if self.K is not None and (np.shape(self.K) != (3, 3) or np.shape(self.dist) != (5,)):
            raise ValueError("Calibration: K must be (3, 3) and dist (5,)")
        if self.board_to_robot is not None and np.shape(self.board_to_robot) != (3, 3):
            raise ValueError("Calibration: board_to_robot must be (3, 3)")
        object.__setattr__(self, "H_pixel_to_robot", H)
        object.__setattr__(self, "_H_inv", np.linalg.inv(H))

    def undistort(self, uv: np.ndarray) -> np.ndarray:
        """(N, 2) distorted px -> (N, 2) undistorted px (``cv2.undistortPoints`` with P = K)."""
        uv = np.asarray(uv, float).reshape(-1, 2)
        if self.K is None or len(uv) == 0:
            return uv.copy()
        return cv2.undistortPoints(uv.reshape(-1, 1, 2), self.K, self.dist, P=self.K,
                                   criteria=_UNDISTORT_CRITERIA).reshape(-1, 2)

    def distort(self, uv: np.ndarray) -> np.ndarray:
        """(N, 2) undistorted px -> (N, 2) distorted px.

        OpenCV's 5-coefficient model (k1, k2, p1, p2, k3; as ``cv2.projectPoints`` of the
        normalised rays, to which tests compare it), in NumPy: it runs on every sample of
        the sync stage's search, where ``projectPoints`` cost 0.3 us a point.
        """
        uv = np.asarray(uv, float).reshape(-1, 2)
        if self.K is None or len(uv) == 0:
            return uv.copy()
        k1, k2, p1, p2, k3 = np.asarray(self.dist, float).ravel()[:5]
        f, c = np.diag(self.K)[:2], self.K[:2, 2]
        x, y = ((uv - c) / f).T
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.column_stack([xd, yd]) * f + c

    def pixel_to_robot(self, uv: np.ndarray) -> np.ndarray:
        """(N, 2) image px (distorted, as recorded) -> (N, 2) robot-frame (x, y), m."""
        u = self.undistort(uv)
        return _apply_h(self.H_pixel_to_robot, u)

    def robot_to_pixel(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) robot-frame (x, y) m in the swing plane -> (N, 2) image px (distorted)."""
        return self.distort(_apply_h(self._H_inv, np.asarray(xy, float).reshape(-1, 2)))

    def m_per_px(self, uv: np.ndarray) -> np.ndarray:
        """(N,) local image scale at pixels uv (N, 2): metres per pixel (mean of the two axes)."""
        uv = np.asarray(uv, float).reshape(-1, 2)
        p = self.pixel_to_robot(np.concatenate([uv, uv + [1, 0], uv + [0, 1]]))
        n = len(uv)
        return 0.5 * (np.linalg.norm(p[n:2 * n] - p[:n], axis=1) + np.linalg.norm(p[2 * n:] - p[:n], axis=1))

    def to_dict(self) -> dict:
        return {
            "image_size": list(self.image_size),
            "K": _f(self.K), "dist": _f(self.dist),
            "H_pixel_to_robot": _f(self.H_pixel_to_robot),
            "board_to_robot": _f(self.board_to_robot),
            "reprojection_error_px": self.reprojection_error_px,
            "n_corners": self.n_corners, "corner_ids": list(self.corner_ids),
            "intrinsics_rms_px": self.intrinsics_rms_px, "intrinsics_views": self.intrinsics_views,
            "intrinsics_views_found": self.intrinsics_views_found, "board_check": self.board_check,
            "warnings": list(self.warnings),
        }

    def to_json(self, path: str | Path) -> None:
        """Write ``calibration.json`` atomically."""
        write_json(path, self.to_dict())

    @classmethod
    def from_json(cls, path: str | Path) -> "Calibration":
        """Read ``calibration.json``. Raises DataError naming the file if keys are missing or wrong."""
        d = read_json(path)
        try:
            arr = (lambda k: None if d.get(k) is None else np.asarray(d[k], float))
            return cls(H_pixel_to_robot=np.asarray(d["H_pixel_to_robot"], float),
                       image_size=tuple(int(v) for v in d["image_size"]), K=arr("K"), dist=arr("dist"),
                       reprojection_error_px=float(d.get("reprojection_error_px") or math.nan),
                       n_corners=int(d.get("n_corners", 0)), board_to_robot=arr("board_to_robot"),
                       intrinsics_rms_px=d.get("intrinsics_rms_px"), intrinsics_views=d.get("intrinsics_views"),
                       warnings=tuple(d.get("warnings", [])), corner_ids=tuple(d.get("corner_ids", [])),
                       intrinsics_views_found=d.get("intrinsics_views_found"), board_check=d.get("board_check"))
        except (KeyError, TypeError, ValueError) as exc:
            raise DataError(f"{path}: not a valid calibration file: {exc!r}") from exc


def _apply_h(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    if len(pts) == 0:
        return pts.reshape(0, 2)
    return cv2.perspectiveTransform(pts.reshape(-1, 1, 2).astype(float), H).reshape(-1, 2)


def plane_homography(image: np.ndarray, board, board_to_robot: np.ndarray, intrinsics: Intrinsics | None = None,
                     source: str = "image", invert: bool | None = None) -> Calibration:
    """Fit the pixel -> robot-frame homography of the swing plane from the board in one image.

    Args:
        image: (H, W) grey frame with the ChArUco board lying in the swing plane.
        board: ``cv2.aruco.CharucoBoard`` (sizes in m). board_to_robot: (3, 3) board -> robot.
        intrinsics: undistort the corners first (``cv2.undistortPoints``, P = K) if given.
        source: named in errors.

    Returns:
        :class:`Calibration` with the reprojection error (robot -> pixel of the corners vs detected).

    Raises:
        DataError: fewer than :data:`MIN_PLANE_CORNERS` corners, or a degenerate fit.
    """
    size = (image.shape[1], image.shape[0])
    if intrinsics is not None and tuple(intrinsics.image_size) != size:
        raise DataError(f"{source}: image is {size[0]}x{size[1]} but the intrinsics are for "
                        f"{intrinsics.image_size[0]}x{intrinsics.image_size[1]}")
    corners, ids = detect_charuco(image, board, invert)
    if len(ids) < MIN_PLANE_CORNERS:
        raise DataError(f"{source}: {'no ChArUco board found' if len(ids) == 0 else f'only {len(ids)} board corners found'}"
                        f" (the plane homography needs >= {MIN_PLANE_CORNERS})")
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
    robot_xy = _apply_h(B, board_xy[inl])
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


def _calib_reader(calib_dir: Path):
    """The calibration views: the folder's images, or the one video inside it."""
    if any(p.suffix.lower() in FRAME_SUFFIXES for p in calib_dir.iterdir()):
        return open_video(calib_dir)
    vids = sorted(p for p in calib_dir.iterdir() if p.is_file() and p.suffix.lower() in (".mkv", ".avi", ".mp4", ".mov"))
    if not vids:
        raise DataError(f"{calib_dir}: no PNG/TIFF images or video of the calibration board")
    return open_video(vids[0])


def median_frame(video, n: int = 5) -> np.ndarray:
    """Pixel-wise median of the first ``n`` frames of a :class:`~stringcast.video.container.VideoReader`."""
    frames = [f for _, (_, f) in zip(range(min(n, video.n_frames)), video)]
    return np.median(np.stack(frames), axis=0).astype(video.dtype)


@contextmanager
def single_threaded_opencv():
    """Run OpenCV on one thread inside the block (``cv2.setNumThreads``), then restore.

    With its worker threads, calibration on the same views gave intrinsics that differed run
    to run in the 9th significant digit (the threads' partial sums add up in varying order);
    the estimation's search amplifies such a difference into another estimate, so a
    reprocessed trial would not reproduce its results. One thread costs this stage ~1 s.
    """
    n = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        yield
    finally:
        cv2.setNumThreads(n)


def run_calibration(trial_dir: str | Path, calib_dir: str | Path | None, campaign, out_json: str | Path,
                    n_median: int = 5, *, board_check: BoardCheckSettings) -> Calibration:
    """Calibrate one trial and write ``calibration.json`` (reproducibly: :func:`single_threaded_opencv`).

    Intrinsics from ``calib_dir`` (if given), then the plane homography from the median of
    the first ``n_median`` trial frames (the arm and string hang still before the motion).
    The configured board-to-robot transform is then checked against the still arm in that
    image at the joint log's first posture (:func:`stringcast.calibrate.board_check.check_board_to_robot`;
    ``board_check`` in the file, a warning above ``board_check.warn_mm``).

    Args:
        board_check: board-check settings (:class:`~stringcast.core.BoardCheckSettings`); the
            check looks for the arm's outline (``campaign.arm``).

    Raises:
        DataError: no board / too few corners in the trial frames or the calibration views,
            or mismatched image sizes (the file is named).
    """
    with single_threaded_opencv():
        return _run_calibration(Path(trial_dir), calib_dir, campaign, out_json, n_median, board_check)


def _run_calibration(trial_dir: Path, calib_dir, campaign, out_json, n_median: int,
                     board_check: BoardCheckSettings) -> Calibration:
    setup = campaign.setup
    board = setup.board.make()
    warnings: list[str] = []
    intr = None
    if calib_dir is not None:
        calib_dir = Path(calib_dir)
        reader = _calib_reader(calib_dir)
        stride = max(1, math.ceil(reader.n_frames / MAX_CANDIDATE_FRAMES))
        flags = cv2.CALIB_FIX_K3 if setup.camera.get("fix_k3") else 0
        intr = calibrate_intrinsics((f for i, f in reader if i % stride == 0), board, str(reader.path), flags=flags)
        if intr.views_rejected:
            warnings.append(f"intrinsics: {intr.views_rejected} calibration views rejected (reprojection outliers)")
    else:
        warnings.append("no calib/ views: homography only, lens distortion is not corrected")
    vpath = find_video(trial_dir)
    with open_video(vpath) as video:
        img = median_frame(video, n_median)
    cal = plane_homography(img, board, setup.board_to_robot, intr, f"{vpath} (median of the first {n_median} frames)")
    n_all = (setup.board.squares_x - 1) * (setup.board.squares_y - 1)
    if cal.reprojection_error_px > setup.reprojection_warn_px:
        warnings.append(f"board reprojection error {cal.reprojection_error_px:.2f} px exceeds "
                        f"{setup.reprojection_warn_px:.2f} px")
    if cal.n_corners < 0.5 * n_all:
        warnings.append(f"only {cal.n_corners} of {n_all} board corners used: the board is partly hidden")
    board = _board_check(trial_dir, img, cal, campaign, board_check, warnings)
    cal = Calibration(cal.H_pixel_to_robot, cal.image_size, cal.K, cal.dist, cal.reprojection_error_px,
                      cal.n_corners, cal.board_to_robot, None if intr is None else intr.rms_px,
                      None if intr is None else intr.n_views, tuple(warnings), cal.corner_ids,
                      None if intr is None else intr.views_found, board)
    cal.to_json(out_json)
    return cal


def _board_check(trial_dir: Path, rest_image: np.ndarray, cal: Calibration, campaign, board_check: BoardCheckSettings,
                 warnings: list[str]) -> dict | None:
    """The board-to-robot check at the joint log's first (rest) posture; None without a joints.csv."""

    joints = trial_dir / "joints.csv"
    if not joints.exists():
        warnings.append(f"{joints} missing: the board-to-robot transform was not checked against the arm")
        return None
    _, q, _ = read_joint_table(joints, n_joints=campaign.arm.n_joints, arm_name=campaign.arm.name)
    grey = rest_image if rest_image.ndim == 2 else cv2.cvtColor(rest_image, cv2.COLOR_BGR2GRAY)
    board = check_board_to_robot(grey.astype(np.float64), cal, campaign.arm, q[0], board_check)
    warn = float(board_check.warn_mm)
    if board.get("residual_mm") is None:
        warnings.append("board-to-robot check: the still arm could not be located in the first frames")
    elif board["residual_mm"] > warn:
        warnings.append(f"board-to-robot check: the still arm is seen {board['residual_mm']:.1f} mm "
                        f"(dx {board['dx_mm']:+.1f}, dy {board['dy_mm']:+.1f} mm) from where the configured "
                        f"board pose puts it (> {warn:g} mm): check setups.*.board_origin_mm / board_angle_deg")
    return board
