"""The lab as a family of set-ups: :func:`draw_setup` draws one (seeded, reproducible) and
:func:`apply_setup` writes it into a config, so that :func:`~.trial.run_trial` and
:func:`~.calib_clip.write_calibration_clip` film it.

The family (issue 25): resolution 1024x768, 1024x1024 or 1280x1024; mono or colour; FFV1, MJPEG
(quality 75-95) or H.264 (CRF 18-28); 500-2000 fps; a view tilted up to 10 deg, rolled up to 3
deg, from 1.8-4 m, its focal length such that the swing region (:data:`.view.SWING_REGION_M`)
fills 85-97 % of the image's limiting side; principal point off by up to 5 % of the image size;
distortion k1 in [-0.25, 0.1] with k2 = -k1 U(0, 0.5) (a lens whose higher term bends back the
first, never folding the image) and small tangential terms; light level, drift, mains flicker
(100 or 120 Hz), read and shot noise, optics blur, vignetting; a plain, blotchy or cluttered
wall; the board anywhere in view in the swing plane, clear of the arm at rest; the arm's link
widths, shades and joint discs (or none); the calibration set (6-30 shots, tilts from 10 deg up
to 20-45 deg, a large (50-85 % of the image's short side) or small (30-45 %) board, over the
whole image or, one set in five, a band of 40-60 % of it along one side); the trigger (exact,
+-2 ms, 30 ms wrong, absent); the joint log (from before the motion, or from its start).

The pipeline's stages never read a draw: :func:`apply_setup` puts what a user would know (image
size, fps, mono, the board's place, the arm's measured outline) where a user would write it
(``cameras``, ``setups``, ``arms``), and the rest, the hidden truth, into ``lab``.
"""
from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass
from collections.abc import Mapping

import numpy as np

from stringcast.core import ConfigError
from .look import hue_tint
from .view import camera, fit_view, place_board

RESOLUTIONS = ((1024, 768), (1024, 1024), (1280, 1024))
CODECS = ("ffv1", "mjpeg", "h264")
BACKGROUNDS = ("plain", "blotchy", "clutter")
TRIGGERS = ("exact", "jitter", "wrong", "absent")
JOINT_LOGS = ("before_motion", "at_motion_start")
CALIB_BOARDS = ("large", "small")
BOARD_MM = (540.0, 360.0)              # the default set-up's board: 9 x 6 squares of 60 mm
BOARD_PAD_MM = 30.0                    # the paper around the print (half a square)
ARM_MEASURE_MM = (10.0, 5.0, (6.0, 5.0))   # a user's outline: widths, radii, gripper widths beyond the true
DRAWN_CAMERA = "lab_drawn"
_GROUPS = ("sensor", "lens", "view", "light", "scene", "board", "arm", "calib", "clock")


