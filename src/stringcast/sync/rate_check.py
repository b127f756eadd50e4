"""Does the video run at the frame rate ``video.yaml`` says? (an fps off by a factor)

The sync puts frame k at ``offset_s + k / fps`` on the controller clock. An ``fps`` off by a factor
(100000 for 500, 50 for 500) stretches or squeezes the whole video against the joint log: no offset
lines the arm seen in the frames up with its forward kinematics, the video's estimate fails or is
poor, and the later stages work on frames at the wrong times (issue 51: tracking crashed, and no
message named ``fps``).

:func:`clock_rate` asks each frame when it was taken, without the frame rate: the arm seen in a
frame (the sync's strips across its segments, :mod:`stringcast.sync.arm_match`, against the still
arm's template) matches the arm's forward kinematics at one instant of the joint log's motion
best. Over :data:`N_FRAMES` frames spread over the video, those whose match peaks inside the
motion (a frame at rest matches every still posture alike) give pairs (k, t_k); a robust line
through them (Theil-Sen: the median of the pairwise slopes, :func:`theil_sen`) has the slope 1 / (the frames' true rate). It is
named where at least :data:`MIN_FRAMES` frames, and :data:`MIN_SHARE` of those matched, lie within
:data:`MAX_SPREAD` pose steps of the line, spanning :data:`MIN_SPAN` of the motion, and the rate
differs from ``fps`` by more than :data:`MIN_RATE_ERROR`. It runs only where the
sync's verdict is not ok; the evidence is the arm's own motion, in s of the log.
"""
from __future__ import annotations

import numpy as np

from . import arm_match as sync_arm
from .video_offset import _rest_and_board, _segments_in_view
from stringcast.core import BoardCheckSettings, SyncSettings, joints_at, motion_window

N_FRAMES = 120
"""Frames asked when they were taken (an even stride over the video)."""
POSE_STEP_S = 0.004
"""The joint log's motion is matched every this many s (a frame's time is refined by a parabola)."""
MIN_FRAMES = 8
"""Frames on the line a rate needs ..."""
MIN_SHARE = 0.6
"""... and this share of the frames matched inside the motion (a calibration that puts the arm
elsewhere matches frames to scattered instants: 44 of 104 on a line, square_mm 50 for 60) ..."""
MIN_SPAN = 0.5
"""... spanning this share of the motion's duration on the log's clock."""
MAX_SPREAD = 3.0
"""A frame lies on the line within this many pose steps."""
MIN_RATE_ERROR = 0.1
"""A rate named must differ from video.yaml's by more than this share (10 %): on the field recording
(another lab's arm, weak intrinsics; its fps right) the frames' own times gave a rate 3 % off, on
the lab's trial 0.1 %."""


def frames_seen_at(video, calibration, arm, t_j: np.ndarray, q_j: np.ndarray, sync: SyncSettings,
                   board_check: BoardCheckSettings) -> tuple[np.ndarray, np.ndarray]:
    """Frames (K,) whose arm matches one instant of the joint log's motion, and those instants (K,) s.

    Raises:
        DataError: no arm segment in view, or the log never moves (as the sync's own search).
    """
    hw = sync_arm.segment_half_widths(arm, sync.strip_margin_mm / 1000)
    n_u, n_v, sig = int(sync.strip_samples), int(sync.strip_width_samples), float(sync.smooth_px)
    hw, segments = _segments_in_view(video, calibration, arm, q_j[0], hw, n_u, n_v)
    _, rest, _, shift = _rest_and_board(video, calibration, arm, q_j[0], sync, board_check)
    template = sync_arm.sample_strips(sync_arm.smooth(rest, sig), calibration, arm, q_j[0][None], hw, n_u, n_v,
                                      segments, shift)[0]
    try:
        t_on, t_off = motion_window(t_j, q_j)
    except ValueError:
        return np.zeros(0, int), np.zeros(0)
    tq = np.arange(t_on - 2 * POSE_STEP_S, t_off + 2 * POSE_STEP_S, POSE_STEP_S)
    poses = joints_at(tq, t_j, q_j)
    ks, ts = [], []
    for k in np.unique(np.linspace(0, video.n_frames - 1, min(video.n_frames, N_FRAMES)).astype(int)):
        c = sync_arm.ncc(sync_arm.smoothed_strips(video.read(int(k)), sig, calibration, arm, poses, hw, n_u, n_v,
                                                  segments, shift), template)
        j = int(np.argmax(c))
        if float(np.ptp(c)) >= sync.min_frame_contrast and 2 <= j <= len(c) - 3:
            ks.append(int(k))
            ts.append(sync_arm.parabola_peak(tq[j - 1:j + 2], c[j - 1:j + 2]))
    return np.asarray(ks, int), np.asarray(ts, float)


def theil_sen(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """The Theil-Sen line through points (x (N,), y (N,)): the median of the slopes between every two
    points with different x, and the median of y - slope x as the intercept (Sen 1968). Robust to
    nearly half the points off the line; NaN slope with fewer than two distinct x. (SciPy's
    ``theilslopes`` loads ``scipy.optimize``, which the sync stage does not otherwise need.)"""
    x, y = np.asarray(x, float), np.asarray(y, float)
    i, j = np.triu_indices(len(x), 1)
    dx = x[j] - x[i]
    ok = dx != 0
    if not ok.any():
        return float("nan"), float("nan")
    slope = float(np.median((y[j] - y[i])[ok] / dx[ok]))
    return slope, float(np.median(y - slope * x))


def clock_rate(video, calibration, arm, t_j: np.ndarray, q_j: np.ndarray, sync: SyncSettings,
               board_check: BoardCheckSettings, fps: float) -> dict | None:
    """The frames' rate as the arm's motion shows it, where it differs from ``fps`` (module doc):
    ``{"fps_fits", "rate" (fps / fps_fits: how many times as far apart the frames are), "offset_s"
    (frame 0's time at that rate), "frames" (on the line), "frames_in_motion"}``, or None.

    Raises:
        DataError: as :func:`frames_seen_at`.
    """
    ks, ts = frames_seen_at(video, calibration, arm, t_j, q_j, sync, board_check)
    if len(ks) < MIN_FRAMES:
        return None
    slope, icpt = theil_sen(ks, ts)
    on = np.abs(ts - (icpt + slope * ks)) <= MAX_SPREAD * POSE_STEP_S
    t_on, t_off = motion_window(t_j, q_j)
    if (on.sum() < max(MIN_FRAMES, MIN_SHARE * len(ks)) or not slope > 0
            or float(np.ptp(ts[on])) < MIN_SPAN * (t_off - t_on)):
        return None
    slope, icpt = theil_sen(ks[on], ts[on])
    rate = slope * fps
    if not slope > 0 or abs(rate - 1) <= MIN_RATE_ERROR:
        return None
    return {"fps_fits": float(1 / slope), "rate": float(rate), "offset_s": float(icpt), "frames": int(on.sum()),
            "frames_in_motion": int(len(ks))}


def rate_reason(found: dict, fps: float, video_yaml) -> str:
    """The sync's reason for a rate found (:func:`clock_rate`), naming ``fps`` in ``video_yaml``."""
    return (f"the arm in the frames follows the joint log's motion at {found['fps_fits']:.4g} frames per s "
            f"({found['frames']} of {found['frames_in_motion']} frames matched to it lie on one line), not at fps "
            f"{fps:g}: the frames are {found['rate']:.3g} times as far apart as video.yaml says; check fps in "
            f"{video_yaml}")


__all__ = ["clock_rate", "frames_seen_at", "rate_reason"]
