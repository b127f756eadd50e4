"""How the lab's scene looks: mono or colour, the materials' shades and tints, the background's
style and the arm's outline (``lab.look``, ``lab.video.colour``).

A mono scene is drawn in reflectance (one channel). A colour scene is drawn in BGR: each
material's reflectance times its tint, a (3,) BGR factor scaled so that its BT.601 luma
(0.114 B + 0.587 G + 0.299 R, what ``cv2.cvtColor(..., COLOR_BGR2GRAY)`` computes) is 1. So a
colour frame converted to grey shows about the mono frame's grey levels (up to saturation,
noise and the colour sensor's Bayer mosaic, :meth:`~.camera.Sensor.expose`), whatever the
tints: a colour camera and a mono one see the same scene.

Backgrounds: ``clutter`` (the default lab: a faintly textured wall, a few boxes and discs and
a hanging dark cable), ``plain`` (the wall alone) and ``blotchy`` (the wall with blotches of
about ``blotch_mm`` at a contrast of ``blotch_contrast``, no clutter).
"""
from __future__ import annotations

import colorsys
from dataclasses import dataclass, field
from collections.abc import Mapping

import numpy as np

from stringcast.core import ConfigError
from .settings import LabSettings
from .draw import ARM_WIDTHS_M, GRIPPER_WIDTH_M, JOINT_RADII_M, REFLECTANCE

BACKGROUNDS = ("clutter", "plain", "blotchy")
LUMA_BGR = np.array([0.114, 0.587, 0.299])   # ITU-R BT.601, as cv2.COLOR_BGR2GRAY
DEFAULT_TINTS = {                              # colour scenes: BGR factors (normalised to luma 1)
    "table": (0.75, 0.95, 1.3), "pedestal": (1.1, 1.0, 0.95), "target": (0.7, 0.75, 1.7),
    "clay": (0.8, 0.95, 1.25), "link": (1.15, 1.0, 0.92), "joint": (1.3, 1.0, 0.85),
}
LOOK_KEYS = {"background", "blotch_mm", "blotch_contrast", "reflectance", "tint", "arm"}
ARM_KEYS = {"link_widths_mm", "joint_radii_mm", "gripper_widths_mm", "joint_discs"}


def luma_tint(bgr) -> np.ndarray:
    """A BGR factor (3,) scaled to BT.601 luma 1. Raises ConfigError for a non-positive one."""
    t = np.asarray(bgr, float).reshape(-1)
    if t.shape != (3,) or np.any(t < 0) or float(LUMA_BGR @ t) <= 0:
        raise ConfigError(f"lab.look.tint: {list(np.ravel(bgr))} is not a BGR triple of factors >= 0")
    return t / float(LUMA_BGR @ t)


def hue_tint(hue: float, saturation: float) -> np.ndarray:
    """A luma-1 BGR tint of ``hue`` in [0, 1) (HSV) mixed ``saturation`` in [0, 1] with grey."""
    r, g, b = colorsys.hsv_to_rgb(hue % 1.0, 1.0, 1.0)
    return luma_tint((1 - saturation) + saturation * np.array([b, g, r]))


@dataclass(frozen=True)
class ArmLook:
    """The arm's outline as drawn, m: link widths (the last repeats), joint radii from the base on
    (the last repeats), the gripper's width at the wrist and at the fingertips. Without
    ``joint_discs`` each joint is a round cap of the link's shade, half the wider adjoining
    link (or gripper) wide: a capsule-like arm with no disc to see."""

    link_widths: tuple = ARM_WIDTHS_M
    joint_radii: tuple = JOINT_RADII_M
    gripper_widths: tuple = GRIPPER_WIDTH_M
    joint_discs: bool = True


@dataclass(frozen=True)
class SceneLook:
    """Mono or colour, each material's value (reflectance, or BGR reflectance (3,) in colour), the
    background's style and the arm's outline (:class:`ArmLook`)."""

    colour: bool = False
    palette: Mapping = field(default_factory=lambda: dict(REFLECTANCE))
    background: str = "clutter"
    blotch_mm: float = 40.0
    blotch_contrast: float = 0.06
    arm: ArmLook = ArmLook()

    def value(self, name: str):
        """Material ``name``'s value: a float (mono) or a (3,) float32 BGR (colour)."""
        return self.palette[name]

    def shade(self, grey: float, tint: np.ndarray | None):
        """A reflectance ``grey`` as this scene draws it: itself (mono), or times a luma-1 tint."""
        if not self.colour:
            return grey
        return (grey * (np.ones(3) if tint is None else tint)).astype(np.float32)


