"""The lab's ChArUco calibration shots: :func:`write_calibration_clip` films the set-up's board in
varied 3D poses with the trial camera (same intrinsics, distortion, light, sensor, colour).

``lab.calibration`` describes the set (every key optional; the defaults are the default lab's
set of 30):

* ``shots``: how many (a call's ``n_frames`` overrides it);
* ``tilt_deg``: [min, max], the board's tilt out of the image plane about a random in-plane
  axis (default [10, 40]);
* ``board_span``: [min, max], the board's long side as a share of the image's short side
  (default [0.45, 0.85]: large; about [0.3, 0.45] is a small board, whose markers still decode);
* ``region``: [u0, v0, u1, v1], the part of the image (shares of width and height) that every
  board corner must fall in (default [0, 0, 1, 1]): a weak set that covers only part of the
  image, as a hurried user's does.
"""
from __future__ import annotations

import math
from pathlib import Path
from collections.abc import Mapping

import cv2
import numpy as np

from stringcast.core import Campaign, ConfigError, DataError, atomic_path, write_json
from .background import gain_map, render_background, warp_board
from .settings import LabSettings
from .camera import CameraModel, IdealCanvas, Sensor, camera_settings
from .draw import supersample_homography
from .look import scene_look

CALIBRATION_DEFAULTS = {"shots": 30, "tilt_deg": [10.0, 40.0], "board_span": [0.45, 0.85], "region": [0.0, 0.0, 1.0, 1.0]}


def calibration_settings(config: Mapping) -> dict:
    """``lab.calibration`` over :data:`CALIBRATION_DEFAULTS`.

    Raises:
        ConfigError: unknown keys; fewer than 1 shot; tilts outside [0, 80) or min > max; spans
            outside (0, 1] or min > max; a region that is not 0 <= u0 < u1 <= 1, 0 <= v0 < v1 <= 1.
    """
    c = dict(LabSettings.from_config(config).calibration)
    unknown = set(c) - set(CALIBRATION_DEFAULTS)
    if unknown:
        raise ConfigError(f"lab.calibration: unknown keys {sorted(unknown)} (known: {sorted(CALIBRATION_DEFAULTS)})")
    c = {**CALIBRATION_DEFAULTS, **c}
    t, s, r = (np.asarray(c[k], float) for k in ("tilt_deg", "board_span", "region"))
    if (int(c["shots"]) < 1 or t.shape != (2,) or not 0 <= t[0] <= t[1] < 80 or s.shape != (2,)
            or not 0 < s[0] <= s[1] <= 1 or r.shape != (4,) or not (0 <= r[0] < r[2] <= 1 and 0 <= r[1] < r[3] <= 1)):
        raise ConfigError(f"lab.calibration: {c}: expected shots >= 1, tilt_deg [min, max] in [0, 80), "
                          "board_span [min, max] in (0, 1], region [u0, v0, u1, v1] inside [0, 1]")
    return c


