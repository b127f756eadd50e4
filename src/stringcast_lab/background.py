"""The lab's static scene as the camera sees it: wall (plain, blotchy or cluttered), table, the
arm's pedestal, the ChArUco board and the target, as reflectance on the camera's ideal canvas
(mono (H, W) or colour (H, W, 3) BGR, :mod:`.look`), and the uneven light over the image.

Rendered once per trial at 2x and area-averaged, through the plane homography of the
swing plane (so circles in the plane become the right ellipses).
"""
from __future__ import annotations

import cv2
import numpy as np

from stringcast.core import BoardSpec, Campaign
from .camera import CameraModel, IdealCanvas, Sensor, apply_homography
from .draw import BG_SS, LEVEL, REFLECTANCE, SHIFT, circle, composite, fix, px_per_m, rect, supersample_homography
from .look import LUMA_BGR, SceneLook, hue_tint


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
    """Draw the board (in place) into a reflectance image (H, W) or (H, W, 3) (grey paper and ink)
    through a board-metres -> pixel homography."""
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
    paper = np.where(warped >= 0, warped, 0)
    if dst.ndim == 3:
        a, paper = a[..., None], paper[..., None]
    roi = dst[y0:y1, x0:x1]
    roi *= 1 - a
    roi += paper * a


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


def canvas_corners_world(cam: CameraModel, canvas: IdealCanvas) -> np.ndarray:
    """(4, 2) swing-plane points seen at the canvas corners, m."""
    Hinv = np.linalg.inv(cam.plane_homography(canvas.K))
    c = np.array([[0, 0], [canvas.width, 0], [canvas.width, canvas.height], [0, canvas.height]], float)
    return apply_homography(Hinv, c)


def _wall(shape: tuple[int, int], tex: np.ndarray, look: SceneLook, lo: np.ndarray, hi: np.ndarray,
          seed: int) -> np.ndarray:
    """The wall's reflectance (H, W) or (H, W, 3): its value plus the low-frequency texture ``tex``
    (and, ``blotchy``, blotches of ``look.blotch_mm`` over the plane box lo..hi m)."""
    Hh, W = shape
    grey = cv2.resize(tex, (W, Hh), interpolation=cv2.INTER_CUBIC)
    if look.background == "blotchy":
        n = np.maximum(np.ceil((hi - lo) / (look.blotch_mm / 1000)).astype(int), 2) + 1
        blot = np.random.default_rng([int(seed), 2]).normal(0, look.blotch_contrast, (n[1], n[0]))
        grey = grey + cv2.resize(blot.astype(np.float32), (W, Hh), interpolation=cv2.INTER_CUBIC)
    wall = look.value("wall")
    if not look.colour:
        return wall + grey
    w0 = float(LUMA_BGR @ np.asarray(wall, float))     # the wall's grey reflectance (tints have luma 1)
    return np.asarray(wall, np.float32) * (1 + grey / np.float32(w0))[..., None]


def _clutter(fill, mask: np.ndarray, H: np.ndarray, rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray,
             look: SceneLook, seed: int) -> np.ndarray:
    """Boxes, discs (random shades; random tints from their own generator in colour) and a hanging
    cable: a smooth dark curve, a distractor that looks like a string. Returns the cable's mask."""
    tints = np.random.default_rng([int(seed), 3])
    tint = (lambda: hue_tint(tints.random(), tints.uniform(0, 0.5))) if look.colour else (lambda: None)
    for _ in range(int(rng.integers(3, 6))):
        c = rng.uniform(lo, hi)
        w, h = rng.uniform(0.08, 0.35, 2)
        fill(rect(c - [w / 2, 0], c + [w / 2, 0], h), look.shade(float(rng.uniform(0.3, 0.85)), tint()))
    for _ in range(int(rng.integers(1, 3))):
        fill(circle(rng.uniform(lo, hi), float(rng.uniform(0.04, 0.12))), look.shade(float(rng.uniform(0.35, 0.8)), tint()))
    p0 = np.array([rng.uniform(lo[0], hi[0]), hi[1] + 0.05])
    ctrl = p0 + np.array([[0, 0], [rng.uniform(-0.2, 0.2), -0.4], [rng.uniform(-0.3, 0.3), -0.8],
                          [rng.uniform(-0.3, 0.3), -(hi[1] - lo[1]) * 0.6]])
    tt = np.linspace(0, 1, 80)[:, None]
    curve = ((1 - tt) ** 3 * ctrl[0] + 3 * (1 - tt) ** 2 * tt * ctrl[1] + 3 * (1 - tt) * tt ** 2 * ctrl[2]
             + tt ** 3 * ctrl[3])
    mask[:] = 0
    thick = max(1, int(round(0.006 * px_per_m(H))))
    cv2.polylines(mask, [fix(apply_homography(H, curve))], False, 255, thick, cv2.LINE_AA, SHIFT)
    return mask


