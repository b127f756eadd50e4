"""Geometry for drawing a lab set-up (:mod:`.randomize`): a camera view that keeps the swing
region in the image, and a board pose in the swing plane clear of the arm at rest.

Both work on the lab camera itself (:class:`~.camera.CameraModel`, ``cv2.projectPoints`` with
the drawn distortion), so what they guarantee holds for the frames the lab renders.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from .camera import CameraModel

# The world the draw assumes: the project's default arm (UR5e planar, base at the origin, table
# top at y = -0.75 m) and its planner's start box for the grasp (motion.start_grasp_box_mm:
# x -0.2..0.9 m, y -0.1..0.7 m).
SWING_REGION_M = ((-0.30, 1.40), (-0.74, 0.92))
"""(x, y) ranges, m, that every drawn view keeps inside the image: the start box, the longest
string (0.61 m) hanging from it down to the table's edge, and the reach of a cast to x = 1.4 m."""
ARM_REST_ZONES_M = (((-0.45, 1.10), (-0.20, 0.95)), ((-0.15, 0.15), (-0.75, 0.0)), ((1.10, 1.50), (0.25, 0.85)))
"""Plane boxes ((x0, x1), (y0, y1)), m, that the drawn board avoids: the arm at rest (a grasp in
the start box, links above the base), its pedestal, and the config's targets (x 1.15-1.45 m,
y 0.3-0.8 m), which the lab draws on the wall too."""
FLOOR_Y_M = -0.75


def region_outline(region=SWING_REGION_M, per_edge: int = 12) -> np.ndarray:
    """(4 per_edge, 2) points along the border of the box ((x0, x1), (y0, y1)), m."""
    (x0, x1), (y0, y1) = region
    t = np.linspace(0, 1, per_edge, endpoint=False)
    return np.concatenate([np.column_stack([x0 + (x1 - x0) * t, np.full_like(t, y0)]),
                           np.column_stack([np.full_like(t, x1), y0 + (y1 - y0) * t]),
                           np.column_stack([x1 - (x1 - x0) * t, np.full_like(t, y1)]),
                           np.column_stack([np.full_like(t, x0), y1 - (y1 - y0) * t])])


def camera(lens: dict, size: tuple[int, int], focal: float, center: np.ndarray) -> CameraModel:
    """The lab camera of ``lens`` (``lab.camera`` keys: principal_offset_px, dist_coeffs, tilt_deg,
    roll_deg, distance_mm) with ``focal`` px, looking at ``center`` (2,) m."""
    settings = {**lens, "focal_px": float(focal), "center_mm": [float(c) * 1000 for c in center]}
    return CameraModel.from_config({"width_px": size[0], "height_px": size[1]}, {"lab": {"camera": settings}})


def _inside(px: np.ndarray, size: tuple[int, int], margin: float) -> bool:
    w, h = size
    return bool(np.all(px[:, 0] >= margin * w) and np.all(px[:, 0] <= (1 - margin) * w - 1)
                and np.all(px[:, 1] >= margin * h) and np.all(px[:, 1] <= (1 - margin) * h - 1))


def _centred(lens: dict, size: tuple[int, int], focal: float, pts: np.ndarray) -> np.ndarray:
    """The plane point (2,) m to aim at so that ``pts``' image is centred in the image (4 Newton-like
    steps: a pixel shift becomes a plane shift of distance / focal, image y pointing down)."""
    center = pts.mean(axis=0)
    scale = float(lens["distance_mm"]) / 1000 / focal
    for _ in range(4):
        px = camera(lens, size, focal, center).project(pts)
        off = (px.min(axis=0) + px.max(axis=0)) / 2 - (np.asarray(size) - 1) / 2
        center = center + np.array([off[0], -off[1]]) * scale
    return center


