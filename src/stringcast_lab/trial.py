"""One execution in the virtual lab, written exactly as docs/data_contract.md.

:func:`run_trial` plays a commanded joint trajectory on the simulated arm and
string (:mod:`.physics` or :mod:`.rod`, as ``lab.physics`` says), films it with the simulated high-speed camera
(:mod:`.camera`, :mod:`.scene`) and writes the video (``lab.video``, :mod:`.encode`: by
default ``video.mkv``, FFV1, 8-bit mono), ``video.yaml``, ``joints.csv`` and the ground truth
that only tests and benchmarks read (``ground_truth.parquet`` / ``.json``).
:func:`~.calib_clip.write_calibration_clip` films the ChArUco board for intrinsics.

Clocks: the joint log's controller clock is the master. The camera is triggered
at a random 20-80 ms after t = 0; frame k's exposure is centred on
t_trigger + k / fps; ``video.yaml`` states the trigger time off by
U(+-lab.trigger_error_s) + lab.trigger_offset_s, as a real trigger line is (or not at all
with ``lab.trigger_written: false``). Recording stops at the end of the log (the last
whole exposure). ``lab.joint_log: at_motion_start`` writes only the log's rows from the
motion's start on (a logger started with the motion; the arm still rests, filmed, before it).

``lab.render: false`` (the loop benchmark's state mode, ``benchmarks/loop_state.py``) films
nothing: no video is rendered or encoded, but the camera's clock is drawn exactly as when
filming (the same trigger for the same seed), so ``video.yaml`` (without ``file``) and
``ground_truth.parquet`` hold the frames the camera would have taken, and
``ground_truth.json`` says ``video.rendered: false``.
"""
from __future__ import annotations

import math
import time
from pathlib import Path
from collections.abc import Mapping

import numpy as np

from stringcast.core import Campaign, ConfigError, atomic_path, write_joint_table, write_json, write_yaml
from .background import gain_map, render_background
from .camera import CameraModel, IdealCanvas, Sensor, camera_settings
from .encode import CODECS, FFV1Writer, open_writer, video_settings
from .look import scene_look
from .mjcf import StringPhysics
from .physics import simulate
from .recording import command_arrays
from .rod import simulate_rod
from .scene import FrameRenderer, StringLook
from .settings import PHYSICS, LabSettings
from .truth import physics_truth, verdict, write_points

__all__ = ["FFV1Writer", "build_renderer", "motion_end", "run_trial", "string_bands"]

TRIGGER_DELAY_S = (0.02, 0.08)


def _lab(config: Mapping) -> LabSettings:
    return LabSettings.from_config(config)


def _fps(campaign: Campaign) -> float:
    cam = campaign.setup.camera
    if "fps" not in cam:
        raise ConfigError(f"setup {campaign.setup.name}: camera has no fps")
    return float(cam["fps"])


def lab_physics(lab: LabSettings | Mapping):
    """The simulate function ``lab.physics`` names: ``mujoco`` (default, :func:`.physics.simulate`,
    the capsule chain) or ``elastica`` (:func:`.rod.simulate_rod`, the Cosserat rod; PyElastica is
    imported when it builds a rod); both take
    (phys, arm, t_cmd, q_cmd, timestep, servo_lag_s, settle_s, progress) and return a Recording.

    Raises:
        ConfigError: any other value (``lab``: the settings, or the ``lab:`` mapping).
    """
    name = (lab if isinstance(lab, LabSettings) else LabSettings.from_config({"lab": lab})).physics
    if name == "mujoco":
        return simulate
    if name == "elastica":
        return simulate_rod
    raise ConfigError(f"lab.physics = {name!r}: expected one of {list(PHYSICS)}")


