"""Does the tracked string respond to the grasp's acceleration as a hanging string does?

A fit check that needs no string model (issue 52). Any string, rope or chain hanging from a moving
grasp in air feels, in the grasp's frame, the pseudo-force -m a of the grasp's acceleration a: its
tilt from the vertical answers a horizontal acceleration about as a pendulum of its own swing period
does (theta'' = -omega^2 theta - a_x / l with omega^2 = g / l). A string that hangs from the grasp
and swings freely at a pendulum's period but does *not* tilt under the grasp's acceleration is not
moving under gravity and inertia alone: no parameter set of a string model (the paper's CG model or
any other) can follow it, and the estimate's failure is the recording's, not the model's (a
simulator that moves the string in the gripper's frame without that frame's inertial forces, or a
joint log that is not this video's motion).

:func:`inertial_response` identifies, for the chord from the grasp point to a tracked point, the
balance of its angular acceleration

    theta'' = a_s sin theta + a_c cos theta - c theta' + b_a (x_g'' sin theta - y_g'' cos theta) + b_phi phi_h''

(gravity's restoring term with omega^2 = hypot(a_s, a_c) and any equilibrium angle, damping, the grasp's
acceleration as the pendulum's pseudo-force, and the hand's angular acceleration), from the tracked
angle and the grasp's path (x_g, y_g) and hand angle phi_h (FK, the problem's ``hand``). The fit is
linear least squares with Huber weights in weak form: the balance times a bump of half-width
:data:`SMOOTH_S`, integrated, the angle's derivatives moved onto the bump by parts, so no tracked angle
is differentiated. Its figures:

* ``inertia_share``: b_a g / omega^2, the chord's tilt per grasp acceleration as a share of a
  pendulum's with the same swing frequency (1 for a point pendulum). Over the lab's string family
  (both engines, every material class, :mod:`stringcast_lab.materials`; benchmarks/inertia.py,
  docs/method.md) 0.81-1.43 where stated; the field recording of issue 52 0.01-0.06.
* ``rotation_coupling``: b_phi, how much of the hand's angular acceleration the chord takes: near 1
  where the string turns with the hand as if carried in its frame; over the family -0.34 to +0.08 on
  ours' first motions and -1.38 to +0.19 under the field's motion (never near +1).
* ``swing_period_s``: 2 pi / omega; ``fit_r2``: the share of the weak-form left side's variance the
  balance explains (without its worst 5 %); ``excitation``: the peak horizontal grasp acceleration over
  g (a pendulum's quasi-static tilt, rad); ``inertia_share_se``: the share's standard error.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage, signal

G = 9.81
"""Gravitational acceleration, m/s^2."""
MIN_EXCITATION = 0.1
"""The share is stated only where the grasp's peak horizontal acceleration reaches 0.1 g (a tilt of
about 6 deg for a pendulum): a gentler motion does not separate inertia from noise."""
MIN_R2 = 0.5
"""The share is stated only where the balance explains this share of the chord's angular acceleration."""
SMOOTH_S = 0.1
"""The weak form's bump half-width, and the Savitzky-Golay window (cubic) for the grasp's acceleration,
s: a tenth of a hanging string's swing period (0.9-1.4 s for 300-610 mm) and long enough that 1 mm of
tracking noise at 1 kHz averages out."""
OUTLIER_RAD = np.radians(5.0)
"""A tracked angle this far from its running median (over ``GAP_S``) is an outlier (a lost point)."""
GAP_S = 0.03
"""Gaps (outliers, untracked frames) up to this long are bridged linearly; longer ones split the runs."""
MAX_SHARE_SE = 0.1
"""The share is stated only where its standard error is at most 0.1: a motion whose hand turns in step
with its sideways acceleration cannot tell turning with the hand from inertia."""
MIN_ROWS = 8
"""Fewest weak-form rows (bumps, spaced SMOOTH_S / 2) the share is stated from."""
MIN_RUN_S = 0.2
"""Only runs of consecutive tracked frames at least this long enter (the window needs its span)."""


