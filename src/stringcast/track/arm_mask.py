"""The robot arm's outline in the image: a binary mask from forward kinematics in pixels.

Used by :mod:`stringcast.track.tracking` (the string is never searched under the arm) and its
background (:mod:`stringcast.track.background`). Polygons drawn with ``cv2.fillConvexPoly`` and
``cv2.circle`` at 1/16 px (fixed-point ``shift``).
"""
from __future__ import annotations

import cv2
import numpy as np

from stringcast.core import ArmSpec, TrackingSettings


def _quad(p0, p1, w0, w1):
    d = np.asarray(p1, float) - p0
    n = np.array([-d[1], d[0]]) / max(np.hypot(*d), 1e-9) / 2
    return np.array([p0 + n * w0, p1 + n * w1, p1 - n * w1, p0 - n * w0])


def draw_arm_mask(shape, poses_px, arm: ArmSpec, st: TrackingSettings, m_per_px: float, offset=(0, 0),
                  grow_px: float = 0.0) -> np.ndarray:
    """Binary mask (H, W) bool of the arm at one or more poses (their union).

    The outline is the arm's (:class:`~stringcast.core.ArmSpec`, m): ``link_widths`` (per link),
    ``joint_radii`` (discs at the base and each joint), ``gripper_widths`` (at the wrist, at
    the fingertips; the gripper's quadrilateral ends ``gripper_mask_extend`` past the grasp
    point, square), each grown by the tracking settings' ``arm_mask_margin_px`` (``st``,
    :class:`~stringcast.core.TrackingSettings`) + ``grow_px``.

    Args:
        poses_px: (J + 2, 2) or (P, J + 2, 2) base, joints and grasp point in px; several
            poses (the start, middle and end of a frame period) cover motion blur.
        m_per_px: image scale. offset: (x0, y0) of the mask's origin in the image (ROI).
    """
    m = np.zeros(shape, np.uint8)
    poses = np.asarray(poses_px, float).reshape(-1, *np.shape(poses_px)[-2:])
    grow = st.arm_mask_margin_px + grow_px
    def px(v):
        return v / m_per_px   # m -> px
    links, radii = arm.link_widths, arm.joint_radii
    gw = [px(w) + 2 * grow for w in arm.gripper_widths]
    sh = 4  # fixed-point bits for sub-pixel polygons
    def fix(v):
        return np.round(np.asarray(v) * 2 ** sh).astype(np.int32)
    for pose in poses:
        p = pose - offset
        J = len(p) - 2
        d = p[-1] - p[-2]
        tip = p[-1] + d / max(np.hypot(*d), 1e-9) * px(arm.gripper_mask_extend)
        for j in range(J):
            w = px(links[min(j, len(links) - 1)]) + 2 * grow
            cv2.fillConvexPoly(m, fix(_quad(p[j], p[j + 1], w, w)), 1, cv2.LINE_8, sh)
        cv2.fillConvexPoly(m, fix(_quad(p[J], tip, gw[0], gw[-1])), 1, cv2.LINE_8, sh)
        for j in range(J + 1):
            r = px(radii[min(j, len(radii) - 1)]) + grow
            cv2.circle(m, tuple(int(v) for v in fix(p[j])), round(r * 2 ** sh), 1, -1, cv2.LINE_8, sh)
    return m.astype(bool)


def near_arm(p: np.ndarray, arm: np.ndarray, reach: float) -> bool:
    """Whether the guarded arm mask ``arm`` (h, w) has a pixel within ``reach`` px of p (row, col)."""
    r = int(np.ceil(reach))
    r0, c0 = max(0, int(p[0]) - r), max(0, int(p[1]) - r)
    rr, cc = np.nonzero(arm[r0:int(p[0]) + r + 1, c0:int(p[1]) + r + 1])
    return bool(len(rr)) and bool(np.any(np.hypot(rr + r0 - p[0], cc + c0 - p[1]) <= reach))
