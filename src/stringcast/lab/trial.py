"""One execution in the virtual lab, written exactly as docs/data_contract.md.

:func:`run_trial` plays a commanded joint trajectory on the simulated arm and
string (:mod:`.physics`), films it with the simulated high-speed camera
(:mod:`.camera`, :mod:`.scene`) and writes ``video.mkv`` (FFV1, 8-bit mono),
``video.yaml``, ``joints.csv`` and the ground truth that only tests and
benchmarks read (``ground_truth.parquet`` / ``.json``).
:func:`write_calibration_clip` films the ChArUco board in varied 3D poses with the
same camera, for intrinsics.

Clocks: the joint log's controller clock is the master. The camera is triggered
at a random 20-80 ms after t = 0; frame k's exposure is centred on
t_trigger + k / fps; ``video.yaml`` states the trigger time off by
U(+-lab.trigger_error_s), as a real trigger line is. Recording stops at the end
of the log (the last whole exposure).
"""
from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Mapping

import cv2
import numpy as np

from stringcast.core import Campaign, ConfigError, DataError, atomic_path, write_joint_table, write_json, write_yaml
from .camera import CameraModel, IdealCanvas, Sensor, camera_settings
from .mjcf import StringPhysics
from .physics import simulate
from .scene import (FrameRenderer, StringLook, gain_map, render_background, supersample_homography,
                    warp_board)
from .truth import physics_truth, verdict, write_points

TRIGGER_DELAY_S = (0.02, 0.08)


def _lab(config: Mapping) -> dict:
    return dict(config.get("lab", {}) or {})


def _fps(campaign: Campaign) -> float:
    cam = campaign.setup.camera
    if "fps" not in cam:
        raise ConfigError(f"setup {campaign.setup.name}: camera has no fps")
    return float(cam["fps"])


def _scene(campaign: Campaign, config: Mapping, scene_seed: int, with_target: bool = True,
           with_board: bool = True):
    """Camera settings, model, ideal canvas, sensor, gain map and static background reflectance."""
    settings = camera_settings(config)
    cam = CameraModel.from_config(campaign.setup.camera, config)
    canvas = IdealCanvas.for_camera(cam)
    sensor = Sensor(cam, settings)
    gain = gain_map(cam, sensor, scene_seed)
    bg = render_background(cam, canvas, campaign, scene_seed, board=with_board, target=with_target)
    return settings, cam, canvas, sensor, gain, bg


class FFV1Writer:
    """``cv2.VideoWriter`` (FFV1, 8-bit mono) fed from a background thread.

    FFV1 encoding costs about as much as rendering a frame; OpenCV releases the
    GIL while encoding, so a second thread overlaps the two. Use as a context
    manager; :meth:`close` waits for the queue and re-raises a writer error.

    Raises:
        DataError: OpenCV cannot open an FFV1 writer for ``path``.
    """

    def __init__(self, path: Path, fps: float, width: int, height: int, queue_size: int = 8):
        import queue
        import threading

        self.path = Path(path)
        self._w = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"FFV1"), fps, (width, height),
                                  isColor=False)
        if not self._w.isOpened():
            raise DataError(f"{path}: OpenCV cannot open an FFV1 writer")
        self._q: "queue.Queue" = queue.Queue(queue_size)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        self.frames = 0

    def _run(self) -> None:
        while True:
            frame = self._q.get()
            if frame is None:
                break
            if self._error is None:
                try:
                    self._w.write(frame)
                except BaseException as exc:  # keep draining; reported in close()
                    self._error = exc

    def write(self, frame: np.ndarray) -> None:
        """Queue one (H, W) uint8 frame."""
        if self._error is not None:
            raise DataError(f"{self.path}: writing a frame failed: {self._error}")
        self._q.put(frame)
        self.frames += 1

    def close(self) -> None:
        if self._thread.is_alive():
            self._q.put(None)
            self._thread.join()
        self._w.release()
        if self._error is not None:
            raise DataError(f"{self.path}: writing a frame failed: {self._error}")

    def __enter__(self) -> "FFV1Writer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def string_bands(config: Mapping, n_points: int, phys: StringPhysics) -> dict:
    """``lab.string_bands`` as :meth:`StringLook.from_physics` keywords ({} without bands).

    Bands are sleeves of tape ``width_mm`` long (default 8), of ``reflectance`` in [0, 1]
    (default 0.45: lighter than the cord's 0.10, darker than the wall's 0.62) and
    ``diameter_mm`` (default the cord's), centred at the model's mass points i L / n, i = 1..n
    (the tip's covers the string's last half band width).

    Raises:
        ConfigError: unknown keys or values out of range.
    """
    bands = _lab(config).get("string_bands")
    if not bands:
        return {}
    bands = dict(bands)
    unknown = set(bands) - {"width_mm", "reflectance", "diameter_mm"}
    w, refl = float(bands.get("width_mm", 8.0)) / 1000, float(bands.get("reflectance", 0.45))
    d = float(bands.get("diameter_mm", phys.diameter * 1000)) / 1000
    if unknown or not (w > 0 and 0 <= refl <= 1 and d > 0 and n_points >= 1):
        raise ConfigError(f"lab.string_bands: {bands} (keys width_mm > 0, reflectance in [0, 1], diameter_mm > 0)")
    L = phys.length
    spans = tuple((max(0.0, c - w / 2), min(L, c + w / 2)) for c in np.arange(1, n_points + 1) * L / n_points)
    return {"bands": spans, "band_diameter": d, "band_reflectance": refl}


