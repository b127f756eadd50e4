"""What the lab camera sees: wall, clutter, table, arm base, ChArUco board, target,
the arm and the string; and the per-frame renderer with motion blur.

Everything is drawn as *reflectance* in [0, 1] on the camera's ideal (undistorted)
canvas (:class:`~stringcast.lab.camera.IdealCanvas`), through the plane
homography of the swing plane (so circles in the plane become the right
ellipses). OpenCV anti-aliases only 8-bit images, so each shape is drawn as an 8-bit coverage
mask (``LINE_AA``, sub-pixel ``shift`` bits) and composited: R <- R (1 - a) + r_shape a. The
static background is rendered once per trial at 2x and area-averaged. The string (cord ~3 mm, clay lumps ~16 mm,
pipes ~8 mm) is drawn at 4x in a box around it and area-averaged, so its width
is right to a small fraction of a pixel. It is dark on a lighter wall but the
tracker must not key on its grey level: the board's black squares, the clutter
(a dark cable too) and the arm are as dark.

Motion blur: each frame averages ``m`` sub-exposure renders over the exposure time, m such that
no point moves more than ~0.7 px between two. The arm is drawn in front of the string.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from stringcast.core import ArmSpec, BoardSpec, Campaign, forward_kinematics
from .camera import CameraModel, IdealCanvas, Sensor, apply_homography

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


def _fix(p: np.ndarray) -> np.ndarray:
    """(N, 2) float pixel coordinates -> int32 with ``SHIFT`` fractional bits."""
    return np.round(np.asarray(p) * ONE).astype(np.int32).reshape(-1, 1, 2)


def _composite(img: np.ndarray, mask: np.ndarray, value: float, scale: float = 1 / 255) -> None:
    """In place: img <- img (1 - a) + value a, a = mask * scale."""
    a = mask.astype(np.float32) * np.float32(scale)
    img *= 1 - a
    img += np.float32(value) * a


def _circle(c: np.ndarray, r: float, n: int = 32) -> np.ndarray:
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.asarray(c) + r * np.stack([np.cos(a), np.sin(a)], axis=1)


def _rect(p0: np.ndarray, p1: np.ndarray, w0: float, w1: float | None = None) -> np.ndarray:
    """(4, 2) quad along p0 -> p1, width w0 at p0 and w1 at p1 (m)."""
    w1 = w0 if w1 is None else w1
    d = np.asarray(p1, float) - np.asarray(p0, float)
    n = np.array([-d[1], d[0]]) / max(np.hypot(*d), 1e-12)
    return np.array([p0 + n * w0 / 2, p1 + n * w1 / 2, p1 - n * w1 / 2, p0 - n * w0 / 2])


def board_image(board: BoardSpec, px_per_square: int, margin_squares: float = 0.5
                ) -> tuple[np.ndarray, np.ndarray]:
    """The printed ChArUco board on white paper, as reflectance.

    Uses ``CharucoBoard.generateImage`` (marginSize 0); paper adds ``margin_squares``
    around it.

    Returns:
        img: (H, W) float32 reflectance; M: (3, 3) homography from image pixels
        (integer pixel centres) to board-frame metres (OpenCV board frame).
    """
    cb = board.make()
    w, h = board.squares_x * px_per_square, board.squares_y * px_per_square
    core = cb.generateImage((w, h), marginSize=0, borderBits=1)
    m = int(round(margin_squares * px_per_square))
    img = np.full((h + 2 * m, w + 2 * m), 255, np.uint8)
    img[m:m + h, m:m + w] = core
    refl = REFLECTANCE["ink"] + (REFLECTANCE["paper"] - REFLECTANCE["ink"]) * img.astype(np.float32) / 255
    s = board.square / px_per_square
    M = np.array([[s, 0, (0.5 - m) * s], [0, s, (0.5 - m) * s], [0, 0, 1.0]])
    return refl, M


def warp_board(dst: np.ndarray, board: BoardSpec, H_board_to_dst: np.ndarray) -> None:
    """Draw the board (in place) into a reflectance image through a board-metres -> pixel homography."""
    # about 2 source pixels per destination pixel along the board
    scale = np.linalg.norm(H_board_to_dst[:2, :2], axis=0).max() / max(H_board_to_dst[2, 2], 1e-9)
    pps = int(np.clip(2 * scale * board.square, 16, 400))
    img, M = board_image(board, pps)
    H = H_board_to_dst @ M
    h, w = img.shape
    corners = apply_homography(H, np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]]))
    x0, y0 = np.maximum(np.floor(corners.min(axis=0)).astype(int) - 2, 0)
    x1, y1 = np.minimum(np.ceil(corners.max(axis=0)).astype(int) + 3, [dst.shape[1], dst.shape[0]])
    if x1 <= x0 or y1 <= y0:
        return
    T = np.array([[1, 0, -x0], [0, 1, -y0], [0, 0, 1.0]]) @ H
    warped = cv2.warpPerspective(img, T, (x1 - x0, y1 - y0), flags=cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)
    mask = np.zeros((h, w), np.uint8)
    mask[:] = 255
    cov = cv2.warpPerspective(mask, T, (x1 - x0, y1 - y0), flags=cv2.INTER_LINEAR)
    a = cov.astype(np.float32) / 255
    roi = dst[y0:y1, x0:x1]
    roi *= 1 - a
    roi += np.where(warped >= 0, warped, 0) * a


def gain_map(cam: CameraModel, sensor: Sensor, seed: int) -> np.ndarray:
    """(H, W) float32 DN per unit reflectance: uneven light (gradient + a soft hot spot) x vignetting,
    scaled by the sensor's ``light_level``."""
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.linspace(-1, 1, cam.width, dtype=np.float32),
                       np.linspace(-1, 1, cam.height, dtype=np.float32))
    gx, gy = rng.uniform(-0.08, 0.08, 2)
    cx, cy = rng.uniform(-0.6, 0.6, 2)
    light = 0.86 + gx * u + gy * v + 0.1 * np.exp(-((u - cx) ** 2 + (v - cy) ** 2) / 0.5)
    level = 255 * LEVEL * sensor.light_level          # lab.camera.light_level: dim light
    return (level * light / light.max() * sensor.vignette).astype(np.float32)


