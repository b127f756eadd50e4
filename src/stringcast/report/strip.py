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


def note_tile(text: str, tile_px: int) -> np.ndarray:
    """A black (tile_px, tile_px, 3) uint8 tile with ``text`` in white (a tile with nothing to show)."""
    tile = np.zeros((tile_px, tile_px, 3), np.uint8)
    for j, line in enumerate(text.split("\n")):
        cv2.putText(tile, line, (10, tile_px // 2 + 18 * j), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1)
    return tile


def _drawable(px: np.ndarray) -> np.ndarray:
    """Rows of (k, 2) pixel coordinates that can be drawn: finite and within +-1e5 px (OpenCV's int32
    fixed point with 2 fractional bits overflows far beyond)."""
    px = np.asarray(px, float).reshape(-1, 2)
    return np.all(np.isfinite(px), axis=1) & np.all(np.abs(px) < 1e5, axis=1)


def crop_around(img: np.ndarray, centre: np.ndarray, R: int) -> np.ndarray | None:
    """The (2R, 2R, 3) window of ``img`` centred on pixel ``centre`` (u, v), black where it leaves the
    image; None when no pixel of the window is inside the image (or the centre is not finite)."""
    if not np.all(np.isfinite(centre)) or R < 1:
        return None
    h, w = img.shape[:2]
    if not (-R < centre[0] < w + R and -R < centre[1] < h + R):
        return None
    c = np.round(centre).astype(int)
    x0, y0 = c[0] - R, c[1] - R
    ix0, iy0, ix1, iy1 = max(x0, 0), max(y0, 0), min(x0 + 2 * R, w), min(y0 + 2 * R, h)
    if ix1 <= ix0 or iy1 <= iy0:
        return None
    out = np.zeros((2 * R, 2 * R) + img.shape[2:], img.dtype)
    out[iy0 - y0:iy1 - y0, ix0 - x0:ix1 - x0] = img[iy0:iy1, ix0:ix1]
    return out


def _draw(img: np.ndarray, calibration: Calibration, grasp_xy: np.ndarray, sim_xy: np.ndarray,
          pts: pd.DataFrame | None) -> None:
    """Draw the simulated points (line and crosses, from the grasp) and the valid tracked points on ``img``."""
    chain = np.vstack([grasp_xy, sim_xy])
    sim_px = calibration.robot_to_pixel(chain[np.all(np.isfinite(chain), axis=1)])
    sim_px = sim_px[_drawable(sim_px)]
    if len(sim_px) > 1:
        cv2.polylines(img, [np.round(sim_px * 4).astype(np.int32)], False, SIMULATED, 1, cv2.LINE_AA, 2)
    for p in sim_px[1:]:
        cv2.drawMarker(img, tuple(int(v) for v in np.round(p)), SIMULATED, cv2.MARKER_TILTED_CROSS, 9, 1, cv2.LINE_AA)
    if pts is None:
        return
    good = pts[pts["valid"].astype(bool)]
    px = calibration.robot_to_pixel(good[["x_m", "y_m"]].to_numpy()) if len(good) else np.zeros((0, 2))
    for point, p, ok in zip(good.index, px, _drawable(px)):
        if ok:
            cv2.circle(img, tuple(int(v) for v in np.round(p * 4)), 16, GRASP if point == 0 else TRACKED, 1,
                       cv2.LINE_AA, 2)


def frame_strip(video_path: Path, calibration: Calibration, tracks: pd.DataFrame, fit: pd.DataFrame,
                length_m: float, n_frames: int = 6, tile_px: int = 300, margin_m: float = 0.08) -> np.ndarray:
    """Tiles of frames around the grasp point with tracked and simulated points, side by side.

    Each tile is the square of side 2 (L + ``margin_m``) around the grasp point, cut out of the frame
    (black where the square leaves the image); a frame whose square misses the image altogether (the
    grasp point far outside the camera's view) gives a note tile instead.

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
    outside = 0
    with open_video(video_path) as video:
        for k in chosen:
            if k >= video.n_frames:
                continue
            grasp = tr.loc[(int(k), 0)] if (int(k), 0) in tr.index else None
            if grasp is None or not np.isfinite(grasp["x_m"]):
                continue
            img = _to_bgr(video.read(int(k)))
            grasp_xy = np.array([[grasp["x_m"], grasp["y_m"]]])
            g_px = calibration.robot_to_pixel(grasp_xy)[0]
            sim = fit[fit["frame"] == k].sort_values("point")
            pts = tr.loc[int(k)] if int(k) in tr.index.get_level_values(0) else None
            _draw(img, calibration, grasp_xy, sim[["x_sim_m", "y_sim_m"]].to_numpy(), pts)
            scale = float(calibration.m_per_px(g_px[None])[0]) if np.all(np.isfinite(g_px)) else float("nan")
            R = int(min(max(8, (length_m + margin_m) / scale), 2 * max(img.shape[:2]))) if scale > 0 else 0
            crop = crop_around(img, g_px, R)
            if crop is None:
                outside += 1
                continue
            tile = cv2.resize(crop, (tile_px, tile_px), interpolation=cv2.INTER_AREA)
            t = float(fit.loc[fit["frame"] == k, "t_s"].iloc[0])
            cv2.putText(tile, f"frame {k}  t={t:.3f} s", (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 255, 255), 1,
                        cv2.LINE_AA)
            tiles.append(tile)
    if not tiles:
        text = f"the grasp point is outside\nthe image in {outside} frames" if outside else "no tracked frames to show"
        tiles = [note_tile(text, tile_px)]
    return np.hstack(tiles)


def strip_data_uri(image: np.ndarray) -> str:
    """A BGR image as an inline ``data:image/png;base64`` URI (``cv2.imencode``)."""
    import base64

    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise DataError("report: PNG encoding of the frame strip failed")
    return "data:image/png;base64," + base64.b64encode(buf.tobytes()).decode("ascii")
