"""The trial report's frame strip: video frames with the tracked and simulated points drawn.

The simulated points are the model's mass points driven by the measured joints with the
estimated parameters (``fit.parquet``, robot frame), projected into the image with the
trial's calibration (:meth:`Calibration.robot_to_pixel`: homography, then lens
distortion), so a person sees where the estimate and the string part. Frames are chosen
evenly over the frames that ``fit.parquet`` covers (the motion and the flight window),
read in increasing order in one pass over the video.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from stringcast.calibrate import Calibration
from stringcast.core import DataError
from stringcast.video import open_video

TRACKED = (60, 200, 60)      # BGR: green circles
GRASP = (40, 40, 230)        # red: point 0 (forward kinematics)
SIMULATED = (0, 150, 255)    # orange crosses and line


def _to_bgr(frame: np.ndarray) -> np.ndarray:
    img = frame if frame.dtype == np.uint8 else cv2.convertScaleAbs(frame, alpha=255.0 / max(1, int(frame.max())))
    return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img.copy()


def choose_frames(fit: pd.DataFrame, n: int) -> np.ndarray:
    """(<= n,) frame indices spread evenly over the frames in ``fit`` (sorted, unique)."""
    frames = np.unique(fit["frame"].to_numpy())
    if len(frames) == 0:
        return frames
    return np.unique(frames[np.linspace(0, len(frames) - 1, min(n, len(frames))).round().astype(int)])


def frame_strip(video_path: Path, calibration: Calibration, tracks: pd.DataFrame, fit: pd.DataFrame,
                length_m: float, n_frames: int = 6, tile_px: int = 300, margin_m: float = 0.08) -> np.ndarray:
    """Tiles of frames around the grasp point with tracked and simulated points, side by side.

    Args:
        video_path: the trial's video (any :func:`~stringcast.video.container.open_video` source).
        calibration: the trial's calibration.
        tracks: ``tracks.parquet`` (frame, point, x_m, y_m, valid; point 0 = grasp).
        fit: ``fit.parquet`` (frame, t_s, point 1..n, x_sim_m, y_sim_m).
        length_m: string length L (m): each tile spans L + ``margin_m`` around the grasp.
        n_frames: tiles; tile_px: tile side (px).

    Returns:
        (tile_px, k * tile_px, 3) uint8 BGR image (k <= n_frames; a note tile if none).

    Raises:
        DataError: the video cannot be read (named by the reader).
    """
    chosen = choose_frames(fit, n_frames)
    tiles = []
    tr = tracks.set_index(["frame", "point"]).sort_index()
    with open_video(video_path) as video:
        for k in chosen:
            if k >= video.n_frames:
                continue
            img = _to_bgr(video.read(int(k)))
            grasp = tr.loc[(int(k), 0)] if (int(k), 0) in tr.index else None
            if grasp is None or not np.isfinite(grasp["x_m"]):
                continue
            g_px = calibration.robot_to_pixel(np.array([[grasp["x_m"], grasp["y_m"]]]))[0]
            sim = fit[fit["frame"] == k].sort_values("point")
            sim_xy = np.vstack([[grasp["x_m"], grasp["y_m"]], sim[["x_sim_m", "y_sim_m"]].to_numpy()])
            ok = np.all(np.isfinite(sim_xy), axis=1)
            sim_px = calibration.robot_to_pixel(sim_xy[ok])
            cv2.polylines(img, [np.round(sim_px * 4).astype(np.int32)], False, SIMULATED, 1, cv2.LINE_AA, 2)
            for p in sim_px[1:]:
                cv2.drawMarker(img, tuple(np.round(p).astype(int)), SIMULATED, cv2.MARKER_TILTED_CROSS, 9, 1, cv2.LINE_AA)
            pts = tr.loc[int(k)] if int(k) in tr.index.get_level_values(0) else None
            if pts is not None:
                good = pts[pts["valid"].astype(bool)]
                px = calibration.robot_to_pixel(good[["x_m", "y_m"]].to_numpy())
                for point, p in zip(good.index, px):
                    cv2.circle(img, tuple(np.round(p * 4).astype(int)), 16, GRASP if point == 0 else TRACKED, 1,
                               cv2.LINE_AA, 2)
            R = max(8, int((length_m + margin_m) / float(calibration.m_per_px(g_px[None])[0])))
            c = np.round(g_px).astype(int)
            crop = cv2.copyMakeBorder(img, R, R, R, R, cv2.BORDER_CONSTANT)[c[1]:c[1] + 2 * R, c[0]:c[0] + 2 * R]
            tile = cv2.resize(crop, (tile_px, tile_px), interpolation=cv2.INTER_AREA)
            t = float(fit.loc[fit["frame"] == k, "t_s"].iloc[0])
            cv2.putText(tile, f"frame {k}  t={t:.3f} s", (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 255, 255), 1,
                        cv2.LINE_AA)
            tiles.append(tile)
    if not tiles:
        tile = np.zeros((tile_px, tile_px, 3), np.uint8)
        cv2.putText(tile, "no tracked frames to show", (10, tile_px // 2), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                    (255, 255, 255), 1)
        tiles = [tile]
    return np.hstack(tiles)


def strip_data_uri(image: np.ndarray) -> str:
    """A BGR image as an inline ``data:image/png;base64`` URI (``cv2.imencode``)."""
    import base64

    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise DataError("report: PNG encoding of the frame strip failed")
    return "data:image/png;base64," + base64.b64encode(buf.tobytes()).decode("ascii")
