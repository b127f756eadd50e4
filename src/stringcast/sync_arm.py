"""Video-to-controller clock offset from the arm seen in the video (the sync stage's estimator).

The arm's pose at any controller time is known from ``joints.csv`` and the forward
kinematics; the calibration maps it into the image. So the offset tau (controller time
of frame 0) is the one for which the arm, predicted at ``tau + k / fps``, lies where
frame k shows it. The arm's *appearance* is learnt from the video itself, not from a
model of the renderer or of the real arm's colours:

1. **Strips** (:func:`strip_points`): along each link and the gripper, a grid of
   ``strip_samples`` x ``strip_width_samples`` points in the swing plane, across the
   segment out to its half-width (from the tracking settings' arm outline) plus
   ``strip_margin_mm``, so each strip holds the segment and its two edges.
2. **Template**: the strips sampled, at the rest posture q(t0) (the log's first
   sample; the arm is still there before the motion, whatever the offset), in the median
   of the first ``rest_frames`` frames.
3. **Coarse offset** (no trigger time, or a wrong one): every frame's rest strips are
   compared with the template (normalised cross-correlation, NCC); the arm leaving its
   rest posture makes that NCC fall. The same curve is predicted from the joint log
   by sampling the rest image at the strips of q(t); the offset is the shift that
   best matches the two (least squares over a grid over the whole possible range).
4. **Fine offset**: each frame in the motion is sampled at the strips of
   q(tau_c + k / fps) for candidate offsets tau_c within ``search_ms`` of the coarse one
   (step ``step_ms``); the mean NCC with the template, summed over frames, peaks at the
   offset; a parabola through the peak gives it below the step. A few bad frames only
   flatten their own score curve. The spread (MAD) of the frames' own best offsets is
   the time residual.
5. **Board check** (:func:`board_check`): across each segment of the rest template,
   the two strongest opposite edges give the segment's axis as seen; its offset from
   the forward kinematics' axis, along each segment's normal, gives (least squares) the
   translation between where the arm is seen and where config's board-to-robot
   transform puts it: the calibration's residual in mm, warned about above
   ``board_check_warn_mm``.
"""
from __future__ import annotations

import math

import cv2
import numpy as np
from scipy.ndimage import map_coordinates

from .arm import forward_kinematics

DEFAULTS = {"method": "trigger", "search_ms": 10.0, "step_ms": 0.25, "coarse_step_ms": 0.5, "strip_samples": 8,
            "strip_width_samples": 41, "strip_margin_mm": 25.0, "rest_frames": 5, "smooth_px": 1.0,
            "board_check_warn_mm": 20.0, "min_frame_contrast": 0.02}


def settings(config: dict | None) -> dict:
    """Sync settings: ``config['sync']`` over :data:`DEFAULTS`."""
    st = dict(DEFAULTS)
    st.update((config or {}).get("sync", {}) or {})
    return st


def segment_half_widths(arm, tracking_st: dict, margin_m: float) -> np.ndarray:
    """(S,) half-widths of the strips, m: links then gripper, from the arm outline (mm) + margin."""
    links = tracking_st["arm_link_widths_mm"]
    widths = [links[min(j, len(links) - 1)] for j in range(arm.n_joints)] + [max(tracking_st["gripper_widths_mm"])]
    return np.asarray(widths, float) / 2000 + margin_m


def strip_points(arm, q: np.ndarray, half_widths: np.ndarray, n_u: int, n_v: int,
                 segments: np.ndarray | None = None) -> np.ndarray:
    """Sampling grid across arm segments: (..., S, n_u, n_v, 2) robot-frame points, m.

    Segments: the J links and the gripper (base -> ... -> grasp point of
    :func:`~stringcast.arm.forward_kinematics`), or those indexed by ``segments`` (S,);
    u runs over 15-85 % of a segment's length (clear of the joints), v over
    +-half_widths[s] (S,) along its normal.
    """
    pts = forward_kinematics(arm, q)
    a, b = pts[..., :-1, :], pts[..., 1:, :]
    if segments is not None:
        a, b = a[..., segments, :], b[..., segments, :]
    d = b - a
    e = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-9)
    nrm = np.stack([-e[..., 1], e[..., 0]], axis=-1)
    u = np.linspace(0.15, 0.85, n_u)[:, None, None]
    v = np.linspace(-1.0, 1.0, n_v)[None, :, None] * np.asarray(half_widths)[:, None, None, None]
    return a[..., :, None, None, :] + u * d[..., :, None, None, :] + v * nrm[..., :, None, None, :]