def _board_pose(rng: np.random.Generator, cam: CameraModel, board_size: np.ndarray, uv: np.ndarray,
                z: float, tilt_deg: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """A board pose (R, t: board frame -> camera frame) centred on pixel ``uv`` at depth ``z``, tilted
    U(tilt_deg) about a random in-plane axis and rolled U(+-25 deg)."""
    axis = rng.normal(size=2)
    axis = np.array([*(axis / np.linalg.norm(axis)), 0.0]) * math.radians(rng.uniform(*tilt_deg))
    R_tilt = cv2.Rodrigues(axis)[0]
    R_roll = cv2.Rodrigues(np.array([0, 0, math.radians(rng.uniform(-25, 25))]))[0]
    R = R_tilt @ R_roll
    ray = np.linalg.inv(cam.K) @ np.array([uv[0], uv[1], 1.0])
    P = ray / ray[2] * z
    t = P - R @ np.array([board_size[0] / 2, board_size[1] / 2, 0.0])
    return R, t


def _pose_for_shot(i: int, n: int, rng: np.random.Generator, cam: CameraModel, size: np.ndarray,
                   calib: Mapping, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shot i's board pose: centred in grid cell ``cells[i]`` of a 3x3 grid over the region (the first
    nine), then anywhere in it; every corner inside the region (8 px in from the image's edge).
    After 500 tries that do not fit (a large, steeply tilted board near a corner), the board's
    span shrinks by 10 % every 100 tries.

    Raises:
        RuntimeError: no pose fits in 1500 tries.
    """
    corners = np.array([[0, 0, 0], [size[0], 0, 0], [size[0], size[1], 0], [0, size[1], 0]], float)
    img_size = np.array([cam.width, cam.height], float)
    u0, v0, u1, v1 = (float(x) for x in calib["region"])
    lo, span = np.array([u0, v0]), np.array([u1 - u0, v1 - v0])
    box_lo = np.maximum(lo * img_size, 8)
    box_hi = np.minimum((lo + span) * img_size, img_size - 1) - 8
    short = min(cam.width, cam.height)
    for attempt in range(1500):
        shrink = 0.9 ** ((attempt - 400) // 100) if attempt >= 500 else 1.0
        if i < min(n, 9):
            cell = np.array([cells[i] % 3, cells[i] // 3]) + rng.uniform(0.15, 0.85, 2)
            uv = (lo + cell / 3 * span) * img_size
        else:
            uv = (lo + rng.uniform(0.1, 0.9, 2) * span) * img_size
        z = cam.K[0, 0] * size.max() / (rng.uniform(*calib["board_span"]) * short * shrink)
        R, t = _board_pose(rng, cam, size, uv, z, tuple(calib["tilt_deg"]))
        img_c, _ = cv2.projectPoints(corners, cv2.Rodrigues(R)[0], t, cam.K, cam.dist)
        img_c = img_c.reshape(-1, 2)
        if (np.all(img_c >= box_lo) and np.all(img_c <= box_hi)
                and np.all((R @ corners.T + t[:, None])[2] > 0.1)):
            return R, t
    raise RuntimeError("write_calibration_clip: no board pose fits the image; check lab.camera and lab.calibration")


def write_calibration_clip(campaign: Campaign, config: Mapping, out_dir: str | Path, seed: int,
                           n_frames: int | None = None) -> Path:
    """Film the set-up's ChArUco board in varied 3D poses with the lab camera, for intrinsics.

    Poses (``lab.calibration``, module doc): board centre on a 3x3 grid of positions over the
    region (then random ones; fewer than nine shots take a random subset of the cells), at a
    depth where the board's long side spans ``board_span`` of the image's short side, tilted
    ``tilt_deg`` about a random in-plane axis and rolled +-25 deg; every board corner stays
    inside the region. Same intrinsics, distortion, light, sensor and colour as the trials.

    Args:
        n_frames: the number of shots; None: ``lab.calibration.shots`` (default 30).

    Writes ``out_dir/board_XX.png`` (8-bit mono, or BGR for a colour camera) and
    ``out_dir/ground_truth.json`` (camera truth, each view's rvec/tvec). Returns ``out_dir``.

    Raises:
        ConfigError: bad ``lab.calibration``. RuntimeError: no pose fits. DataError: PNG encoding failed.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    calib = calibration_settings(config)
    n = int(calib["shots"] if n_frames is None else n_frames)
    rng = np.random.default_rng(int(seed) + 7919)
    Sensor.seed(int(seed) + 7919)
    scene_seed = LabSettings.from_config(config).scene_seed
    look = scene_look(config)
    cam = CameraModel.from_config(campaign.setup.camera, config)
    canvas = IdealCanvas.for_camera(cam)
    sensor = Sensor(cam, camera_settings(config))
    gain = gain_map(cam, sensor, scene_seed)
    bg = render_background(cam, canvas, campaign, scene_seed, board=False, target=False, look=look)
    board = campaign.setup.board
    size = np.array([board.squares_x, board.squares_y]) * board.square
    bg2 = cv2.resize(bg, (canvas.width * 2, canvas.height * 2), interpolation=cv2.INTER_LINEAR)
    cells = np.arange(9) if n >= 9 else rng.permutation(9)[:n]
    views = []
    for i in range(n):
        R, t = _pose_for_shot(i, n, rng, cam, size, calib, cells)
        H = supersample_homography(canvas.K @ np.column_stack([R[:, 0], R[:, 1], t]), 2)
        ss_img = bg2.copy()
        warp_board(ss_img, board, H)
        ideal = cv2.resize(ss_img, (canvas.width, canvas.height), interpolation=cv2.INTER_AREA)
        dn = canvas.distort(sensor.blur(ideal)) * (gain[..., None] if look.colour else gain)
        ok, buf = cv2.imencode(".png", sensor.expose(dn))
        if not ok:
            raise DataError(f"{out_dir}: PNG encoding failed")
        with atomic_path(out_dir / f"board_{i:02d}.png") as tmp:
            tmp.write_bytes(buf.tobytes())
        views.append({"file": f"board_{i:02d}.png", "rvec": cv2.Rodrigues(R)[0].ravel(), "tvec": t})
    write_json(out_dir / "ground_truth.json", {"camera": cam.truth(), "views": views, "seed": int(seed),
                                               "calibration": calib})
    return out_dir