def build_renderer(campaign: Campaign, config: Mapping, phys: StringPhysics | None = None) -> FrameRenderer:
    """The trial camera's :class:`FrameRenderer` (same scene, light and camera as :func:`run_trial`)."""
    phys = phys or StringPhysics.from_campaign(campaign, config)
    _, cam, canvas, sensor, gain, bg = _scene(campaign, config, int(_lab(config).get("scene_seed", 11)))
    look = StringLook.from_physics(phys, **string_bands(config, campaign.string.n_points, phys))
    return FrameRenderer(cam, canvas, sensor, bg, gain, campaign.arm, look)


def motion_end(t_cmd: np.ndarray, q_cmd: np.ndarray) -> float:
    """Controller time at which the commanded motion reaches its final hold, s."""
    moving = np.nonzero(np.any(np.abs(q_cmd - q_cmd[-1]) > 1e-12, axis=1))[0]
    return float(t_cmd[min(len(t_cmd) - 1, moving[-1] + 1)]) if len(moving) else float(t_cmd[0])


def run_trial(t_cmd: np.ndarray, q_cmd: np.ndarray, campaign: Campaign, config: Mapping,
              out_dir: str | Path, seed: int, motion_start_s: float) -> dict:
    """Play a commanded joint trajectory in the lab and record the trial's raw files.

    Args:
        t_cmd: (K,) controller times from 0 at ``arm.controller_rate``, s.
        q_cmd: (K, J) commanded joint angles, rad (pre- and post-roll holds included).
        campaign: string, target, arm and set-up; config: the loaded config (``lab`` section).
        out_dir: the trial folder (created). seed: all randomness of this trial.
        motion_start_s: when the motion leaves the pre-roll hold (start of the hit window).

    Writes into ``out_dir``: ``video.mkv``, ``video.yaml``, ``joints.csv``
    (``t_s, q1_rad.. measured, q1_cmd_rad.. commanded``), ``ground_truth.parquet``
    (``frame, t_s, point, x_m, y_m``: the n + 1 points at arc i L / n at each
    exposure centre, true times) and ``ground_truth.json``.

    Returns:
        The ground_truth.json dict (hit, closest_approach_mm, ...).

    Raises:
        ValueError: bad shapes or times; DataError: the video cannot be written;
        FloatingPointError: the physics diverged.
    """
    wall0 = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    arm = campaign.arm
    t_cmd, q_cmd = _checked_command(t_cmd, q_cmd, arm.n_joints)
    lab = _lab(config)
    ss = np.random.SeedSequence(int(seed))
    rng_trig, rng_joint, rng_noise = (np.random.default_rng(s) for s in ss.spawn(3))
    Sensor.seed(int(rng_noise.integers(2 ** 31)))

    # -- physics ---------------------------------------------------------------
    phys = StringPhysics.from_campaign(campaign, config)
    lpp = int(lab.get("links_per_point", 3))
    rec = simulate(phys, arm, t_cmd, q_cmd, float(lab.get("timestep_s", 5e-5)),
                   float(lab.get("servo_lag_s", 0.008)), float(lab.get("settle_s", 0.3)), progress=True)
    wall_physics = time.perf_counter() - wall0

    # -- joint log ----------------------------------------------------------------
    q_true = rec.arm_at(t_cmd)
    q_meas = q_true + rng_joint.normal(0, float(lab.get("joint_noise_rad", 2e-4)), q_true.shape)
    write_joint_table(out_dir / "joints.csv", t_cmd, q_meas,
                      {f"q{j + 1}_cmd_rad": q_cmd[:, j] for j in range(arm.n_joints)})

    # -- camera ------------------------------------------------------------------
    wall1 = time.perf_counter()
    settings = camera_settings(config)
    renderer = build_renderer(campaign, config, phys)
    cam = renderer.cam
    fps = _fps(campaign)
    exposure, t_trigger, t_trigger_written, n_frames = _frame_clock(settings, fps, float(rec.t[-1]), lab, rng_trig)
    n = campaign.string.n_points
    gt_rows, size_mb = _film(out_dir / "video.mkv", renderer, rec, t_trigger, n_frames, exposure, fps, n, lpp)
    wall_render = time.perf_counter() - wall1

    write_yaml(out_dir / "video.yaml", {
        "file": "video.mkv", "fps": fps, "frames": n_frames, "trigger_time_s": round(t_trigger_written, 9),
        "width_px": cam.width, "height_px": cam.height, "bit_depth": 8})
    write_points(out_dir / "ground_truth.parquet", gt_rows)

    # -- verdict -------------------------------------------------------------------
    truth = {
        **verdict(rec, campaign, config, motion_start_s, motion_end(t_cmd, q_cmd)),
        "trigger_time_s": t_trigger,
        "trigger_time_written_s": t_trigger_written,
        "exposure_s": exposure,
        "fps": fps,
        "frames": n_frames,
        "n_points": n,
        "camera": cam.truth(),
        **physics_truth(rec, phys),
        "video_mb": size_mb,
        "video_mb_per_frame": size_mb / n_frames,
        "wall_s": {"physics": wall_physics, "render": wall_render, "total": time.perf_counter() - wall0},
        "seed": int(seed),
    }
    write_json(out_dir / "ground_truth.json", truth)
    return truth