def render_background(cam: CameraModel, canvas: IdealCanvas, campaign: Campaign, seed: int,
                      board: bool = True, target: bool = True) -> np.ndarray:
    """Static scene reflectance on the ideal canvas: (canvas.height, canvas.width) float32.

    Wall with low-frequency texture, a few clutter shapes and a dark cable
    (placed by ``seed``, the same for every trial of a lab), the table below
    ``arm.floor_y``, the arm's pedestal, the ChArUco board at
    ``setup.board_to_robot`` and the target disc.
    """
    rng = np.random.default_rng(seed)
    s = BG_SS
    W, Hh = canvas.width * s, canvas.height * s
    H = supersample_homography(cam.plane_homography(canvas.K), s)
    tex = rng.normal(0, 0.03, (9, 9)).astype(np.float32)
    img = REFLECTANCE["wall"] + cv2.resize(tex, (W, Hh), interpolation=cv2.INTER_CUBIC)
    mask = np.zeros((Hh, W), np.uint8)

    def fill(poly_world: np.ndarray, value: float) -> None:
        mask[:] = 0
        cv2.fillPoly(mask, [_fix(apply_homography(H, poly_world))], 255, cv2.LINE_AA, SHIFT)
        _composite(img, mask, value)

    # clutter in the field of view (world metres, on the wall behind the plane)
    corners = canvas_corners_world(cam, canvas)
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    for _ in range(int(rng.integers(3, 6))):
        c = rng.uniform(lo, hi)
        w, h = rng.uniform(0.08, 0.35, 2)
        fill(_rect(c - [w / 2, 0], c + [w / 2, 0], h), float(rng.uniform(0.3, 0.85)))
    for _ in range(int(rng.integers(1, 3))):
        fill(_circle(rng.uniform(lo, hi), float(rng.uniform(0.04, 0.12))), float(rng.uniform(0.35, 0.8)))
    # a hanging cable: a smooth dark curve (a distractor that looks like a string)
    p0 = np.array([rng.uniform(lo[0], hi[0]), hi[1] + 0.05])
    ctrl = p0 + np.array([[0, 0], [rng.uniform(-0.2, 0.2), -0.4], [rng.uniform(-0.3, 0.3), -0.8],
                          [rng.uniform(-0.3, 0.3), -(hi[1] - lo[1]) * 0.6]])
    tt = np.linspace(0, 1, 80)[:, None]
    curve = ((1 - tt) ** 3 * ctrl[0] + 3 * (1 - tt) ** 2 * tt * ctrl[1] + 3 * (1 - tt) * tt ** 2 * ctrl[2]
             + tt ** 3 * ctrl[3])
    mask[:] = 0
    thick = max(1, int(round(0.006 * _px_per_m(H))))
    cv2.polylines(mask, [_fix(apply_homography(H, curve))], False, 255, thick, cv2.LINE_AA, SHIFT)
    _composite(img, mask, REFLECTANCE["cable"])
    # table below the floor line, its lit top edge, and the arm's pedestal
    fy = campaign.arm.floor_y
    far = 10.0
    fill(np.array([[-far, fy], [far, fy], [far, fy - far], [-far, fy - far]]), REFLECTANCE["table"])
    fill(_rect(np.array([-far, fy - 0.006]), np.array([far, fy - 0.006]), 0.012), REFLECTANCE["table_edge"])
    fill(np.array([[-0.08, -0.06], [0.08, -0.06], [0.1, fy], [-0.1, fy]]), REFLECTANCE["pedestal"])
    if board:
        warp_board(img, campaign.setup.board, H @ campaign.setup.board_to_robot)
    if target:
        tg = campaign.target
        fill(_circle(tg.xy, tg.radius, 48), REFLECTANCE["target"])
        mask[:] = 0
        cv2.fillPoly(mask, [_fix(apply_homography(H, _circle(tg.xy, tg.radius * 0.6, 48)))], 255, cv2.LINE_AA, SHIFT)
        cv2.fillPoly(mask, [_fix(apply_homography(H, _circle(tg.xy, tg.radius * 0.4, 48)))], 0, cv2.LINE_AA, SHIFT)
        _composite(img, mask, REFLECTANCE["target_ring"])
    return cv2.resize(img, (canvas.width, canvas.height), interpolation=cv2.INTER_AREA)