def fit_view(lens: dict, size: tuple[int, int], fill: float, shift: np.ndarray, margin: float = 0.02
             ) -> tuple[float, np.ndarray]:
    """Focal length (px) and aim point (2,) m so that :data:`SWING_REGION_M` stays in the image.

    The largest focal length at which the region, centred, fits inside the image less ``margin``
    (a share of each side) is found by bisection; ``fill`` (0, 1] of it is used, and the aim moves
    by ``shift`` (2,) in [-1, 1] of the slack left on each axis (halved until the region fits).

    Raises:
        RuntimeError: the region fits at no focal length (a lens that folds the image).
    """
    pts = region_outline()
    lo, hi = 300.0, 20000.0         # 300 px: a 1280 px image sees +-65 deg, the plane fills it
    if not _inside(camera(lens, size, lo, _centred(lens, size, lo, pts)).project(pts), size, margin):
        raise RuntimeError("fit_view: the swing region fits at no focal length")
    for _ in range(40):
        mid = math.sqrt(lo * hi)
        ok = _inside(camera(lens, size, mid, _centred(lens, size, mid, pts)).project(pts), size, margin)
        lo, hi = (mid, hi) if ok else (lo, mid)
    focal = lo * float(fill)
    center = _centred(lens, size, focal, pts)
    px = camera(lens, size, focal, center).project(pts)
    slack = ((1 - 2 * margin) * np.asarray(size) - (px.max(axis=0) - px.min(axis=0))) / 2
    step = np.asarray(shift, float) * np.maximum(slack, 0) * float(lens["distance_mm"]) / 1000 / focal
    for _ in range(8):
        cand = center - np.array([step[0], -step[1]])
        if _inside(camera(lens, size, focal, cand).project(pts), size, margin):
            return focal, cand
        step = step / 2
    return focal, center


def board_corners(origin: np.ndarray, angle_deg: float, size: tuple[float, float], pad: float) -> np.ndarray:
    """(4, 2) plane corners, m, of a board hung upright (``board_flip_y``: its y axis along -y of the
    robot, turned by ``angle_deg`` about +z) with its (0, 0) corner at ``origin`` (2,) m, size (w, h)
    m, grown by ``pad`` m on each side (the paper around the print). The transform is
    :class:`stringcast.core.SetupSpec`'s ``board_to_robot``."""
    a = math.radians(angle_deg)
    T = np.array([[math.cos(a), math.sin(a)], [math.sin(a), -math.cos(a)]])
    w, h = size
    local = np.array([[-pad, -pad], [w + pad, -pad], [w + pad, h + pad], [-pad, h + pad]])
    return np.asarray(origin, float) + local @ T.T


def _overlaps(poly: np.ndarray, box) -> bool:
    (x0, x1), (y0, y1) = box
    rect = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], np.float32)
    area, _ = cv2.intersectConvexConvex(poly.astype(np.float32), rect)
    return area > 1e-9


def place_board(rng: np.random.Generator, cam: CameraModel, size: tuple[float, float], pad: float,
                max_angle_deg: float = 12.0, margin: float = 0.03, tries: int = 4000) -> tuple[np.ndarray, float]:
    """A board pose (origin (2,) m, angle deg) in the swing plane: all of it (with its paper) in the
    image less ``margin``, above the table, clear of :data:`ARM_REST_ZONES_M`; centre uniform over
    the plane box the image sees, angle U(+-max_angle_deg).

    Raises:
        RuntimeError: no pose found in ``tries`` draws.
    """
    seen = np.linalg.inv(cam.plane_homography())
    c = np.array([[0, 0, 1], [cam.width, 0, 1], [cam.width, cam.height, 1], [0, cam.height, 1]], float) @ seen.T
    c = c[:, :2] / c[:, 2:]
    lo, hi = c.min(axis=0), c.max(axis=0)
    for _ in range(tries):
        centre = rng.uniform(lo, hi)
        angle = float(rng.uniform(-max_angle_deg, max_angle_deg))
        origin = centre - (board_corners(np.zeros(2), angle, size, 0.0)[2]) / 2
        poly = board_corners(origin, angle, size, pad)
        if (poly[:, 1].min() > FLOOR_Y_M + 0.01 and _inside(cam.project(poly), (cam.width, cam.height), margin)
                and not any(_overlaps(poly, z) for z in ARM_REST_ZONES_M)):
            return origin, angle
    raise RuntimeError("place_board: no board pose in view clear of the arm's rest zone")