def chord_points(n: int) -> list[int]:
    """The tracked points (0-based) whose chords are judged: a quarter, half, three quarters and the tip."""
    return sorted({max(0, n // 4 - 1), n // 2 - 1, 3 * n // 4 - 1, n - 1})


def _chord_angle(frame_t, tracked, valid, hand_t, hand, point):
    """The chord angle grasp -> point (F,), rad (NaN where not tracked)."""
    g = np.stack([np.interp(frame_t, hand_t, hand[:, j]) for j in (0, 1)], -1)
    v = tracked[:, point] - g
    ok = valid[:, point] & np.all(np.isfinite(v), axis=-1) & (np.linalg.norm(v, axis=-1) > 0)
    ang = np.full(len(frame_t), np.nan)
    ang[ok] = np.arctan2(v[ok, 1], v[ok, 0])
    return ang


def _runs(ok: np.ndarray, min_len: int) -> list[slice]:
    """The runs of True in ``ok`` at least ``min_len`` long."""
    edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(int), 0]))
    return [slice(a, b) for a, b in zip(edges[::2], edges[1::2]) if b - a >= min_len]


def _huber_lstsq(X, y):
    """Huber-weighted least squares (5 reweightings, threshold 1.345 robust sd): (coefficients, residuals)."""
    w = np.ones(len(y))
    for _ in range(5):
        beta = np.linalg.lstsq(X * w[:, None], y * w, rcond=None)[0]
        r = y - X @ beta
        k = 1.345 * 1.4826 * float(np.median(np.abs(r)))
        w = np.sqrt(np.minimum(1.0, k / np.maximum(np.abs(r), 1e-12)))
    return beta, r


def _clean(ang: np.ndarray, period: float) -> np.ndarray:
    """``ang`` unwrapped over its tracked runs, outliers (:data:`OUTLIER_RAD` from the running median)
    removed and gaps up to :data:`GAP_S` bridged; NaN elsewhere."""
    out = np.full(len(ang), np.nan)
    ok = np.isfinite(ang)
    if ok.sum() < 3:
        return out
    idx = np.flatnonzero(ok)
    th = np.unwrap(ang[ok])
    k = max(3, int(round(GAP_S / period)) | 1)
    med = ndimage.median_filter(th, size=k, mode="nearest")
    good = np.abs(th - med) <= OUTLIER_RAD
    idx, th = idx[good], th[good]
    if len(idx) < 3:
        return out
    span = np.arange(idx[0], idx[-1] + 1)
    gap_to = np.diff(idx)                                           # bridge short gaps only
    fill = np.interp(span, idx, th)
    short = np.repeat(gap_to <= max(1, int(round(GAP_S / period))), gap_to)
    out[span[:-1][short]] = fill[:-1][short]
    out[idx] = th
    return out


def _window(period: float) -> int:
    """The Savitzky-Golay window for :data:`SMOOTH_S` at a frame period, samples (odd, at least 5)."""
    return max(5, int(round(SMOOTH_S / period)) | 1)