def _checked_command(t_cmd: np.ndarray, q_cmd: np.ndarray, n_joints: int) -> tuple[np.ndarray, np.ndarray]:
    """t_cmd (K,) s and q_cmd (K, J) rad as float arrays, checked.

    Raises:
        ValueError: t_cmd not (K,) strictly increasing with K >= 2, or q_cmd not (K, n_joints).
    """
    t_cmd = np.asarray(t_cmd, float)
    q_cmd = np.asarray(q_cmd, float)
    if t_cmd.ndim != 1 or len(t_cmd) < 2 or np.any(np.diff(t_cmd) <= 0):
        raise ValueError("run_trial: t_cmd must be (K,) strictly increasing, K >= 2")
    if q_cmd.shape != (len(t_cmd), n_joints):
        raise ValueError(f"run_trial: q_cmd must be ({len(t_cmd)}, {n_joints}), got {q_cmd.shape}")
    return t_cmd, q_cmd


def _frame_clock(settings: Mapping, fps: float, t_end: float, lab: dict,
                 rng_trig: np.random.Generator) -> tuple[float, float, float, int]:
    """The camera's clock: exposure s, the true trigger time s (U(TRIGGER_DELAY_S), frame 0's
    exposure centre), the trigger time video.yaml states (off by U(+-lab.trigger_error_s)) and the
    number of whole exposures before the log ends at ``t_end`` s. Two draws from ``rng_trig``.

    Raises:
        ConfigError: an exposure not within (0, 1/fps). ValueError: a log shorter than the trigger delay.
    """
    exposure = float(settings["exposure_s"])
    if not 0 < exposure < 1 / fps:
        raise ConfigError(f"lab.camera.exposure_s = {exposure} must be within (0, 1/fps = {1 / fps:.6g})")
    t_trigger = float(rng_trig.uniform(*TRIGGER_DELAY_S))
    n_frames = int(math.floor((t_end - exposure / 2 - t_trigger) * fps + 1e-9)) + 1
    if n_frames < 1:
        raise ValueError(f"run_trial: the log ({t_end:.3f} s) is shorter than the camera's trigger delay")
    trigger_error = float(lab.get("trigger_error_s", 0.002))
    t_trigger_written = t_trigger + float(rng_trig.uniform(-trigger_error, trigger_error))
    return exposure, t_trigger, t_trigger_written, n_frames


def _film(path: Path, renderer: FrameRenderer, rec, t_trigger: float, n_frames: int, exposure: float, fps: float,
          n: int, lpp: int) -> tuple[list, float]:
    """Render and write the video (FFV1) of the simulation ``rec``: n_frames exposures centred on
    t_trigger + k / fps, s.

    Returns the ground-truth rows (per frame: frame, t_s, point, x_m, y_m, each (n + 1,): the string's
    n + 1 points, every ``lpp``-th link end, at the exposure centre) and the video's size, MB.
    """
    t_frames = t_trigger + np.arange(n_frames) / fps
    gt_rows = []
    from tqdm import tqdm

    with atomic_path(path) as tmp, FFV1Writer(tmp, fps, renderer.cam.width, renderer.cam.height) as writer:
        for k, tc in enumerate(tqdm(t_frames, desc="lab frames", unit="frame", disable=None, leave=False)):
            m = renderer.n_sub(rec.at(np.array([tc - exposure / 2, tc + exposure / 2])))
            sub_t = tc + exposure * ((np.arange(m) + 0.5) / m - 0.5)
            writer.write(renderer.render(rec.at(sub_t), rec.arm_at(sub_t), renderer.sensor.light(tc, exposure)))
            pts = rec.at(np.array([tc]))[0][::lpp][: n + 1]
            gt_rows.append((np.full(n + 1, k), np.full(n + 1, tc), np.arange(n + 1), pts[:, 0], pts[:, 1]))
        writer.close()
        size_mb = tmp.stat().st_size / 1e6
    return gt_rows, size_mb