def _mm_tuple(arm: Mapping, key: str, default: tuple, n_min: int) -> tuple:
    if key not in arm:
        return default
    v = tuple(float(x) / 1000 for x in arm[key])
    if len(v) < n_min or min(v) <= 0:
        raise ConfigError(f"lab.look.arm.{key}: expected at least {n_min} values > 0 (mm)")
    return v


def arm_look(look: Mapping) -> ArmLook:
    """``lab.look.arm`` as an :class:`ArmLook` (defaults: the default lab's arm).

    Raises:
        ConfigError: unknown keys, values not > 0, a gripper width list that is not 2 long.
    """
    arm = dict(look.get("arm", {}) or {})
    unknown = set(arm) - ARM_KEYS
    if unknown:
        raise ConfigError(f"lab.look.arm: unknown keys {sorted(unknown)} (known: {sorted(ARM_KEYS)})")
    gw = _mm_tuple(arm, "gripper_widths_mm", GRIPPER_WIDTH_M, 2)
    if len(gw) != 2:
        raise ConfigError("lab.look.arm.gripper_widths_mm: expected 2 values (at the wrist, at the fingertips)")
    return ArmLook(_mm_tuple(arm, "link_widths_mm", ARM_WIDTHS_M, 1), _mm_tuple(arm, "joint_radii_mm", JOINT_RADII_M, 1),
                   gw, bool(arm.get("joint_discs", True)))


def scene_look(config: Mapping) -> SceneLook:
    """The scene's look from ``lab.look`` and ``lab.video.colour`` (absent: the default lab, mono).

    ``lab.look``: ``background`` (clutter | plain | blotchy), ``blotch_mm``, ``blotch_contrast``,
    ``reflectance`` ({material: value in [0, 1]} over the defaults), ``tint`` ({material: [B, G,
    R]}, colour only, scaled to luma 1; defaults for the table, pedestal, target, clay, link and
    joint), ``arm`` (:func:`arm_look`).

    Raises:
        ConfigError: unknown keys or materials, values out of range.
    """
    lab = LabSettings.from_config(config)
    look = dict(lab.look)
    colour = bool(lab.video.get("colour", False))
    unknown = set(look) - LOOK_KEYS
    if unknown:
        raise ConfigError(f"lab.look: unknown keys {sorted(unknown)} (known: {sorted(LOOK_KEYS)})")
    refl = dict(REFLECTANCE)
    for name, v in (look.get("reflectance", {}) or {}).items():
        if name not in REFLECTANCE or not 0 <= float(v) <= 1:
            raise ConfigError(f"lab.look.reflectance.{name} = {v}: expected a material of {sorted(REFLECTANCE)} "
                              "and a value in [0, 1]")
        refl[name] = float(v)
    tints = {**DEFAULT_TINTS, **(look.get("tint", {}) or {})}
    bad = set(tints) - set(REFLECTANCE)
    if bad:
        raise ConfigError(f"lab.look.tint: unknown materials {sorted(bad)}")
    palette = {k: (np.float32(v) * luma_tint(tints.get(k, (1, 1, 1)))).astype(np.float32) if colour else v
               for k, v in refl.items()}
    bg = str(look.get("background", "clutter"))
    if bg not in BACKGROUNDS:
        raise ConfigError(f"lab.look.background = {bg!r}: expected one of {list(BACKGROUNDS)}")
    blotch_mm, contrast = float(look.get("blotch_mm", 40.0)), float(look.get("blotch_contrast", 0.06))
    if blotch_mm <= 0 or not 0 <= contrast <= 0.3:
        raise ConfigError("lab.look: blotch_mm must be > 0 and blotch_contrast in [0, 0.3]")
    return SceneLook(colour, palette, bg, blotch_mm, contrast, arm_look(look))
