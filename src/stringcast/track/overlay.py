"""Tracking overlay: a PNG strip of frames with the centreline and tracked points drawn.

Used by :mod:`stringcast.track.tracking` (``run_tracking(..., overlay_png=...)``).
"""
from __future__ import annotations

import cv2
import numpy as np

from stringcast.core import atomic_path


def write_overlay(path, shown, t, m_per_px: float, L: float, tile: int = 320) -> None:
    """A strip of frames (crops around the grasp) with the centreline and tracked points drawn.

    shown: (frame index, (H, W) frame, (P, 2) centreline px, (n + 1, 2) points px, (n + 1,) valid)
    per tile; a grasp outside the image is cropped around the nearest image pixel."""
    tiles = []
    for k, frame, path_px, pts_px, ok in shown:
        img = frame if frame.dtype == np.uint8 else cv2.convertScaleAbs(frame, alpha=255.0 / max(1, int(frame.max())))
        rgb = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        if len(path_px) > 1:
            cv2.polylines(rgb, [np.round(path_px * 4).astype(np.int32)], False, (255, 160, 0), 1, cv2.LINE_AA, 2)
        for i, (p, v) in enumerate(zip(pts_px, ok)):
            if v:
                cv2.circle(rgb, tuple(np.round(p * 4).astype(int)), 12, (0, 0, 255) if i == 0 else (0, 200, 0), 1,
                           cv2.LINE_AA, 2)
        R = int((L + 0.12) / m_per_px)
        h, w = img.shape[:2]  # the crop's centre: the grasp, kept on the image (the arm may reach out of view)
        c = np.clip(np.nan_to_num(pts_px[0], nan=0.0), [0, 0], [w - 1, h - 1]).astype(int)
        crop = cv2.copyMakeBorder(rgb, R, R, R, R, cv2.BORDER_CONSTANT, value=(0, 0, 0))[c[1]:c[1] + 2 * R, c[0]:c[0] + 2 * R]
        crop = cv2.resize(crop, (tile, tile), interpolation=cv2.INTER_AREA)
        cv2.putText(crop, f"frame {k}  t={t[k]:.3f} s", (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 255, 255), 1, cv2.LINE_AA)
        tiles.append(crop)
    if not tiles:
        tiles = [np.zeros((tile, tile, 3), np.uint8)]
        cv2.putText(tiles[0], "no frames tracked", (10, tile // 2), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 1)
    ok, buf = cv2.imencode(".png", np.hstack(tiles))
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.tobytes())