def string_bands(config: Mapping, n_points: int, phys: StringPhysics) -> dict:
    """``lab.string_bands`` as :meth:`StringLook.from_physics` keywords ({} without bands).

    Bands are sleeves of tape ``width_mm`` long (default 8), of ``reflectance`` in [0, 1]
    (default 0.45: lighter than the cord's 0.10, darker than the wall's 0.62) and
    ``diameter_mm`` (default the cord's), centred at the model's mass points i L / n, i = 1..n
    (the tip's covers the string's last half band width).

    Raises:
        ConfigError: unknown keys or values out of range.
    """
    bands = _lab(config).string_bands
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
    scene_seed = _lab(config).scene_seed
    scene = scene_look(config)
    cam = CameraModel.from_config(campaign.setup.camera, config)
    canvas = IdealCanvas.for_camera(cam)
    sensor = Sensor(cam, camera_settings(config))
    gain = gain_map(cam, sensor, scene_seed)
    bg = render_background(cam, canvas, campaign, scene_seed, look=scene)
    look = StringLook.from_physics(phys, **string_bands(config, campaign.string.n_points, phys))
    return FrameRenderer(cam, canvas, sensor, bg, gain, campaign.arm, look, scene)


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

    Writes into ``out_dir``: the video (``video.mkv``, or ``video.avi`` / ``video.mp4`` for
    ``lab.video.codec`` mjpeg / h264), ``video.yaml``, ``joints.csv`` (``t_s, q1_rad..
    measured, q1_cmd_rad.. commanded``; from the motion's start on with ``lab.joint_log:
    at_motion_start``), ``ground_truth.parquet`` (``frame, t_s, point, x_m, y_m``: the n + 1
    points at arc i L / n at each exposure centre, true times) and ``ground_truth.json``; with
    ``lab.render: false`` no video (module doc).

    Returns:
        The ground_truth.json dict (hit, closest_approach_mm, ..., video: the codec written).

    Raises:
        ValueError: bad shapes or times; DataError: the video cannot be written;
        ConfigError: bad ``lab`` settings; FloatingPointError: the physics diverged.
    """
    wall0 = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    arm = campaign.arm
    t_cmd, q_cmd = command_arrays(t_cmd, q_cmd, arm.n_joints, "run_trial")
    lab = _lab(config)
    render = lab.render
    video = video_settings(config)
    ss = np.random.SeedSequence(int(seed))
    rng_trig, rng_joint, rng_noise = (np.random.default_rng(s) for s in ss.spawn(3))
    Sensor.seed(int(rng_noise.integers(2 ** 31)))

    # -- physics ---------------------------------------------------------------
    phys = StringPhysics.from_campaign(campaign, config)
    lpp = lab.links_per_point
    rec = lab_physics(lab)(phys, arm, t_cmd, q_cmd, lab.timestep_s, lab.servo_lag_s, lab.settle_s, progress=True)
    wall_physics = time.perf_counter() - wall0
    log_start = _write_joint_log(out_dir / "joints.csv", rec, t_cmd, q_cmd, lab, rng_joint, motion_start_s,
                                 arm.controller_rate)

    # -- camera ------------------------------------------------------------------
    wall1 = time.perf_counter()
    renderer = build_renderer(campaign, config, phys) if render else None
    cam = renderer.cam if render else CameraModel.from_config(campaign.setup.camera, config)
    fps = _fps(campaign)
    exposure, t_trigger, t_trigger_written, n_frames = _frame_clock(camera_settings(config), fps, float(rec.t[-1]),
                                                                    lab, rng_trig)
    n = campaign.string.n_points
    name = "video" + CODECS[video["codec"]] if render else None
    t_frames = t_trigger + np.arange(n_frames) / fps            # the exposure centres, s
    size_mb, written = _film(out_dir / name, video, renderer, rec, t_frames, exposure, fps) if render else (0.0, None)
    gt_rows = _truth_rows(rec, t_frames, n, lpp)
    wall_render = time.perf_counter() - wall1

    meta = ({"file": name} if render else {}) | {"fps": fps, "frames": n_frames}
    if t_trigger_written is not None:
        meta["trigger_time_s"] = round(t_trigger_written, 9)
    write_yaml(out_dir / "video.yaml", {**meta, "width_px": cam.width, "height_px": cam.height, "bit_depth": 8})
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
    truth["video"] = {**video, "file": name, "codec_written": written, "rendered": render}
    truth["joint_log_start_s"] = log_start
    write_json(out_dir / "ground_truth.json", truth)
    return truth


def _truth_rows(rec, t_frames: np.ndarray, n: int, lpp: int) -> list:
    """Ground-truth rows at the exposure centres ``t_frames`` (F,) s, filmed or not: per frame
    (frame, t_s, point, x_m, y_m), each (n + 1,): the string's n + 1 points, every ``lpp``-th link end."""
    pts = rec.at(np.asarray(t_frames, float))[:, ::lpp][:, : n + 1]
    return [(np.full(n + 1, k), np.full(n + 1, tc), np.arange(n + 1), p[:, 0], p[:, 1])
            for k, (tc, p) in enumerate(zip(t_frames, pts))]


