"""What the lab camera sees move: the arm and the string, and the per-frame renderer with
motion blur, over the static scene of :mod:`.background` (wall, clutter, table, arm base,
ChArUco board, target).

Everything is drawn as *reflectance* in [0, 1] (mono), or BGR reflectance (colour,
:mod:`.look`), on the camera's ideal (undistorted) canvas
(:class:`~stringcast_lab.camera.IdealCanvas`), through the plane homography of the swing plane
(so circles in the plane become the right ellipses), as anti-aliased coverage masks
composited over the background (:mod:`.draw`). The string (cord ~3 mm, clay lumps ~16 mm,
pipes ~8 mm) is drawn at 4x in a box around it and area-averaged, so its width is right to a
small fraction of a pixel. It is dark on a lighter wall but the tracker must not key on its
grey level: the board's black squares, the clutter (a dark cable too) and the arm are as dark.

Motion blur: each frame averages ``m`` sub-exposure renders over the exposure time, m such that
no point moves more than ~0.7 px between two. The arm is drawn in front of the string.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from stringcast.core import ArmSpec, forward_kinematics
from .background import board_image, canvas_corners_world, gain_map, render_background, warp_board
from .camera import CameraModel, IdealCanvas, Sensor, apply_homography
from .draw import MAX_SUB, SHIFT, STRING_SS, circle, composite, fix, px_per_m, rect, supersample_homography
from .look import ArmLook, SceneLook

__all__ = ["FrameRenderer", "StringLook", "arm_shapes", "board_image", "canvas_corners_world", "gain_map",
           "render_background", "supersample_homography", "warp_board"]


def arm_shapes(arm: ArmSpec, q: np.ndarray, look: ArmLook | None = None) -> list[tuple[np.ndarray, str]]:
    """Convex polygons (world m) of the arm at joints q (J,), back to front, with reflectance names.

    ``look`` (:class:`~.look.ArmLook`, default the default lab's arm) gives the outline; without
    joint discs each joint is a round cap of the link's shade (half the wider adjoining link or
    gripper wide).
    """
    look = look or ArmLook()
    pts = forward_kinematics(arm, q)            # base, joints..., grasp
    J = arm.n_joints
    widths = [look.link_widths[min(j, len(look.link_widths) - 1)] for j in range(J)]
    shapes = [(rect(pts[j], pts[j + 1], widths[j]), "link") for j in range(J)]
    shapes.append((rect(pts[J], pts[J + 1], *look.gripper_widths), "gripper"))
    for j in range(J + 1):
        if look.joint_discs:
            shapes.append((circle(pts[j], look.joint_radii[min(j, len(look.joint_radii) - 1)], 24), "joint"))
        else:
            near = widths[max(j - 1, 0):j + 1] + ([look.gripper_widths[0]] if j == J else [])
            shapes.append((circle(pts[j], max(near) / 2, 24), "link"))
    return shapes


@dataclass(frozen=True)
class StringLook:
    """How the string looks: cord diameter, site arc positions, clay lumps, pipes, bands (m).

    Bands (``lab.string_bands``, none by default): sleeves of tape of another shade, of the
    cord's diameter unless set, centred at each of the model's mass points i L / n (i = 1..n;
    the tip's covers the last half band width); drawn over the cord, under pipes and clay.
    """

    arc: np.ndarray            # (S,) arc length of each physics site
    diameter: float
    weights: tuple             # ((at, diameter), ...)
    pipes: tuple               # ((from, to, diameter), ...)
    bands: tuple = ()          # ((from, to), ...)
    band_diameter: float = 0.0
    band_reflectance: float = 0.0

    @classmethod
    def from_physics(cls, phys, bands: tuple = (), band_diameter: float = 0.0,
                     band_reflectance: float = 0.0) -> StringLook:
        """The look of the lab string ``phys``, with bands ((from, to), ...) m (:func:`.trial.string_bands`)."""
        arc = np.arange(phys.n_links + 1) * phys.link_length
        return cls(arc, phys.diameter, tuple((a, d) for a, _, d in phys.weights),
                   tuple((a, b, d) for a, b, _, d in phys.pipes), tuple(bands), band_diameter, band_reflectance)

    def along(self, sites: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Points at arc lengths s (K,) on the site polyline (S, 2) -> (K, 2)."""
        return np.stack([np.interp(s, self.arc, sites[:, 0]), np.interp(s, self.arc, sites[:, 1])], axis=1)

    def span(self, sites: np.ndarray, a: float, b: float) -> np.ndarray:
        inner = self.arc[(self.arc > a) & (self.arc < b)]
        return self.along(sites, np.concatenate([[a], inner, [b]]))


def _flat_ended(mask: np.ndarray, look: StringLook, q: np.ndarray, a: float, b: float, d: float,
                width_px: int) -> None:
    """Draw the string's span from arc a to b (m) on the site polyline q (S, 2) (px) into ``mask``,
    ``width_px`` wide (d in m), with flat ends: a cord or a pipe ends where its ground truth
    does. ``cv2.polylines`` draws round caps, width/2 past each end (4 mm for an 8 mm pipe),
    so the line stops d/2 short of each end and a quad of the full width closes it."""
    h = min(d / 2, (b - a) / 2)
    cv2.polylines(mask, [fix(look.span(q, a + h, b - h))], False, 255, width_px, cv2.LINE_AA, SHIFT)
    for end, inner in ((a, a + h), (b, b - h)):
        e, p = look.along(q, np.array([end, inner]))
        t = e - p
        n = float(np.hypot(*t))
        if n > 1e-9:
            side = np.array([-t[1], t[0]]) / n * (width_px / 2)
            cv2.fillConvexPoly(mask, fix(np.array([p + side, e + side, e - side, p - side])), 255,
                               cv2.LINE_AA, SHIFT)


class FrameRenderer:
    """Renders camera frames of the lab (static background once, dynamic parts per frame).

    Args:
        cam, canvas, sensor: the camera model, its ideal canvas and sensor.
        background: (canvas.height, canvas.width) float32 reflectance (sharp), (..., 3) BGR in colour.
        gain: (H, W) float32 DN per unit reflectance (:func:`gain_map`).
        arm: the arm; look: the string's :class:`StringLook`.
        scene: the scene's :class:`~.look.SceneLook` (mono or colour, shades, the arm's outline);
            None: the default lab's.
    """

    def __init__(self, cam: CameraModel, canvas: IdealCanvas, sensor: Sensor, background: np.ndarray,
                 gain: np.ndarray, arm: ArmSpec, look: StringLook, scene: SceneLook | None = None):
        self.cam, self.canvas, self.sensor = cam, canvas, sensor
        self.scene = scene or SceneLook()
        self.background = background
        self.gain = gain
        self._gain = gain[..., None] if self.scene.colour else gain      # broadcast over B, G, R
        self.bg_dn = canvas.distort(sensor.blur(background)) * self._gain
        self.arm, self.look = arm, look
        self.H = cam.plane_homography(canvas.K)
        self.px_per_m = px_per_m(self.H)
        self.margin = int(math.ceil(3 * sensor.blur_sigma)) + 3

    def n_sub(self, sites: np.ndarray) -> int:
        """Sub-exposures needed so points move < 0.7 px between them; sites (m0, S, 2)."""
        if len(sites) < 2:
            return 1
        d = np.linalg.norm(sites[-1] - sites[0], axis=-1).max() * self.px_per_m
        return int(np.clip(math.ceil(d / 0.7), 1, MAX_SUB))

    def render(self, sites: np.ndarray, q_arm: np.ndarray, light: float = 1.0) -> np.ndarray:
        """One frame: sites (m, S, 2) world m and q_arm (m, J) rad at m sub-exposure times -> (H, W) uint8
        ((H, W, 3) BGR for a colour scene).

        ``light``: the frame's relative illumination (:meth:`Sensor.light`). Noise from
        :meth:`Sensor.expose` (seed it with :meth:`Sensor.seed`).
        """
        dn = self.dynamic_dn(sites, q_arm)
        if light != 1.0:
            dn *= np.float32(light)
        return self.sensor.expose(dn)

    def dynamic_dn(self, sites: np.ndarray, q_arm: np.ndarray) -> np.ndarray:
        """Noise-free DN image (H, W) (or (H, W, 3)) float32 of one frame (see :meth:`render`)."""
        m = len(sites)
        px = [apply_homography(self.H, s) for s in sites]
        arm_px = [[(apply_homography(self.H, p), name) for p, name in arm_shapes(self.arm, q, self.scene.arm)] for q in q_arm]
        allpts = np.concatenate(px + [p for shapes in arm_px for p, _ in shapes])
        pad = self.margin + self.look.diameter * self.px_per_m + 0.02 * self.px_per_m
        box = (*(allpts.min(axis=0) - pad), *(allpts.max(axis=0) + pad))
        out = self.bg_dn.copy()
        cw, ch = self.canvas.width, self.canvas.height
        box = (max(0.0, box[0]), max(0.0, box[1]), min(cw - 1.0, box[2]), min(ch - 1.0, box[3]))
        if box[2] <= box[0] or box[3] <= box[1]:
            return out
        iroi = self.canvas.image_roi(box)
        if iroi is None:
            return out
        x0, y0, x1, y1 = iroi
        mx, my = self.canvas.map_x[y0:y1, x0:x1], self.canvas.map_y[y0:y1, x0:x1]
        c0 = np.maximum(np.floor([mx.min(), my.min()]).astype(int) - self.margin, 0)
        c1 = np.minimum(np.ceil([mx.max(), my.max()]).astype(int) + self.margin + 1, [cw, ch])
        crop = self.background[c0[1]:c1[1], c0[0]:c1[0]].copy()
        self._draw_string(crop, [p - c0 for p in px], m)
        self._draw_arm(crop, [[(p - c0, n) for p, n in shapes] for shapes in arm_px], m)
        crop = self.sensor.blur(crop)
        out[y0:y1, x0:x1] = self.canvas.distort(crop, iroi, (int(c0[0]), int(c0[1]))) * self._gain[y0:y1, x0:x1]
        return out

    def _draw_string(self, crop: np.ndarray, px: list[np.ndarray], m: int) -> None:
        s = STRING_SS
        allp = np.concatenate(px)
        r_max = max([self.look.diameter, self.look.band_diameter] + [d for _, d in self.look.weights]
                    + [d for *_, d in self.look.pipes])
        pad = r_max * self.px_per_m + 2
        lo = np.maximum(np.floor(allp.min(axis=0) - pad).astype(int), 0)
        hi = np.minimum(np.ceil(allp.max(axis=0) + pad).astype(int), [crop.shape[1], crop.shape[0]])
        if np.any(hi <= lo):
            return
        w, h = (hi - lo) * s
        names = (["cord"] + (["band"] if self.look.bands else []) + (["pipe"] if self.look.pipes else [])
                 + (["clay"] if self.look.weights else []))
        acc = {k: np.zeros((h, w), np.uint16) for k in names}  # coverage summed over sub-exposures
        mask = np.zeros((h, w), np.uint8)
        th = max(1, int(round(self.look.diameter * self.px_per_m * s)))
        for p in px:
            q = (p - lo) * s + (s - 1) / 2             # crop px -> supersampled px
            mask[:] = 0
            _flat_ended(mask, self.look, q, 0.0, float(self.look.arc[-1]), self.look.diameter, th)
            acc["cord"] += mask
            if "band" in acc:
                mask[:] = 0
                bw = max(1, int(round(self.look.band_diameter * self.px_per_m * s)))
                for a, b in self.look.bands:
                    _flat_ended(mask, self.look, q, a, b, self.look.band_diameter, bw)
                acc["band"] += mask
            if "pipe" in acc:
                mask[:] = 0
                for a, b, d in self.look.pipes:
                    _flat_ended(mask, self.look, q, a, b, d, max(1, int(round(d * self.px_per_m * s))))
                acc["pipe"] += mask
            if "clay" in acc:
                mask[:] = 0
                for at, d in self.look.weights:
                    c = self.look.along(q, np.array([at]))[0]
                    cv2.fillConvexPoly(mask, fix(circle(c, d / 2 * self.px_per_m * s, 40)), 255,
                                       cv2.LINE_AA, SHIFT)
                acc["clay"] += mask
        sub = crop[lo[1]:hi[1], lo[0]:hi[0]]
        for name in names:                              # area-average 4x -> 1x, then composite
            a = cv2.resize(acc[name].astype(np.float32), (hi[0] - lo[0], hi[1] - lo[1]),
                           interpolation=cv2.INTER_AREA)
            composite(sub, a, self.look.band_reflectance if name == "band" else self.scene.value(name),
                      1 / (255 * m))

    def _draw_arm(self, crop: np.ndarray, shapes_per_sub: list, m: int) -> None:
        h, w = crop.shape[:2]
        names = ("link", "gripper", "joint")
        acc = {n: np.zeros((h, w), np.uint16) for n in names}
        mask = np.zeros((h, w), np.uint8)
        for shapes in shapes_per_sub:
            for n in names:
                mask[:] = 0
                for poly, name in shapes:
                    if name == n:
                        cv2.fillConvexPoly(mask, fix(poly), 255, cv2.LINE_AA, SHIFT)
                acc[n] += mask
        for n in names:
            composite(crop, acc[n], self.scene.value(n), 1 / (255 * m))
