"""Drawing primitives shared by the lab's scene and background: anti-aliased coverage masks
composited into reflectance images, the materials' reflectance and the default arm's outline.

OpenCV anti-aliases only 8-bit images, so each shape is drawn as an 8-bit coverage mask
(``LINE_AA``, sub-pixel ``shift`` bits) and composited: R <- R (1 - a) + r_shape a. A mono
image is (H, W) float32; a colour one (H, W, 3) float32 BGR, composited channel by channel
with a (3,) value (a grey value is broadcast).
"""
from __future__ import annotations

import numpy as np

SHIFT = 4                      # sub-pixel bits for cv2 drawing
ONE = 1 << SHIFT
BG_SS = 2                      # background supersampling
STRING_SS = 4                  # string supersampling
MAX_SUB = 48                   # most sub-exposure renders per frame (long exposures, fast strings)

REFLECTANCE = {
    "wall": 0.62, "table": 0.38, "table_edge": 0.85, "pedestal": 0.28, "paper": 0.92, "ink": 0.06,
    "target": 0.22, "target_ring": 0.85, "cable": 0.2,
    "cord": 0.10, "pipe": 0.40, "clay": 0.30,
    "link": 0.52, "joint": 0.32, "gripper": 0.18,
}
ARM_WIDTHS_M = (0.11, 0.09, 0.075)   # link widths, m (more links reuse the last)
JOINT_RADII_M = (0.065, 0.055, 0.045, 0.04)
GRIPPER_WIDTH_M = (0.06, 0.025)      # at the wrist, at the fingertips
LEVEL = 1.05                          # DN = 255 * LEVEL * illumination * vignette * reflectance


def supersample_homography(H: np.ndarray, s: int) -> np.ndarray:
    """Compose a homography into a canvas with ``s``x supersampling (pixel centres kept)."""
    A = np.array([[s, 0, (s - 1) / 2], [0, s, (s - 1) / 2], [0, 0, 1.0]])
    return A @ H


def fix(p: np.ndarray) -> np.ndarray:
    """(N, 2) float pixel coordinates -> int32 with ``SHIFT`` fractional bits."""
    return np.round(np.asarray(p) * ONE).astype(np.int32).reshape(-1, 1, 2)


def composite(img: np.ndarray, mask: np.ndarray, value, scale: float = 1 / 255) -> None:
    """In place: img <- img (1 - a) + value a, a = mask * scale.

    img: (H, W) float32 (value a float) or (H, W, 3) float32 BGR (value a float or (3,)).
    """
    a = mask.astype(np.float32) * np.float32(scale)
    if img.ndim == 3:
        a = a[..., None]
        img *= 1 - a
        img += np.asarray(value, np.float32) * a
        return
    img *= 1 - a
    img += np.float32(value) * a


def circle(c: np.ndarray, r: float, n: int = 32) -> np.ndarray:
    """(n, 2) polygon of a circle of radius r around c (2,)."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.asarray(c) + r * np.stack([np.cos(a), np.sin(a)], axis=1)


def rect(p0: np.ndarray, p1: np.ndarray, w0: float, w1: float | None = None) -> np.ndarray:
    """(4, 2) quad along p0 -> p1, width w0 at p0 and w1 at p1 (m)."""
    w1 = w0 if w1 is None else w1
    d = np.asarray(p1, float) - np.asarray(p0, float)
    n = np.array([-d[1], d[0]]) / max(np.hypot(*d), 1e-12)
    return np.array([p0 + n * w0 / 2, p1 + n * w1 / 2, p1 - n * w1 / 2, p0 - n * w0 / 2])


def px_per_m(H: np.ndarray) -> float:
    """Mean pixels per metre of a plane -> image homography (at its origin)."""
    return float(np.linalg.norm(H[:2, :2], axis=0).mean() / H[2, 2])