@dataclass(frozen=True)
class Setup:
    """One drawn lab set-up. Lengths in mm, angles in deg, times in s, shades are reflectances.

    Sensor and recording: ``width_px``, ``height_px``, ``colour``, ``codec`` (ffv1 | mjpeg | h264),
    ``mjpeg_quality`` (mjpeg only, else None), ``h264_crf`` (h264 only, else None), ``fps``,
    ``exposure_s``. Lens and view (``lab.camera``): ``focal_px``, ``principal_offset_px`` (x, y),
    ``dist_coeffs`` (k1, k2, p1, p2, k3), ``distance_mm``, ``center_mm`` (x, y: where the optical
    axis meets the swing plane), ``tilt_deg`` (about the camera's x and y axes), ``roll_deg``.
    Light: ``light_level``, ``light_drift_per_s``, ``flicker`` (relative amplitude, 0: none),
    ``flicker_hz``, ``noise_sigma`` (DN), ``shot_gain``, ``blur_sigma_px``, ``vignetting``. Scene:
    ``background`` (plain | blotchy | clutter), ``blotch_mm``, ``blotch_contrast``, ``scene_seed``,
    ``wall_tint``, ``string_tint`` (BGR, luma 1; colour only), ``board_origin_mm``,
    ``board_angle_deg``. Arm: ``link_widths_mm``, ``joint_discs``, ``joint_radii_mm`` (the discs',
    or without discs the round caps'), ``gripper_widths_mm``, ``link_shade``, ``joint_shade``,
    ``gripper_shade``. Calibration set: ``calib_shots``, ``calib_tilt_deg`` (min, max),
    ``calib_board`` (large | small), ``calib_board_span`` (min, max share of the image's short
    side), ``calib_region`` (u0, v0, u1, v1 shares of the image). Clocks: ``trigger`` (exact |
    jitter | wrong | absent), ``trigger_error_s`` (written minus true trigger time; None when
    absent), ``joint_log`` (before_motion | at_motion_start).
    """

    seed: int
    width_px: int
    height_px: int
    colour: bool
    codec: str
    mjpeg_quality: int | None
    h264_crf: int | None
    fps: float
    exposure_s: float
    focal_px: float
    principal_offset_px: tuple
    dist_coeffs: tuple
    distance_mm: float
    center_mm: tuple
    tilt_deg: tuple
    roll_deg: float
    light_level: float
    light_drift_per_s: float
    flicker: float
    flicker_hz: float
    noise_sigma: float
    shot_gain: float
    blur_sigma_px: float
    vignetting: float
    background: str
    blotch_mm: float
    blotch_contrast: float
    scene_seed: int
    wall_tint: tuple
    string_tint: tuple
    board_origin_mm: tuple
    board_angle_deg: float
    link_widths_mm: tuple
    joint_discs: bool
    joint_radii_mm: tuple
    gripper_widths_mm: tuple
    link_shade: float
    joint_shade: float
    gripper_shade: float
    calib_shots: int
    calib_tilt_deg: tuple
    calib_board: str
    calib_board_span: tuple
    calib_region: tuple
    trigger: str
    trigger_error_s: float | None
    joint_log: str

    def as_dict(self) -> dict:
        """The draw as plain JSON-able values (tuples become lists)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()}

    def scaled(self, factor: float) -> Setup:
        """The same view on a sensor ``factor`` times as wide and high (even sizes; focal length and
        principal point offset scaled alike): small frames for fast tests."""
        w, h = (max(16, 2 * int(round(v * factor / 2))) for v in (self.width_px, self.height_px))
        s = w / self.width_px
        return dataclasses.replace(self, width_px=w, height_px=h, focal_px=self.focal_px * s,
                                   principal_offset_px=tuple(v * s for v in self.principal_offset_px))


def _r(x: float, nd: int = 4) -> float:
    return float(round(float(x), nd))


def _sensor(g: np.random.Generator) -> dict:
    w, h = RESOLUTIONS[int(g.integers(len(RESOLUTIONS)))]
    colour = bool(g.random() < 0.5)
    codec = CODECS[int(g.integers(len(CODECS)))]
    quality, crf = int(g.integers(75, 96)), int(g.integers(18, 29))
    fps = float(np.clip(round(g.uniform(500, 2000) / 10) * 10, 500, 2000))
    exposure = min(g.uniform(0.25, 0.7) / fps, 0.0012)      # a share of the frame period, at most 1.2 ms
    return {"width_px": w, "height_px": h, "colour": colour, "codec": codec,
            "mjpeg_quality": quality if codec == "mjpeg" else None, "h264_crf": crf if codec == "h264" else None,
            "fps": fps, "exposure_s": _r(exposure, 7)}


def _lens(g: np.random.Generator, size: tuple[int, int]) -> dict:
    k1 = g.uniform(-0.25, 0.1)
    k2 = -k1 * g.uniform(0.0, 0.5)
    p1, p2 = g.uniform(-5e-4, 5e-4, 2)
    off = g.uniform(-0.05, 0.05, 2) * np.asarray(size)
    return {"principal_offset_px": (_r(off[0], 2), _r(off[1], 2)),
            "dist_coeffs": (_r(k1, 5), _r(k2, 5), _r(p1, 6), _r(p2, 6), 0.0),
            "distance_mm": _r(g.uniform(1800, 4000), 1)}


def _view(g: np.random.Generator, lens: dict, size: tuple[int, int]) -> dict:
    mag, ang = g.uniform(0, 10), g.uniform(0, 2 * np.pi)
    view = {"tilt_deg": (_r(mag * np.cos(ang), 3), _r(mag * np.sin(ang), 3)), "roll_deg": _r(g.uniform(-3, 3), 3)}
    fill, shift = g.uniform(0.85, 0.97), g.uniform(-1, 1, 2)
    focal, center = fit_view({**lens, **view}, size, fill, shift)
    return {**view, "focal_px": _r(focal, 2), "center_mm": (_r(center[0] * 1000, 2), _r(center[1] * 1000, 2))}


def _light(g: np.random.Generator) -> dict:
    flicker = 0.0 if g.random() < 0.4 else g.uniform(0.02, 0.12)
    return {"light_level": _r(g.uniform(0.35, 1.0), 3), "light_drift_per_s": _r(0.0 if g.random() < 0.5 else g.uniform(-0.3, 0.3), 3),
            "flicker": _r(flicker, 4), "flicker_hz": float(g.choice([100.0, 120.0])),
            "noise_sigma": _r(g.uniform(0.6, 2.5), 3), "shot_gain": _r(g.uniform(0.001, 0.006), 5),
            "blur_sigma_px": _r(g.uniform(0.3, 1.0), 3), "vignetting": _r(g.uniform(0.05, 0.4), 3)}


def _scene(g: np.random.Generator) -> dict:
    tint = lambda s0, s1: tuple(_r(v, 4) for v in hue_tint(g.random(), g.uniform(s0, s1)))  # noqa: E731
    return {"background": BACKGROUNDS[int(g.integers(len(BACKGROUNDS)))], "blotch_mm": _r(g.uniform(15, 80), 1),
            "blotch_contrast": _r(g.uniform(0.03, 0.1), 4), "scene_seed": int(g.integers(1, 2 ** 31 - 1)),
            "wall_tint": tint(0.0, 0.3), "string_tint": tint(0.3, 0.9)}


def _arm(g: np.random.Generator) -> dict:
    widths = np.array([110.0, 90.0, 75.0]) * g.uniform(0.75, 1.3)
    discs = bool(g.random() < 0.5)
    if discs:   # each disc at least 5 mm beyond its widest link, so it shows
        near = np.array([widths[0], widths[:2].max(), widths[1:].max(), widths[2]]) / 2 + 5
        radii = np.maximum(np.array([65.0, 55.0, 45.0, 40.0]) * g.uniform(0.85, 1.25), near)
    else:       # the round caps the renderer draws: half the wider adjoining link (or gripper)
        radii = None
    gripper = np.array([60.0, 25.0]) * g.uniform(0.8, 1.25)
    if radii is None:
        radii = np.array([widths[0], widths[:2].max(), widths[1:].max(), max(widths[2], gripper[0])]) / 2
    link = g.uniform(0.3, 0.85)
    step = g.uniform(0.15, 0.35) * (1 if link < 0.45 or (link < 0.7 and g.random() < 0.3) else -1)
    return {"link_widths_mm": tuple(_r(v, 1) for v in widths), "joint_discs": discs,
            "joint_radii_mm": tuple(_r(v, 1) for v in radii), "gripper_widths_mm": tuple(_r(v, 1) for v in gripper),
            "link_shade": _r(link, 3), "joint_shade": _r(np.clip(link + step, 0.05, 0.95), 3),
            "gripper_shade": _r(g.uniform(0.1, 0.4), 3)}


def _calib(g: np.random.Generator) -> dict:
    board = CALIB_BOARDS[int(g.integers(2))]
    if g.random() < 0.8:
        region = (0.0, 0.0, 1.0, 1.0)
    else:                                   # a band along one side: the weak set of a hurried user
        e, side = _r(g.uniform(0.4, 0.6), 3), int(g.integers(4))
        f = _r(1 - e, 3)
        region = ((0.0, 0.0, 1.0, e), (0.0, f, 1.0, 1.0), (0.0, 0.0, e, 1.0), (f, 0.0, 1.0, 1.0))[side]
    # the board's long side over the image's short side; a small board's markers (5x5 bits) still
    # decode (a bit over 2.5 px at 0.3); in a band a large board is only as large as fits
    span = ((0.5, 0.85) if region == (0.0, 0.0, 1.0, 1.0) else (0.45, 0.6)) if board == "large" else (0.3, 0.45)
    return {"calib_shots": int(g.integers(6, 31)), "calib_tilt_deg": (10.0, _r(g.uniform(20, 45), 2)),
            "calib_board": board, "calib_board_span": span, "calib_region": region}


def _clock(g: np.random.Generator) -> dict:
    trigger = TRIGGERS[int(g.choice(4, p=[0.3, 0.35, 0.1, 0.25]))]
    error = {"exact": 0.0, "jitter": _r(g.uniform(-0.002, 0.002), 7), "wrong": 0.03 * float(g.choice([-1.0, 1.0])),
             "absent": None}[trigger]
    return {"trigger": trigger, "trigger_error_s": error,
            "joint_log": JOINT_LOGS[0] if g.random() < 0.6 else JOINT_LOGS[1]}


def draw_setup(seed: int) -> Setup:
    """Draw one lab set-up of the family (module doc), reproducibly from ``seed``.

    Each group of settings (sensor, lens, view, light, scene, board, arm, calibration set, clocks)
    has its own generator spawned from ``np.random.SeedSequence([seed, 25])``, so a draw's groups
    do not shift when another group's draws change. The view is fitted on the lab camera
    (:func:`.view.fit_view`) and the board placed on it (:func:`.view.place_board`).

    Returns:
        A :class:`Setup`. Raises RuntimeError if no view or board pose fits (not seen in 2000 seeds).
    """
    g = dict(zip(_GROUPS, (np.random.default_rng(s) for s in np.random.SeedSequence([int(seed), 25]).spawn(len(_GROUPS)))))
    sensor = _sensor(g["sensor"])
    size = (sensor["width_px"], sensor["height_px"])
    lens = _lens(g["lens"], size)
    view = _view(g["view"], lens, size)
    cam = camera({**lens, **view}, size, view["focal_px"], np.asarray(view["center_mm"]) / 1000)
    origin, angle = place_board(g["board"], cam, (BOARD_MM[0] / 1000, BOARD_MM[1] / 1000), BOARD_PAD_MM / 1000)
    board = {"board_origin_mm": (_r(origin[0] * 1000, 1), _r(origin[1] * 1000, 1)), "board_angle_deg": _r(angle, 3)}
    return Setup(seed=int(seed), **sensor, **lens, **view, **_light(g["light"]), **_scene(g["scene"]), **board,
                 **_arm(g["arm"]), **_calib(g["calib"]), **_clock(g["clock"]))


def _default_setup(config: Mapping) -> dict:
    setups = config.get("setups", {}) or {}
    if "default" not in setups:
        raise ConfigError("apply_setup: the config has no setups.default to replace")
    b = setups["default"]["board"]
    size = (b["squares_x"] * b["square_mm"], b["squares_y"] * b["square_mm"])
    if size[0] > BOARD_MM[0] + 1 or size[1] > BOARD_MM[1] + 1:
        raise ConfigError(f"apply_setup: setups.default's board is {size[0]:.0f} x {size[1]:.0f} mm; draws place "
                          f"a board of at most {BOARD_MM[0]:.0f} x {BOARD_MM[1]:.0f} mm")
    return setups["default"]


def apply_setup(config: Mapping, setup: Setup) -> dict:
    """A deep copy of ``config`` that films ``setup``.

    The user's view (what a user knows and writes down): ``cameras.lab_drawn`` (image size, fps,
    8 bit, mono unless colour, k3 held at 0), ``setups.default`` on that camera with the board
    at the drawn pose (upright: ``board_flip_y``), and the first arm's outline as measured: the
    drawn link widths + 10 mm, joint radii + 5 mm, gripper widths + 6 / + 5 mm (the margins the
    project's own config keeps over its lab's arm). The hidden truth goes into ``lab``:
    ``camera`` (lens, view, light, sensor), ``video`` (codec, colour, quality), ``look``
    (background, shades, tints, the arm's true outline and discs), ``calibration`` (the shots),
    ``scene_seed``, ``trigger_error_s`` = 0 with ``trigger_offset_s`` = the drawn error and
    ``trigger_written``, and ``joint_log``.

    Raises:
        ConfigError: no ``setups.default``, or its board larger than the draw assumes (:data:`BOARD_MM`).
    """
    out = copy.deepcopy(dict(config))
    s = setup
    base = _default_setup(out)
    out.setdefault("cameras", {})[DRAWN_CAMERA] = {"width_px": s.width_px, "height_px": s.height_px, "fps": s.fps,
                                                   "bit_depth": 8, "mono": not s.colour, "fix_k3": True}
    out["setups"]["default"] = {**base, "camera": DRAWN_CAMERA, "board_origin_mm": list(s.board_origin_mm),
                                "board_angle_deg": s.board_angle_deg, "board_flip_y": True}
    arm_id = next(iter(out["arms"]))
    dw, dr, dg = ARM_MEASURE_MM
    out["arms"][arm_id] = {**out["arms"][arm_id], "link_widths_mm": [v + dw for v in s.link_widths_mm],
                           "joint_radii_mm": [v + dr for v in s.joint_radii_mm],
                           "gripper_widths_mm": [v + d for v, d in zip(s.gripper_widths_mm, dg)]}
    lab = out["lab"] = dict(out.get("lab", {}) or {})
    cam_keys = ("focal_px", "principal_offset_px", "dist_coeffs", "distance_mm", "center_mm", "tilt_deg", "roll_deg",
                "exposure_s", "light_level", "light_drift_per_s", "flicker", "flicker_hz", "noise_sigma", "shot_gain",
                "blur_sigma_px", "vignetting")
    lab["camera"] = {**(lab.get("camera", {}) or {}), **{k: _plain(getattr(s, k)) for k in cam_keys}}
    lab["video"] = {"codec": s.codec, "colour": s.colour, "mjpeg_quality": s.mjpeg_quality or 90,
                    "h264_crf": s.h264_crf or 23}
    lab["look"] = {"background": s.background, "blotch_mm": s.blotch_mm, "blotch_contrast": s.blotch_contrast,
                   "reflectance": {"link": s.link_shade, "joint": s.joint_shade, "gripper": s.gripper_shade},
                   "tint": {"wall": list(s.wall_tint), "cord": list(s.string_tint)},
                   "arm": {"link_widths_mm": list(s.link_widths_mm), "joint_radii_mm": list(s.joint_radii_mm),
                           "gripper_widths_mm": list(s.gripper_widths_mm), "joint_discs": s.joint_discs}}
    lab["calibration"] = {"shots": s.calib_shots, "tilt_deg": list(s.calib_tilt_deg),
                          "board_span": list(s.calib_board_span), "region": list(s.calib_region)}
    lab.update({"scene_seed": s.scene_seed, "trigger_error_s": 0.0, "trigger_offset_s": s.trigger_error_s or 0.0,
                "trigger_written": s.trigger != "absent",
                "joint_log": "at_motion_start" if s.joint_log == "at_motion_start" else "full"})
    return out


def _plain(v):
    return list(v) if isinstance(v, tuple) else v

