"""The pixel <-> swing-plane mapping of one trial (:class:`Calibration`, ``calibration.json``).

Undistorted pixels map to the robot frame's (x, y) in the swing plane by one homography;
OpenCV's 5-coefficient lens model (k1, k2, p1, p2, k3) relates them to the recorded
(distorted) pixels (``cv2.undistortPoints`` one way, the model in NumPy the other).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from stringcast.core import DataError, Verdict, read_json, write_json

_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)


def _f(a):
    return None if a is None else np.asarray(a, float).tolist()


@dataclass(frozen=True)
class Calibration:
    """Pixel <-> robot-frame mapping of the swing plane for one trial.

    Attributes
    ----------
    H_pixel_to_robot : ndarray, (3, 3)
        Homography from undistorted pixels (px) to robot-frame (x, y), m.
    image_size : tuple of int, (2,)
        (width, height), px.
    K : ndarray, (3, 3), or None
        Camera matrix, px; None (with ``dist``): homography only.
    dist : ndarray, (5,), or None
        OpenCV's lens coefficients (k1, k2, p1, p2, k3); None (with ``K``): homography only.
    reprojection_error_px : float
        RMS of the board corners, robot -> pixel vs detected, px (NaN when not measured).
    n_corners : int
        Board corners used.
    board_to_robot : ndarray, (3, 3), or None
        Board-plane (x, y) -> robot-frame (x, y) transform (homogeneous), m.
    intrinsics_rms_px : float or None
        From :func:`~stringcast.calibrate.charuco.calibrate_intrinsics`, if any: the reprojection RMS of
        the views used, px.
    intrinsics_views : int or None
        From :func:`~stringcast.calibrate.charuco.calibrate_intrinsics`, if any: the views used.
    warnings : tuple of str
        Human-readable problems worth reporting.
    corner_ids : tuple of int
        The ChArUco ids of the board corners used.
    intrinsics_views_found : int or None
        From :func:`~stringcast.calibrate.charuco.calibrate_intrinsics`, if any: the views with the board.
    board_check : dict or None
        The board-to-robot transform checked against the arm at rest (``residual_mm``, ``dx_mm``,
        ``dy_mm``, ...), or None when not checked.
    intrinsics_quality : dict or None
        How well the calib/ views determine the intrinsics (:func:`stringcast.calibrate.quality.assess`:
        standard deviations, per-view errors, coverage, tilt, what was held), or None without calib/.
    board_view : dict or None
        The trial's board reprojected under the calib/ intrinsics
        (:func:`stringcast.calibrate.intrinsics.board_view_check`), or None.
    verdict : Verdict
        :class:`~stringcast.core.Verdict`, ok / warn / fail with its reasons.

    Raises
    ------
    ValueError
        ``H_pixel_to_robot`` not a finite invertible (3, 3); ``K`` without ``dist`` or the reverse; ``K`` not
        (3, 3) or ``dist`` not (5,), or either not finite, or a focal length <= 0; ``board_to_robot`` not a
        finite (3, 3); ``image_size`` not (width, height) >= 1 px.
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
    intrinsics_quality: dict | None = None
    board_view: dict | None = None
    verdict: Verdict = Verdict()

    def __post_init__(self):
        H = np.asarray(self.H_pixel_to_robot, float)
        if H.shape != (3, 3) or not np.all(np.isfinite(H)) or abs(np.linalg.det(H)) < 1e-300:
            raise ValueError(f"Calibration: H_pixel_to_robot must be a finite invertible (3, 3), got {H.shape}")
        if (self.K is None) != (self.dist is None):
            raise ValueError("Calibration: K and dist go together (both or neither)")
        if self.K is not None and (np.shape(self.K) != (3, 3) or np.shape(self.dist) != (5,)):
            raise ValueError("Calibration: K must be (3, 3) and dist (5,)")
        if self.K is not None and not (np.all(np.isfinite(self.K)) and np.all(np.isfinite(self.dist))
                                       and self.K[0][0] > 0 and self.K[1][1] > 0):
            raise ValueError("Calibration: K and dist must be finite, with positive focal lengths")
        if self.board_to_robot is not None and (np.shape(self.board_to_robot) != (3, 3)
                                                or not np.all(np.isfinite(self.board_to_robot))):
            raise ValueError("Calibration: board_to_robot must be a finite (3, 3)")
        if len(self.image_size) != 2 or min(self.image_size) < 1:
            raise ValueError(f"Calibration: image_size must be (width, height) >= 1 px, got {self.image_size}")
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
        return apply_homography(self.H_pixel_to_robot, u)

    def robot_to_pixel(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) robot-frame (x, y) m in the swing plane -> (N, 2) image px (distorted)."""
        return self.distort(apply_homography(self._H_inv, np.asarray(xy, float).reshape(-1, 2)))

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
            "warnings": list(self.warnings), "intrinsics": self.intrinsics_quality, "board_view": self.board_view,
            "verdict": self.verdict.as_dict(),
        }

    def to_json(self, path: str | Path) -> None:
        """Write ``calibration.json`` atomically."""
        write_json(path, self.to_dict())

    @classmethod
    def from_json(cls, path: str | Path) -> Calibration:
        """Read ``calibration.json``. Raises DataError naming the file if keys are missing or wrong."""
        d = read_json(path, mapping=True)
        try:
            def arr(k):
                return (None if d.get(k) is None else np.asarray(d[k], float))
            return cls(H_pixel_to_robot=np.asarray(d["H_pixel_to_robot"], float),
                       image_size=tuple(int(v) for v in d["image_size"]), K=arr("K"), dist=arr("dist"),
                       reprojection_error_px=float(d.get("reprojection_error_px") or math.nan),
                       n_corners=int(d.get("n_corners", 0)), board_to_robot=arr("board_to_robot"),
                       intrinsics_rms_px=d.get("intrinsics_rms_px"), intrinsics_views=d.get("intrinsics_views"),
                       warnings=tuple(d.get("warnings", [])), corner_ids=tuple(d.get("corner_ids", [])),
                       intrinsics_views_found=d.get("intrinsics_views_found"), board_check=d.get("board_check"),
                       intrinsics_quality=d.get("intrinsics"), board_view=d.get("board_view"),
                       verdict=Verdict.from_dict(d.get("verdict")))
        except (KeyError, TypeError, ValueError, AttributeError, np.linalg.LinAlgError) as exc:
            raise DataError(f"{path}: not a valid calibration file: {exc!r}") from exc


def apply_homography(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(N, 2) points through the (3, 3) homography H (``cv2.perspectiveTransform``) -> (N, 2)."""
    if len(pts) == 0:
        return pts.reshape(0, 2)
    return cv2.perspectiveTransform(pts.reshape(-1, 1, 2).astype(float), H).reshape(-1, 2)