def sample(image: np.ndarray, calibration, points: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``image`` at robot-frame ``points`` (..., 2) -> (...) float."""
    uv = calibration.robot_to_pixel(points.reshape(-1, 2))
    vals = map_coordinates(image, [uv[:, 1], uv[:, 0]], order=1, mode="nearest")
    return vals.reshape(points.shape[:-1])


def ncc(samples: np.ndarray, template: np.ndarray) -> np.ndarray:
    """Mean over segments of the NCC of (..., S, n_u, n_v) samples with (S, n_u, n_v) -> (...)."""
    a = samples - samples.mean(axis=(-2, -1), keepdims=True)
    b = template - template.mean(axis=(-2, -1), keepdims=True)
    num = (a * b).sum(axis=(-2, -1))
    den = np.sqrt((a * a).sum(axis=(-2, -1)) * (b * b).sum(axis=(-2, -1)))
    return np.mean(num / np.maximum(den, 1e-12), axis=-1)


def joints_at(t: np.ndarray, t_j: np.ndarray, q_j: np.ndarray) -> np.ndarray:
    """Joint angles at times t (...,) by linear interpolation, held at the log's ends: (..., J)."""
    t = np.asarray(t, float)
    return np.stack([np.interp(t, t_j, q_j[:, j]) for j in range(q_j.shape[1])], axis=-1)


def coarse_offset(rest_ncc: np.ndarray, fps: float, predicted_t: np.ndarray, predicted: np.ndarray,
                  step_s: float) -> float:
    """Offset s that best lines up the frames' rest-strip NCC (F,) with its prediction.

    ``predicted`` (T,) is the NCC expected at controller times ``predicted_t`` (T,); the
    grid of offsets spans every shift that keeps a tenth of the frames on the log.
    """
    k_t = np.arange(len(rest_ncc)) / fps
    lo = predicted_t[0] - k_t[-1] * 0.9
    hi = predicted_t[-1] - k_t[-1] * 0.1
    taus = np.arange(lo, hi + step_s, step_s)
    pred = np.interp(taus[:, None] + k_t[None, :], predicted_t, predicted)
    cost = np.nanmean((pred - rest_ncc[None, :]) ** 2, axis=1)
    return float(taus[int(np.argmin(cost))])


def parabola_peak(x: np.ndarray, y: np.ndarray) -> float:
    """x of the maximum of y, refined by a parabola through it and its neighbours."""
    i = int(np.nanargmax(y))
    if 0 < i < len(y) - 1:
        den = y[i - 1] - 2 * y[i] + y[i + 1]
        if den < 0:
            return float(x[i] + 0.5 * (y[i - 1] - y[i + 1]) / den * (x[1] - x[0]))
    return float(x[i])


def _edge_offset(profile: np.ndarray, v: np.ndarray) -> float | None:
    """Axis offset (m) of a segment's mean cross profile: midpoint of its two strongest
    opposite-signed edges, one on each side of the predicted axis; None if unclear."""
    g = np.gradient(profile, v)
    left, right = v < 0, v > 0
    if not left.any() or not right.any():
        return None
    il = int(np.argmax(np.where(left, np.abs(g), -1)))
    ir = int(np.argmax(np.where(right & (np.sign(g) != np.sign(g[il])), np.abs(g), -1)))
    if not right[ir] or np.sign(g[ir]) == np.sign(g[il]):
        return None

    def refine(i):
        if 0 < i < len(g) - 1:
            y0, y1, y2 = np.abs(g[i - 1:i + 2])
            den = y0 - 2 * y1 + y2
            if den < 0:
                return v[i] + 0.5 * (y0 - y2) / den * (v[1] - v[0])
        return v[i]

    return 0.5 * (refine(il) + refine(ir))


def board_check(rest_image: np.ndarray, calibration, arm, q_rest: np.ndarray, half_widths: np.ndarray,
                segments: np.ndarray | None = None, n_u: int = 24, n_v: int = 81) -> dict:
    """Where the still arm is seen vs where the forward kinematics put it (the board-to-robot check).

    Args:
        rest_image: (H, W) float, the arm at rest at ``q_rest`` (J,) rad.
        half_widths: (S,) strip half-widths, m (:func:`segment_half_widths`), of the
            segments indexed by ``segments`` (default: all).

    Returns:
        ``{"translation_mm": [dx, dy] or None, "residual_mm": |d| or None,
        "segment_offsets_mm": per segment (None where its edges were unclear)}``.
    """
    pts = strip_points(arm, q_rest, half_widths, n_u, n_v, segments)
    vals = sample(rest_image, calibration, pts)  # (S, n_u, n_v)
    fk = forward_kinematics(arm, q_rest)
    index = np.arange(len(fk) - 1) if segments is None else np.asarray(segments)
    rows, rhs, offsets = [], [], []
    for s in range(vals.shape[0]):
        v = np.linspace(-1.0, 1.0, n_v) * half_widths[s]
        off = _edge_offset(np.median(vals[s], axis=0), v)
        offsets.append(None if off is None else float(off) * 1000)
        if off is not None:
            e = fk[index[s] + 1] - fk[index[s]]
            e = e / max(np.hypot(*e), 1e-9)
            rows.append([-e[1], e[0]])
            rhs.append(off)
    if len(rows) < 2 or np.linalg.matrix_rank(np.asarray(rows), tol=0.2) < 2:
        return {"translation_mm": None, "residual_mm": None, "segment_offsets_mm": offsets}
    d = np.linalg.lstsq(np.asarray(rows), np.asarray(rhs), rcond=None)[0] * 1000
    return {"translation_mm": [float(d[0]), float(d[1])], "residual_mm": float(math.hypot(*d)),
            "segment_offsets_mm": offsets}


def smooth(frame: np.ndarray, sigma: float) -> np.ndarray:
    """A frame as float32, Gaussian-smoothed by ``sigma`` px (none if sigma <= 0)."""
    f = np.asarray(frame, np.float32)
    return cv2.GaussianBlur(f, (0, 0), sigma) if sigma > 0 else f