def _bump(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The test function (1 - u^2)^4 on |u| < 1 and its first and second derivatives in u."""
    inside = np.abs(u) < 1
    a = np.where(inside, 1 - u ** 2, 0.0)
    return a ** 4, np.where(inside, -8 * u * a ** 3, 0.0), np.where(inside, -8 * a ** 3 + 48 * u ** 2 * a ** 2, 0.0)


def _rows(frame_t, ang, hand_t, hand):
    """The balance's rows in weak form over the tracked runs: (left side (R,), regressors (R, 5)) or None.

    Each row is the balance multiplied by a bump of half-width ``SMOOTH_S`` and integrated, the angle's
    derivatives moved onto the bump by parts (weak-form identification, as in weak SINDy): no derivative
    of a tracked angle is taken, so tracking noise averages out over the bump."""
    period = float(np.median(np.diff(frame_t)))
    h = max(SMOOTH_S, 5 * period)
    ang = _clean(ang, period)
    win = _window(period)
    ys, xs = [], []
    for run in _runs(np.isfinite(ang), max(int(2 * h / period) + 2, int(MIN_RUN_S / period))):
        t, th = frame_t[run], ang[run]
        q = np.stack([np.interp(t, hand_t, hand[:, j]) for j in range(3)], -1)
        acc = signal.savgol_filter(q[:, :2], win, 3, deriv=2, delta=period, axis=0)   # FK: smooth already
        inertial = acc[:, 0] * np.sin(th) - acc[:, 1] * np.cos(th)
        for c in np.arange(t[0] + h, t[-1] - h + 1e-12, h / 2):
            b, b1, b2 = _bump((t - c) / h)
            b1, b2 = b1 / h, b2 / h ** 2
            ys.append(np.trapezoid(th * b2, t))
            xs.append([np.trapezoid(np.sin(th) * b, t), np.trapezoid(np.cos(th) * b, t),
                       -np.trapezoid(th * b1, t), np.trapezoid(inertial * b, t), np.trapezoid(q[:, 2] * b2, t)])
    return (np.asarray(ys), np.asarray(xs)) if ys else None


def _share_se(X: np.ndarray, r: np.ndarray, scale: float) -> float:
    """The share's standard error: the least-squares covariance of the inertial coefficient (robust
    residual scale, 1.4826 MAD), doubled for the neighbouring bumps' overlap (each row shares half its span
    with each neighbour), times ``scale`` (g / omega^2). inf where the regressors are degenerate."""
    sigma = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    try:
        cov = np.linalg.inv(X.T @ X)
    except np.linalg.LinAlgError:
        return float("inf")
    v = cov[3, 3]
    return float(2 * sigma * np.sqrt(v) * scale) if v > 0 else float("inf")


def inertial_response(frame_t: np.ndarray, tracked: np.ndarray, valid: np.ndarray, hand_t: np.ndarray,
                      hand: np.ndarray, point: int) -> dict:
    """The chord's balance of angular acceleration (module doc) for one tracked point.

    Args:
        frame_t: (F,) s, frame times (controller clock), increasing. tracked: (F, n, 2) m. valid: (F, n)
            bool. hand_t: (K,) s, increasing. hand: (K, 3): grasp x, y (m) and hand angle (rad), from FK.
        point: the tracked point's index (0-based) whose chord from the grasp point is used.

    Returns:
        ``{"inertia_share", "rotation_coupling", "swing_period_s", "fit_r2", "excitation",
        "inertia_share_se"}``; the first three None where the motion's excitation is under
        :data:`MIN_EXCITATION`, the balance explains under :data:`MIN_R2` of its left side's variance, the
        share's standard error exceeds :data:`MAX_SHARE_SE`, or no run of frames is long enough.

    Raises:
        ValueError: the arrays' shapes disagree, or ``point`` is not a tracked point.
    """
    frame_t, tracked, valid = np.asarray(frame_t, float), np.asarray(tracked, float), np.asarray(valid, bool)
    hand_t, hand = np.asarray(hand_t, float), np.asarray(hand, float)
    f = len(frame_t)
    if tracked.shape[:1] != (f,) or tracked.shape[2:] != (2,) or valid.shape != tracked.shape[:2] \
            or hand.shape != (len(hand_t), 3) or not 0 <= point < tracked.shape[1] or f < 3:
        raise ValueError(f"inertial_response: frame_t (F,), tracked (F, n, 2), valid (F, n), hand (K, 3) and a "
                         f"point < n expected; got {frame_t.shape}, {tracked.shape}, {valid.shape}, {hand.shape}, "
                         f"point {point}")
    out = {"inertia_share": None, "rotation_coupling": None, "swing_period_s": None, "fit_r2": None,
           "excitation": None, "inertia_share_se": None}
    inside = (frame_t >= hand_t[0]) & (frame_t <= hand_t[-1])
    ang = np.where(inside, _chord_angle(frame_t, tracked, valid, hand_t, hand, point), np.nan)
    rows = _rows(frame_t, ang, hand_t, hand)
    if rows is None or len(rows[0]) < MIN_ROWS:
        return out
    y, X = rows
    hq = np.stack([np.interp(frame_t[inside], hand_t, hand[:, j]) for j in (0, 1)], -1)
    period = float(np.median(np.diff(frame_t)))
    win = _window(period)
    if len(hq) > win:
        out["excitation"] = float(np.max(np.abs(signal.savgol_filter(hq[:, 0], win, 3, deriv=2, delta=period))) / G)
    beta, r = _huber_lstsq(X, y)
    core = np.abs(r) <= np.percentile(np.abs(r), 95)                       # R^2 without the worst 5 %
    spread = float(np.var(y[core]))
    r2 = 1.0 - float(np.var(r[core])) / spread if spread > 0 else 0.0
    out["fit_r2"] = r2
    w2 = float(np.hypot(beta[0], beta[1]))
    if (out["excitation"] or 0.0) < MIN_EXCITATION or r2 < MIN_R2 or w2 <= 0:
        return out
    se = _share_se(X, r, G / w2)
    out["inertia_share_se"] = se
    if not se <= MAX_SHARE_SE:
        return out
    out.update(inertia_share=float(beta[3] * G / w2), rotation_coupling=float(beta[4]),
               swing_period_s=float(2 * np.pi / np.sqrt(w2)))
    return out


def string_response(frame_t, tracked, valid, hand_t, hand) -> dict:
    """Does the tracked string feel its grasp's acceleration? :func:`inertial_response` of the chords to the
    points :func:`chord_points` names, and their medians (docs/method.md, "The field recording").

    Parameters
    ----------
    frame_t : ndarray, (F,)
        Frame times on the controller clock, s, increasing.
    tracked : ndarray, (F, n, 2)
        The tracked points 1..n, m in the robot frame.
    valid : ndarray of bool, (F, n)
        Which tracked points are valid.
    hand_t : ndarray, (K,)
        The hand's sample times, s, increasing.
    hand : ndarray, (K, 3)
        The grasp's x and y (m) and the hand's angle (rad), from the forward kinematics.

    Returns
    -------
    dict
        ``inertia_share`` (the acceleration term's gain over a pendulum's; 1 for a string in air),
        ``rotation_coupling``, ``swing_period_s`` (s): medians over the points whose share is stated
        (None where none is); ``fit_r2`` and ``excitation`` of the first point; ``points`` (1-based) the
        share was stated for; ``per_point``: each chord's share, coupling, ``fit_r2`` and standard error
        by point (1-based).

    Raises
    ------
    ValueError
        The arrays' shapes disagree (:func:`inertial_response`).
    """
    n = np.asarray(tracked).shape[1]
    rows = {pt: inertial_response(frame_t, tracked, valid, hand_t, hand, pt) for pt in chord_points(n)}
    stated = {pt: r for pt, r in rows.items() if r["inertia_share"] is not None}
    first = next(iter(rows.values()))

    def med(key):
        return float(np.median([r[key] for r in stated.values()])) if stated else None
    return {"inertia_share": med("inertia_share"), "rotation_coupling": med("rotation_coupling"),
            "swing_period_s": med("swing_period_s"), "fit_r2": first["fit_r2"], "excitation": first["excitation"],
            "points": [pt + 1 for pt in stated],
            "per_point": {str(pt + 1): {k: r[k] for k in ("inertia_share", "rotation_coupling", "fit_r2",
                                                          "inertia_share_se")} for pt, r in rows.items()}}
