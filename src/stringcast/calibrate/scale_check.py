"""Is the still arm seen at a scale of where the forward kinematics put it? (a board size off by a factor)

The calibration maps pixels to the robot frame through the ChArUco board, whose corners lie at
multiples of ``square_mm`` in the board's frame. A square size given as 50 mm for a 60 mm board
scales every mapped point about the board's origin O by k = 50 / 60: the arm at p is seen at
O + k (p - O), 80-170 mm from its forward kinematics over the arm's reach, and the board check
(:mod:`stringcast.calibrate.board_check`), looking for its links within a few mm of p, finds too
few of them to say anything but "not checked" (issue 51: then the sweep moved the mapping by
102 mm with warnings only, and tracking crashed).

:func:`arm_scale` is the check the board check cannot make: only where the board check did not
find the arm where the forward kinematics put it, the same features (the links' edge pairs and
the joint discs, :mod:`stringcast.calibrate.link_profiles`) are looked for at O + k (p - O), for k
on a grid of :data:`SCALE_STEP` (about 2.5 %) over ``[1 / MAX_SCALE, MAX_SCALE]``, and around the
best k at a fifth of that step, then to 1e-4 by a bounded scalar search (``scipy.optimize.minimize_scalar``).
The coarse k where the most features are found, refined to where the board check's translation
is smallest, is the scale the arm is seen at; it is named only where
the board check there finds the arm (its translation determined and within ``board_check.warn_mm``)
and k differs from 1 by more than :data:`MIN_SCALE_ERROR`. Nothing here depends on the camera:
the features are the arm's own, in mm of the arm.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.optimize import minimize_scalar

from stringcast.core import BoardCheckSettings

from .board_check import _disc_offsets, _segment_offsets, check_board_to_robot

MAX_SCALE = 1.6
"""The largest scale factor looked for (and 1 / it the smallest): a square size off by 60 %."""
SCALE_STEP = 0.025
"""The coarse grid's step in log k (2.5 %); the fine grid's is a fifth of it."""
MIN_SCALE_ERROR = 0.03
"""A scale named must differ from 1 by more than this (3 %): the board check's own translation,
1-2 mm at the arm's 0.5-1 m from the board, is a 0.2-0.4 % scale."""


def scaled_about(calibration, origin: np.ndarray, k: float):
    """The calibration under which robot point p maps to the pixel ``calibration`` maps O + k (p - O) to
    (O = ``origin`` (2,) m): where the arm at p is seen when the board's size is off by k."""
    T = np.array([[k, 0.0, (1 - k) * origin[0]], [0.0, k, (1 - k) * origin[1]], [0.0, 0.0, 1.0]])
    return dataclasses.replace(calibration, H_pixel_to_robot=np.linalg.inv(T) @ calibration.H_pixel_to_robot)


def _found(image, calibration, arm, q_rest, st: BoardCheckSettings) -> int:
    """How many of the arm's features (links' edge pairs, joint discs) are found where ``calibration`` puts them."""
    n = len(_segment_offsets(image, calibration, arm, q_rest, st))
    return n + (len(_disc_offsets(image, calibration, arm, q_rest, st)) if st.use_discs else 0)


def arm_scale(rest_image: np.ndarray, calibration, arm, q_rest: np.ndarray, board_check: BoardCheckSettings) -> dict | None:
    """The scale about the board's origin at which the still arm is seen, where it is not 1 (module doc).

    Args:
        rest_image: (H, W) grey image of the arm still at ``q_rest`` (J,) rad.
        calibration: :class:`~stringcast.calibrate.mapping.Calibration` with ``board_to_robot`` (its
            translation is the board's origin O in the robot frame).
        arm: :class:`~stringcast.core.specs.ArmSpec` with its outline. board_check: its settings.

    Returns:
        None where no scale other than 1 explains the arm, else ``{"scale": k, "features": found at k,
        "features_at_1": found at 1, "residual_mm": the board check's translation at k}``.
    """
    if calibration.board_to_robot is None:
        return None
    img = np.asarray(rest_image, np.float32)
    origin = np.asarray(calibration.board_to_robot, float)[:2, 2]
    st = board_check
    at_1 = _found(img, calibration, arm, q_rest, st)
    n = int(round(math.log(MAX_SCALE) / SCALE_STEP))
    coarse = np.exp(np.arange(-n, n + 1) * SCALE_STEP)
    counts = np.array([_found(img, scaled_about(calibration, origin, k), arm, q_rest, st) for k in coarse])
    if counts.max() <= at_1:
        return None
    checks: dict[float, dict] = {}

    def check(k: float) -> dict:
        if k not in checks:
            checks[k] = check_board_to_robot(img, scaled_about(calibration, origin, k), arm, q_rest, st)
        return checks[k]

    def residual(k: float) -> float:   # the board check's translation at k; inf where it is not determined
        r = check(float(k))["residual_mm"]
        return math.inf if r is None else float(r)

    # the links' edges are found over a span of k (their search reaches past the outline); the translation
    # falls steeply to its minimum, by some 10 mm a per cent of k: the coarse k of the most features with the
    # least translation, then a fifth of the step, then the bounded search
    k0 = min((float(k) for k in coarse[counts == counts.max()]), key=residual)
    step = SCALE_STEP / 5
    k1 = min((float(k) for k in k0 * np.exp(np.arange(-5, 6) * step)), key=residual)
    if not math.isfinite(residual(k1)):
        return None
    res = minimize_scalar(lambda k: min(residual(k), 1e9), bounds=(k1 * math.exp(-step), k1 * math.exp(step)),
                          method="bounded", options={"xatol": 1e-4})
    k = min(float(res.x), k1, key=residual)
    doc = check(k)
    if abs(k - 1) <= MIN_SCALE_ERROR or doc["residual_mm"] > st.warn_mm:
        return None
    return {"scale": k, "features": int(doc["n_used"]), "features_at_1": int(at_1), "residual_mm": doc["residual_mm"]}


__all__ = ["arm_scale", "scaled_about"]
