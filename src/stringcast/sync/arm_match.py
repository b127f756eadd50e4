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
4. **Fine offset**: each frame in the motion (in it for every candidate offset, if at
   least ``min_frames`` are) is sampled at the strips of q(tau_c + k / fps) for candidate
   offsets tau_c within ``search_ms`` of the coarse one (step ``step_ms``); each
   segment's NCC with the template, summed over frames, peaks at the offset; segments
   whose own peak is off the others' by more than ``segment_agree_ms`` are left out;
   a parabola through the peak of the rest's sum gives it below the step. A few bad
   frames only flatten their own score curve. The spread (MAD) of the frames' own best
   offsets is the time residual. Each frame's strips are predicted at the exposure
   centre ``tau + k / fps`` (motion blur averages the arm over the exposure: its
   centre, to first order). ``strip_margin_mm`` is kept small (10 mm): the static
   background in the template's margins pulls the match towards the rest posture
   (25 mm: -0.67 ms on the test clip, 10 mm: +0.04 ms).
5. **Residual** (:func:`match_residual`): every frame's and segment's own best offset,
   times the segment's speed across itself, is a distance in mm between the arm seen
   and the arm predicted at the estimated offset; their robust spread is the residual.

The board-to-robot check (where the still arm is seen vs its FK position) is
:func:`stringcast.calibrate.board_check.check_board_to_robot`; :func:`stringcast.sync.video_offset.estimate_offset`
moves the strips by the translation it measures.
"""
from __future__ import annotations

import cv2
import numpy as np
from scipy.ndimage import map_coordinates

from stringcast.core import forward_kinematics
from .strip_kernel import strips_kernel


def segment_half_widths(arm, margin_m: float) -> np.ndarray:
    """(S,) half-widths of the strips, m: links then gripper, from the arm's outline
    (:class:`~stringcast.core.ArmSpec` ``link_widths``, ``gripper_widths``) + margin."""
    links = arm.link_widths
    widths = [links[min(j, len(links) - 1)] for j in range(arm.n_joints)] + [max(arm.gripper_widths)]
    return np.asarray(widths, float) / 2 + margin_m


def strip_points(arm, q: np.ndarray, half_widths: np.ndarray, n_u: int, n_v: int,
                 segments: np.ndarray | None = None) -> np.ndarray:
    """Sampling grid across arm segments: (..., S, n_u, n_v, 2) robot-frame points, m.

    Segments: the J links and the gripper (base -> ... -> grasp point of
    :func:`~stringcast.core.arm.forward_kinematics`), or those indexed by ``segments`` (S,);
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
    """Bilinear samples of ``image`` (H, W) at robot-frame ``points`` (..., 2) m -> (...) of the image's
    dtype: ``calibration.robot_to_pixel`` then ``scipy.ndimage.map_coordinates`` (order 1, mode
    "nearest"). The reference :func:`sample_strips` is held to."""
    uv = calibration.robot_to_pixel(points.reshape(-1, 2))
    vals = map_coordinates(image, [uv[:, 1], uv[:, 0]], order=1, mode="nearest")
    return vals.reshape(points.shape[:-1])


def _camera(calibration) -> np.ndarray:
    """(10,) fx, fy, cx, cy, k1, k2, p1, p2, k3 and 1 of a calibration with intrinsics; zeros without."""
    if calibration.K is None:
        return np.zeros(10)
    K, dist = np.asarray(calibration.K, float), np.asarray(calibration.dist, float).ravel()
    return np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *dist[:5], 1.0])