def _px_per_m(H: np.ndarray) -> float:
    return float(np.linalg.norm(H[:2, :2], axis=0).mean() / H[2, 2])


def canvas_corners_world(cam: CameraModel, canvas: IdealCanvas) -> np.ndarray:
    """(4, 2) swing-plane points seen at the canvas corners, m."""
    Hinv = np.linalg.inv(cam.plane_homography(canvas.K))
    c = np.array([[0, 0], [canvas.width, 0], [canvas.width, canvas.height], [0, canvas.height]], float)
    return apply_homography(Hinv, c)


def arm_shapes(arm: ArmSpec, q: np.ndarray) -> list[tuple[np.ndarray, str]]:
    """Convex polygons (world m) of the arm at joints q (J,), back to front, with reflectance names."""
    pts = forward_kinematics(arm, q)            # base, joints..., grasp
    J = arm.n_joints
    shapes = []
    for j in range(J):
        w = ARM_WIDTHS_M[min(j, len(ARM_WIDTHS_M) - 1)]
        shapes.append((_rect(pts[j], pts[j + 1], w), "link"))
    shapes.append((_rect(pts[J], pts[J + 1], *GRIPPER_WIDTH_M), "gripper"))
    for j in range(J + 1):
        shapes.append((_circle(pts[j], JOINT_RADII_M[min(j, len(JOINT_RADII_M) - 1)], 24), "joint"))
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
                     band_reflectance: float = 0.0) -> "StringLook":
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
    cv2.polylines(mask, [_fix(look.span(q, a + h, b - h))], False, 255, width_px, cv2.LINE_AA, SHIFT)
    for end, inner in ((a, a + h), (b, b - h)):
        e, p = look.along(q, np.array([end, inner]))
        t = e - p
        n = float(np.hypot(*t))
        if n > 1e-9:
            side = np.array([-t[1], t[0]]) / n * (width_px / 2)
            cv2.fillConvexPoly(mask, _fix(np.array([p + side, e + side, e - side, p - side])), 255,
                               cv2.LINE_AA, SHIFT)