def _board_pose(rng: np.random.Generator, cam: CameraModel, board_size: np.ndarray, uv: np.ndarray,
                z: float, max_tilt_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """A board pose (R, t: board frame -> camera frame) centred on pixel ``uv`` at depth ``z``."""
    axis = rng.normal(size=2)
    axis = np.array([*(axis / np.linalg.norm(axis)), 0.0]) * math.radians(rng.uniform(10, max_tilt_deg))
    R_tilt = cv2.Rodrigues(axis)[0]
    R_roll = cv2.Rodrigues(np.array([0, 0, math.radians(rng.uniform(-25, 25))]))[0]
    R = R_tilt @ R_roll
    ray = np.linalg.inv(cam.K) @ np.array([uv[0], uv[1], 1.0])
    P = ray / ray[2] * z
    t = P - R @ np.array([board_size[0] / 2, board_size[1] / 2, 0.0])
    return R, t


def write_calibration_clip(campaign: Campaign, config: Mapping, out_dir: str | Path, seed: int,
                           n_frames: int = 30) -> Path:
    """Film the set-up's ChArUco board in varied 3D poses with the lab camera, for intrinsics.

    Poses: board centre on a 3x3 grid of image positions (then random ones), at
    a depth where the board's long side spans 45-85 % of the image, tilted 10-40 deg
    about a random in-plane axis and rolled +-25 deg; every board corner stays
    inside the image. Same intrinsics, distortion, light and sensor as the trials.

    Writes ``out_dir/board_XX.png`` (8-bit mono) and ``out_dir/ground_truth.json``
    (camera truth, each view's rvec/tvec). Returns ``out_dir``.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(int(seed) + 7919)
    Sensor.seed(int(seed) + 7919)
    lab = _lab(config)
    scene_seed = int(lab.get("scene_seed", 11))
    settings, cam, canvas, sensor, gain, bg = _scene(campaign, config, scene_seed, with_target=False,
                                                     with_board=False)
    board = campaign.setup.board
    size = np.array([board.squares_x, board.squares_y]) * board.square
    corners = np.array([[0, 0, 0], [size[0], 0, 0], [size[0], size[1], 0], [0, size[1], 0]], float)
    bg2 = cv2.resize(bg, (canvas.width * 2, canvas.height * 2), interpolation=cv2.INTER_LINEAR)
    views = []
    for i in range(n_frames):
        for _ in range(500):
            if i < 9:
                cell = np.array([i % 3, i // 3]) + rng.uniform(0.15, 0.85, 2)
                uv = cell / 3 * [cam.width, cam.height]
            else:
                uv = rng.uniform(0.1, 0.9, 2) * [cam.width, cam.height]
            z = cam.K[0, 0] * size.max() / (rng.uniform(0.45, 0.85) * min(cam.width, cam.height))
            R, t = _board_pose(rng, cam, size, uv, z, 40.0)
            img_c, _ = cv2.projectPoints(corners, cv2.Rodrigues(R)[0], t, cam.K, cam.dist)
            img_c = img_c.reshape(-1, 2)
            if (img_c.min() >= 8 and np.all(img_c.max(axis=0) <= [cam.width - 9, cam.height - 9])
                    and np.all((R @ corners.T + t[:, None])[2] > 0.1)):
                break
        else:
            raise RuntimeError("write_calibration_clip: no board pose fits the image; check lab.camera")
        H = supersample_homography(canvas.K @ np.column_stack([R[:, 0], R[:, 1], t]), 2)
        ss_img = bg2.copy()
        warp_board(ss_img, board, H)
        ideal = cv2.resize(ss_img, (canvas.width, canvas.height), interpolation=cv2.INTER_AREA)
        dn = canvas.distort(sensor.blur(ideal)) * gain
        frame = sensor.expose(dn)
        ok, buf = cv2.imencode(".png", frame)
        if not ok:
            raise DataError(f"{out_dir}: PNG encoding failed")
        with atomic_path(out_dir / f"board_{i:02d}.png") as tmp:
            tmp.write_bytes(buf.tobytes())
        views.append({"file": f"board_{i:02d}.png", "rvec": cv2.Rodrigues(R)[0].ravel(), "tvec": t})
    write_json(out_dir / "ground_truth.json", {"camera": cam.truth(), "views": views, "seed": int(seed)})
    return out_dir