def sample_strips(image: np.ndarray, calibration, arm, q: np.ndarray, half_widths: np.ndarray, n_u: int, n_v: int,
                  segments: np.ndarray, shift: np.ndarray, origin: tuple[int, int] = (0, 0),
                  frame_shape: tuple[int, int] | None = None) -> np.ndarray:
    """``image`` (H, W) sampled at the strips of postures q (T, J) rad moved by ``shift`` (2,) m: (T, S, n_u, n_v)
    of the image's dtype.

    The same values as the reference ``sample(image, calibration, strip_points(arm, q,
    half_widths, n_u, n_v, segments) + shift)``, bit for bit, in one compiled pass
    (:func:`~stringcast.sync.strip_kernel.strips_kernel`: the strip arithmetic of :func:`strip_points`, the homography as
    ``cv2.perspectiveTransform``, the distortion as :meth:`~stringcast.calibrate.mapping.Calibration.distort`,
    bilinear with the edge held as ``map_coordinates``' mode "nearest") and without the
    (T, S, n_u, n_v, 2) point array. It is the sync stage's inner loop (some 100 000 points per
    frame) at about half the reference's time.

    ``image`` may be a window of a frame of ``frame_shape`` (H, W), from row and column ``origin``:
    the values are then the frame's, NaN where a sample's pixels are not all in the window.

    Raises:
        ValueError: an image that is not (H, W) with H, W >= 2.
    """
    img = np.ascontiguousarray(image)
    if img.ndim != 2 or min(img.shape) < 2:
        raise ValueError(f"sample_strips: image must be (H, W) with H, W >= 2, got {img.shape}")
    h, w = img.shape if frame_shape is None else frame_shape
    fk = np.ascontiguousarray(forward_kinematics(arm, np.atleast_2d(q)))
    u = np.linspace(0.15, 0.85, n_u)
    v = np.ascontiguousarray(np.linspace(-1.0, 1.0, n_v)[None, :] * np.asarray(half_widths, float)[:, None])
    out = np.empty((len(fk), len(segments), n_u, n_v), img.dtype)
    strips_kernel(img, fk, np.asarray(segments, np.int64), u, v, np.asarray(shift, float),
                   np.asarray(calibration._H_inv, float), _camera(calibration), out, int(origin[0]), int(origin[1]),
                   int(h), int(w))
    return out


WINDOW_COLUMNS = 64
"""A strip window's columns start and run in multiples of this: OpenCV's vector loops then cover the
window's columns as they cover the frame's, and its smoothing gives the frame's values bit for bit."""


def _reach(sigma: float) -> int:
    """Pixels a Gaussian of ``sigma`` px reaches in ``cv2.GaussianBlur`` (float images: radius round(4 sigma)), or more."""
    return int(np.ceil(4 * sigma)) + 1 if sigma > 0 else 0