def _write_joint_log(path: Path, rec, t_cmd: np.ndarray, q_cmd: np.ndarray, lab: LabSettings,
                     rng_joint: np.random.Generator, motion_start_s: float, rate: float) -> float:
    """Write ``joints.csv``: the arm's true joints at t_cmd (K,) s plus N(0, lab.joint_noise_rad) noise,
    and the commands q_cmd (K, J) rad; with ``lab.joint_log: at_motion_start`` only the rows from
    ``motion_start_s`` on (half a controller period's tolerance). Returns the log's first time, s.

    """
    mode = lab.joint_log
    q_true = rec.arm_at(t_cmd)
    q_meas = q_true + rng_joint.normal(0, lab.joint_noise_rad, q_true.shape)
    keep = (t_cmd >= motion_start_s - 0.5 / rate) if mode == "at_motion_start" else np.ones(len(t_cmd), bool)
    write_joint_table(path, t_cmd[keep], q_meas[keep],
                      {f"q{j + 1}_cmd_rad": q_cmd[keep, j] for j in range(q_cmd.shape[1])})
    return float(t_cmd[keep][0])


def _frame_clock(settings: Mapping, fps: float, t_end: float, lab: LabSettings,
                 rng_trig: np.random.Generator) -> tuple[float, float, float | None, int]:
    """The camera's clock: exposure s, the true trigger time s (U(TRIGGER_DELAY_S), frame 0's
    exposure centre), the trigger time video.yaml states (off by U(+-lab.trigger_error_s) +
    lab.trigger_offset_s; None with ``lab.trigger_written: false``) and the number of whole
    exposures before the log ends at ``t_end`` s. Two draws from ``rng_trig``, always.

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
    trigger_error = lab.trigger_error_s
    t_trigger_written = t_trigger + float(rng_trig.uniform(-trigger_error, trigger_error))
    t_trigger_written += lab.trigger_offset_s
    if not lab.trigger_written:
        t_trigger_written = None
    return exposure, t_trigger, t_trigger_written, n_frames


def _film(path: Path, video: Mapping, renderer: FrameRenderer, rec, t_frames: np.ndarray,
          exposure: float, fps: float) -> tuple[float, str]:
    """Render and write the video (``video``: :func:`~.encode.video_settings`) of the simulation
    ``rec``: an exposure centred on each of ``t_frames`` (F,) s.

    Returns the video's size, MB, and the codec written (:func:`~.encode.open_writer`).
    """
    from tqdm import tqdm

    with atomic_path(path) as tmp:
        writer, written = open_writer(tmp, video, fps, renderer.cam.width, renderer.cam.height)
        with writer:
            for tc in tqdm(t_frames, desc="lab frames", unit="frame", disable=None, leave=False):
                m = renderer.n_sub(rec.at(np.array([tc - exposure / 2, tc + exposure / 2])))
                sub_t = tc + exposure * ((np.arange(m) + 0.5) / m - 0.5)
                writer.write(renderer.render(rec.at(sub_t), rec.arm_at(sub_t), renderer.sensor.light(tc, exposure)))
        size_mb = tmp.stat().st_size / 1e6
    return size_mb, written