def render_background(cam: CameraModel, canvas: IdealCanvas, campaign: Campaign, seed: int,
                      board: bool = True, target: bool = True, look: SceneLook | None = None) -> np.ndarray:
    """Static scene reflectance on the ideal canvas: (canvas.height, canvas.width) float32, or
    (..., 3) BGR for a colour ``look`` (:class:`~.look.SceneLook`; None: the default, mono, cluttered).

    Wall with low-frequency texture (``blotchy``: and blotches), for ``clutter`` a few shapes and
    a dark cable (placed by ``seed``, the same for every trial of a lab), the table below
    ``arm.floor_y``, the arm's pedestal, the ChArUco board at ``setup.board_to_robot`` and the
    target disc.
    """
    look = look or SceneLook()
    rng = np.random.default_rng(seed)
    s = BG_SS
    W, Hh = canvas.width * s, canvas.height * s
    H = supersample_homography(cam.plane_homography(canvas.K), s)
    tex = rng.normal(0, 0.03, (9, 9)).astype(np.float32)
    corners = canvas_corners_world(cam, canvas)
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    img = _wall((Hh, W), tex, look, lo, hi, seed)
    mask = np.zeros((Hh, W), np.uint8)

    def fill(poly_world: np.ndarray, value) -> None:
        mask[:] = 0
        cv2.fillPoly(mask, [fix(apply_homography(H, poly_world))], 255, cv2.LINE_AA, SHIFT)
        composite(img, mask, value)

    if look.background == "clutter":     # clutter in the field of view (world metres, on the wall behind the plane)
        composite(img, _clutter(fill, mask, H, rng, lo, hi, look, seed), look.value("cable"))
    # table below the floor line, its lit top edge, and the arm's pedestal
    fy = campaign.arm.floor_y
    far = 10.0
    fill(np.array([[-far, fy], [far, fy], [far, fy - far], [-far, fy - far]]), look.value("table"))
    fill(rect(np.array([-far, fy - 0.006]), np.array([far, fy - 0.006]), 0.012), look.value("table_edge"))
    fill(np.array([[-0.08, -0.06], [0.08, -0.06], [0.1, fy], [-0.1, fy]]), look.value("pedestal"))
    if board:
        warp_board(img, campaign.setup.board, H @ campaign.setup.board_to_robot)
    if target:
        tg = campaign.target
        fill(circle(tg.xy, tg.radius, 48), look.value("target"))
        mask[:] = 0
        cv2.fillPoly(mask, [fix(apply_homography(H, circle(tg.xy, tg.radius * 0.6, 48)))], 255, cv2.LINE_AA, SHIFT)
        cv2.fillPoly(mask, [fix(apply_homography(H, circle(tg.xy, tg.radius * 0.4, 48)))], 0, cv2.LINE_AA, SHIFT)
        composite(img, mask, look.value("target_ring"))
    return cv2.resize(img, (canvas.width, canvas.height), interpolation=cv2.INTER_AREA)