def strip_window(calibration, arm, q: np.ndarray, half_widths: np.ndarray, segments: np.ndarray,
                 shift: np.ndarray, frame_shape: tuple[int, int], sigma: float) -> tuple[int, int, int, int] | None:
    """The frame's window (r0, r1, c0, c1) px to smooth by ``sigma`` px for the strips of postures q (T, J)
    rad: the strips' corners in the image (:func:`strip_points` with 2 x 2 samples), out by the
    Gaussian's reach twice (its edge band, where the window's border changes the smoothing, is not read)
    and 3 px for the bilinear's next pixel and the strips' edges bowed by the lens; columns in whole
    :data:`WINDOW_COLUMNS`. None where that is over half the frame or not finite."""
    h, w = frame_shape
    uv = calibration.robot_to_pixel((strip_points(arm, np.atleast_2d(q), half_widths, 2, 2, segments)
                                     + shift).reshape(-1, 2))
    if not np.all(np.isfinite(uv)):
        return None
    pad = 2 * _reach(sigma) + 3
    c, r = np.clip(uv[:, 0], 0, w - 1), np.clip(uv[:, 1], 0, h - 1)
    r0, r1 = max(0, int(r.min()) - pad), min(h, int(r.max()) + 1 + pad)
    c0 = max(0, int(c.min()) - pad) // WINDOW_COLUMNS * WINDOW_COLUMNS
    c1 = min(w, c0 + -(-(int(c.max()) + 1 + pad - c0) // WINDOW_COLUMNS) * WINDOW_COLUMNS)
    return None if (r1 - r0) * (c1 - c0) > 0.5 * h * w else (r0, r1, c0, c1)


def smoothed_strips(frame: np.ndarray, sigma: float, calibration, arm, q: np.ndarray, half_widths: np.ndarray,
                    n_u: int, n_v: int, segments: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """``sample_strips(smooth(frame, sigma), ...)``, smoothing only the window the strips need
    (:func:`strip_window`): the sync stage's work per frame, of which smoothing the whole frame was half.
    Only the window's inside, a Gaussian's reach from its border (where the border is not the frame's),
    is read; where a sample needs more, or no window is worth it, the whole frame is smoothed.
    (T, S, n_u, n_v) float32."""
    h, w = frame.shape
    window = strip_window(calibration, arm, q, half_widths, segments, shift, (h, w), sigma)
    if window is not None:
        r0, r1, c0, c1 = window
        e = _reach(sigma)
        top, left = (e if r0 > 0 else 0), (e if c0 > 0 else 0)
        inner = smooth(frame[r0:r1, c0:c1], sigma)[top:r1 - r0 - (e if r1 < h else 0),
                                                   left:c1 - c0 - (e if c1 < w else 0)]
        out = sample_strips(inner, calibration, arm, q, half_widths, n_u, n_v, segments, shift,
                            (r0 + top, c0 + left), (h, w))
        if not np.isnan(out).any():
            return out
    return sample_strips(smooth(frame, sigma), calibration, arm, q, half_widths, n_u, n_v, segments, shift)


def ncc_segments(samples: np.ndarray, template: np.ndarray) -> np.ndarray:
    """NCC of each segment's (..., S, n_u, n_v) samples with the (S, n_u, n_v) template -> (..., S)."""
    a = samples - samples.mean(axis=(-2, -1), keepdims=True)
    b = template - template.mean(axis=(-2, -1), keepdims=True)
    num = (a * b).sum(axis=(-2, -1))
    den = np.sqrt((a * a).sum(axis=(-2, -1)) * (b * b).sum(axis=(-2, -1)))
    return num / np.maximum(den, 1e-12)


def ncc(samples: np.ndarray, template: np.ndarray) -> np.ndarray:
    """Mean over segments of :func:`ncc_segments` -> (...)."""
    return np.mean(ncc_segments(samples, template), axis=-1)


def normal_speeds(arm, q_minus: np.ndarray, q_mid: np.ndarray, q_plus: np.ndarray, dt: float,
                  segments: np.ndarray, n_u: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Motion of each segment across itself, for :func:`match_residual`.

    Args:
        q_minus, q_mid, q_plus: (F, J) rad, the joints at t - dt, t, t + dt (dt s).
        segments: (S,) segment indices; n_u: samples along each strip.

    Returns:
        a (F, S) m/s: RMS over the strip's length of the velocity along the segment's
        normal; b (F, S): mean / RMS of that velocity (1 for a translation, ~0.86 for a
        rotation about one end), so that a static position error e along the normal
        shifts the segment's best offset by ``b e / a``; nrm (F, S, 2): the unit normals.
    """
    zero = np.zeros(len(segments))
    p0 = strip_points(arm, q_minus, zero, n_u, 1, segments)[..., 0, :]  # (F, S, n_u, 2)
    p1 = strip_points(arm, q_plus, zero, n_u, 1, segments)[..., 0, :]
    pts = forward_kinematics(arm, q_mid)
    d = (pts[..., 1:, :] - pts[..., :-1, :])[..., segments, :]
    e = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-9)
    nrm = np.stack([-e[..., 1], e[..., 0]], axis=-1)  # (F, S, 2)
    vn = np.einsum("fsuc,fsc->fsu", (p1 - p0) / (2 * dt), nrm)
    rms = np.sqrt(np.mean(vn ** 2, axis=-1))
    return rms, np.mean(vn, axis=-1) / np.maximum(rms, 1e-12), nrm


def match_residual(tau_ks: np.ndarray, a: np.ndarray, offset_s: float) -> tuple[float | None, int]:
    """Robust residual (mm) of the arm's match at ``offset_s``, and the equations used.

    Each frame k and segment s that matched (tau_ks (F, S) s, NaN where not) and moved
    across itself (a (F, S) m/s from :func:`normal_speeds`, > 1 mm/s) gives the distance
    ``a_ks (tau_ks - offset_s)`` by which the segment seen and the segment predicted at the
    offset differ across the segment; the residual is 1.4826 x their median absolute
    value (a MAD: a few bad frames do not inflate it). None if fewer than 3.
    """
    ok = np.isfinite(tau_ks) & np.isfinite(a) & (a > 1e-3)
    if ok.sum() < 3:
        return None, int(ok.sum())
    d = a[ok] * (tau_ks[ok] - offset_s)
    return float(1.4826 * np.median(np.abs(d)) * 1000), int(ok.sum())


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


def smooth(frame: np.ndarray, sigma: float) -> np.ndarray:
    """A frame as float32, Gaussian-smoothed by ``sigma`` px (none if sigma <= 0)."""
    f = np.asarray(frame, np.float32)
    return cv2.GaussianBlur(f, (0, 0), sigma) if sigma > 0 else f