class FrameRenderer:
    """Renders camera frames of the lab (static background once, dynamic parts per frame).

    Args:
        cam, canvas, sensor: the camera model, its ideal canvas and sensor.
        background: (canvas.height, canvas.width) float32 reflectance (sharp).
        gain: (H, W) float32 DN per unit reflectance (:func:`gain_map`).
        arm: the arm; look: the string's :class:`StringLook`.
    """

    def __init__(self, cam: CameraModel, canvas: IdealCanvas, sensor: Sensor, background: np.ndarray,
                 gain: np.ndarray, arm: ArmSpec, look: StringLook):
        self.cam, self.canvas, self.sensor = cam, canvas, sensor
        self.background = background
        self.gain = gain
        self.bg_dn = canvas.distort(sensor.blur(background)) * gain
        self.arm, self.look = arm, look
        self.H = cam.plane_homography(canvas.K)
        self.px_per_m = _px_per_m(self.H)
        self.margin = int(math.ceil(3 * sensor.blur_sigma)) + 3

    def n_sub(self, sites: np.ndarray) -> int:
        """Sub-exposures needed so points move < 0.7 px between them; sites (m0, S, 2)."""
        if len(sites) < 2:
            return 1
        d = np.linalg.norm(sites[-1] - sites[0], axis=-1).max() * self.px_per_m
        return int(np.clip(math.ceil(d / 0.7), 1, MAX_SUB))

    def render(self, sites: np.ndarray, q_arm: np.ndarray, light: float = 1.0) -> np.ndarray:
        """One frame: sites (m, S, 2) world m and q_arm (m, J) rad at m sub-exposure times -> (H, W) uint8.

        ``light``: the frame's relative illumination (:meth:`Sensor.light`). Noise from
        :meth:`Sensor.expose` (seed it with :meth:`Sensor.seed`).
        """
        dn = self.dynamic_dn(sites, q_arm)
        if light != 1.0:
            dn *= np.float32(light)
        return self.sensor.expose(dn)

    def dynamic_dn(self, sites: np.ndarray, q_arm: np.ndarray) -> np.ndarray:
        """Noise-free DN image (H, W) float32 of one frame (see :meth:`render`)."""
        m = len(sites)
        px = [apply_homography(self.H, s) for s in sites]
        arm_px = [[(apply_homography(self.H, p), name) for p, name in arm_shapes(self.arm, q)] for q in q_arm]
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
        out[y0:y1, x0:x1] = self.canvas.distort(crop, iroi, (int(c0[0]), int(c0[1]))) * self.gain[y0:y1, x0:x1]
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
                    cv2.fillConvexPoly(mask, _fix(_circle(c, d / 2 * self.px_per_m * s, 40)), 255,
                                       cv2.LINE_AA, SHIFT)
                acc["clay"] += mask
        sub = crop[lo[1]:hi[1], lo[0]:hi[0]]
        for name in names:                              # area-average 4x -> 1x, then composite
            a = cv2.resize(acc[name].astype(np.float32), (hi[0] - lo[0], hi[1] - lo[1]),
                           interpolation=cv2.INTER_AREA)
            _composite(sub, a, self.look.band_reflectance if name == "band" else REFLECTANCE[name], 1 / (255 * m))

    def _draw_arm(self, crop: np.ndarray, shapes_per_sub: list, m: int) -> None:
        h, w = crop.shape
        names = ("link", "gripper", "joint")
        acc = {n: np.zeros((h, w), np.uint16) for n in names}
        mask = np.zeros((h, w), np.uint8)
        for shapes in shapes_per_sub:
            for n in names:
                mask[:] = 0
                for poly, name in shapes:
                    if name == n:
                        cv2.fillConvexPoly(mask, _fix(poly), 255, cv2.LINE_AA, SHIFT)
                acc[n] += mask
        for n in names:
            _composite(crop, acc[n], REFLECTANCE[n], 1 / (255 * m))
