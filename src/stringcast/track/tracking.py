"""Markerless string tracking: video -> mass-point series in the robot frame.

:func:`run_tracking` writes ``tracks.parquet`` (``frame, t_s, point, x_m, y_m, valid``;
point 0 = grasp, 1..n = the model's points at arc length s_i = i L / n, n = tip).
Settings: tracking settings (:class:`~stringcast.core.TrackingSettings`).

1. **Background** (:func:`~stringcast.track.background.build_background`): the arm-masked temporal
   median of ``background_samples`` frames spread over the arm's motion in ``background_bursts``
   short runs (:func:`~stringcast.track.background.background_samples`: only the runs are decoded; the
   string and arm hang still before the motion, and again after it; ``background_window_s``
   limits the samples to the motion's first seconds, for containers that cannot seek: but a string that leaves its rest
   place late in that span becomes background there, and is lost at rest), pixels the arm
   covers throughout taken from pre-motion frames; the same samples give the sensor's noise
   model sigma^2 = a + b B. The main pass decodes ahead in a thread (:mod:`stringcast.video.decode_ahead`).
2. **Segmentation** (per frame, within L + ``roi_margin_mm`` of the grasp): a gain for
   flicker ``g = median(I / B)``, ``|I - g B|`` smoothed by a Gaussian, and a hysteresis
   threshold in units of the *local* noise sigma (``threshold_low/high``); polarity free.
3. **Arm mask** from the *measured* joints at the start, middle and end of each frame period
   (:func:`~stringcast.track.arm_mask.draw_arm_mask`), plus a guard band of ``arm_guard_px``.
4. **Centreline** (:mod:`stringcast.track.centreline`): skeleton of the foreground; the longest walk
   (:func:`~stringcast.track.junctions.walk_skeleton`) from near the grasp (or from just outside its clear
   zone, past a hook at the fingertips), through a crossing by
   the smoothest way on (a pass whose choice is a guess, or by an arm never walked, is an
   ambiguity), bridging gaps up to ``max_gap_px`` (bridged parts are never valid); the first
   ``grasp_clear_mm`` replaced by a circular arc from the grasp (:func:`hidden_arc`); sub-pixel
   refinement across the path, smoothing that keeps bends, chords of ``arc_step_px`` joined
   by a spline; a free end (:func:`clean_end`: not fading, not at an occluder's rim, not
   within ``end_touch_mm`` of the string's own earlier stretch, no branch within a point
   spacing, no arm or image edge within a string width + 4 px:
   :func:`~stringcast.track.ends.end_cut`, no string-like contrast going on past it:
   :func:`string_continues`) is extended to where the contrast fades, or to a clay ball's
   centre (:func:`~stringcast.track.ends.locate_end`).
5. **Metric resampling** (:func:`resample_by_arc`): :meth:`Calibration.pixel_to_robot`, arc
   length from the grasp, points at s_i = i L / n. With a trusted free end whose length
   agrees with L (within ``anchor_tol_mm`` / ``anchor_tol_px``), the mismatch is shared
   among the hidden head, the visible arc and the free end by their uncertainties
   (:func:`mismatch_split`); a longer mismatch (the start hidden or folded behind the
   gripper) anchors the arc at the free end, valid after the last ambiguity (a branch
   joining the walk, a guess at a crossing, a bridged gap) and, for a missing length D, not
   within D past the hidden head (a loop at the fingers); but an end over the calibration
   board is the tip only where its length agrees (a square of the string's shade may hide the
   rest: :mod:`stringcast.track.board_zone`). A string seen *longer* than L to a trusted free
   end, by up to ``max_stretch_share`` of L and with no ambiguity on the way, is stretched (an
   elastic cord under a cast, or an image scale off by as much): its points lie at s_i = (i / n)
   times the seen length (uniform strain; the tip at the tip). Without a free end, the arc is
   anchored at the grasp, valid before the first ambiguity, its points spread by the stretch seen
   in the frames within ``stretch_hold_ms`` (:mod:`stringcast.track.held_stretch`; 1 for a string
   that does not stretch). Where the walk stops at the arm (the string passes behind a link), the one
   stretch that comes out from behind it and ends free (:mod:`stringcast.track.beyond_arm`) adds
   its points, anchored at the tip in the same way. Invalid points keep NaN positions: never a guess.
   A point outside the image is never valid: a stretch of the path with a vertex outside the
   region tracked holds none (:func:`~stringcast.track.centreline.seen_segments`), and every
   point is checked against the image once more before ``tracks.parquet`` is written.
6. **Verdict** (:mod:`stringcast.track.quality`, ``tracking.json``), over every frame a later stage
   compares (the motion's start to the joint log's end): the valid share, consecutive points
   farther apart than the string between them and the hanging string's jitter, judged (warn
   with the likely cause); the measured length against L, reported, and judged where it says
   the string filmed is not the campaign's.
7. **Markers** (``mode: markers``, :mod:`stringcast.track.markers`): strings with a band at each mass
   point; a point's position is its band's centre on the centreline, valid where step 5 trusts
   the order along the path and the band is found whole and unambiguous.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from stringcast.core import TrackingSettings, forward_kinematics, joints_at, motion_window
from .arm_mask import draw_arm_mask
from .background import background_samples, build_background
from stringcast.calibrate import Calibration
from stringcast.core import (DataError, TrialFiles, joint_log_span, read_joint_table, read_json, write_json,
                             write_parquet)
from .frame_tracker import FrameTracker
from .held_stretch import held_stretch, respread_frames
from .parallel import track_frames
from .overlay import write_overlay
from .quality import frames_judged, tracking_quality
from stringcast.video import prefetch
from stringcast.sync import frame_times
from stringcast.video import CachedVideo, open_trial_video


def _joint_px(cal: Calibration, arm, q: np.ndarray) -> np.ndarray:
    pts = forward_kinematics(arm, q)  # (F, J + 2, 2)
    return cal.robot_to_pixel(pts.reshape(-1, 2)).reshape(pts.shape)


def _scale_note(cal: Calibration, campaign) -> str | None:
    """What the calibration said where it saw the still arm at a scale (its board check's ``arm_scale``), or None."""
    found = (cal.board_check or {}).get("arm_scale") if isinstance(cal.board_check, dict) else None
    if not found:
        return None
    return (f"the calibration sees the still arm scaled by {float(found['scale']):.3f} against its forward kinematics; "
            f"check {campaign.setup_setting('board.square_mm')}")


def inside_image(cal: Calibration, xy: np.ndarray) -> np.ndarray:
    """Whether robot-frame points xy (..., 2) m lie in the image (:meth:`Calibration.robot_to_pixel`:
    within the pixels' area, -0.5 .. W - 0.5 and -0.5 .. H - 0.5): (...,) bool, False for NaN."""
    xy = np.asarray(xy, float)
    flat = xy.reshape(-1, 2)
    fin = np.all(np.isfinite(flat), axis=1)
    uv = np.full(flat.shape, np.nan)
    if fin.any():
        uv[fin] = cal.robot_to_pixel(flat[fin])
    w, h = cal.image_size
    with np.errstate(invalid="ignore"):
        inside = (uv[:, 0] >= -0.5) & (uv[:, 0] <= w - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= h - 0.5)
    return inside.reshape(xy.shape[:-1])


@dataclass(frozen=True)
class TrackedVideo:
    """What :func:`track_video` finds in a video.

    Attributes
    ----------
    table : DataFrame
        The long table ``frame, t_s, point, x_m, y_m, valid`` ((n + 1) rows per frame; s; m in the robot
        frame; point 0 the grasp; invalid points NaN), ``tracks.parquet``'s content.
    quality : dict
        The tracking's self-measures and verdict (:func:`~stringcast.track.quality.tracking_quality`),
        ``tracking.json``'s content.
    shown : list
        The frames kept for the overlay: (frame index, image (H, W), centreline px, points px, valid);
        empty unless asked for.
    m_per_px : float
        The image scale near the grasp, m / px (median over the frames).
    """

    table: pd.DataFrame
    quality: dict
    shown: list = field(default_factory=list)
    m_per_px: float = float("nan")


def track_video(video, calibration: Calibration, frame_times_s: np.ndarray, t_j: np.ndarray, q_j: np.ndarray,
                campaign, *, tracking: TrackingSettings, fps: float | None = None, joint_log: dict | None = None,
                workers: int = 1, overlay: bool = False) -> TrackedVideo:
    """Track the string in a video already open, in memory (the module doc's steps 1-6).

    Parameters
    ----------
    video : VideoReader
        The trial's frames (:func:`~stringcast.video.open_trial_video`; a
        :class:`~stringcast.video.CachedVideo` is read by ``workers`` processes side by side, any other
        reader is tracked as it decodes, with a second reader of its path for the background).
    calibration : Calibration
        The trial's mapping (``geometry.json`` or ``calibration.json``), for ``video``'s image size.
    frame_times_s : ndarray, (F,)
        Each frame's time on the controller clock, s (:func:`~stringcast.sync.frame_times`).
    t_j, q_j : ndarray, (K,) and (K, J)
        The joint log, s and rad.
    campaign : Campaign
        The resolved campaign (arm, string length L, n points).
    tracking : TrackingSettings
    fps : float, optional
        The clock's frame rate, frames / s (``sync.json``'s ``fps``); default ``video.fps``.
    joint_log : dict, optional
        ``sync.json``'s ``joint_log`` (an extended log: the arm known outside its span).
    workers : int
        Processes tracking frames side by side (a :class:`~stringcast.video.CachedVideo` only);
        the same result for any number.
    overlay : bool
        Keep ``tracking.overlay_frames`` frames for the overlay figure.

    Returns
    -------
    TrackedVideo
        The tracked points, the tracking's verdict and the overlay's frames.
    """
    st, cal = tracking, calibration
    t = np.asarray(frame_times_s, float)
    arm, n, F = campaign.arm, campaign.string.n_points, len(t)
    lo, hi = joint_log_span(t_j, joint_log)   # an extended log: the arm still outside it
    in_log = (t >= lo) & (t <= hi)
    half = 0.5 / float(fps or video.fps)  # the arm at the start, middle and end of each frame period
    jpx = np.stack([_joint_px(cal, arm, joints_at(t + dt, t_j, q_j)) for dt in (-half, 0.0, half)], axis=1)
    scale = float(np.median(cal.m_per_px(jpx[:, 1, -1])))
    motion = _motion_span(t_j, q_j)
    judged, rest = frames_judged(t, in_log, motion[0], hi)   # the frames tracking.json judges
    frames = None if isinstance(video, CachedVideo) else prefetch(video, int(st.prefetch_frames))  # runs ahead
    tracker, win = _tracker(video, cal, t, motion, in_log, jpx, scale, np.nonzero(rest)[0], campaign, st, workers)
    xy = np.full((F, n + 1, 2), np.nan)
    valid = np.zeros((F, n + 1), bool)
    mismatch = np.full(F, np.nan)
    past_roi, off_image, stretch = np.zeros(F, bool), np.zeros(F, bool), np.ones(F)
    unplaced = np.full(F, "", dtype=object)
    measured, arcs = np.full(F, np.nan), {}
    xy[:, 0] = forward_kinematics(arm, joints_at(t, t_j, q_j))[:, -1]  # point 0: the grasp
    valid[:, 0] = in_log
    xy[~in_log, 0] = np.nan
    shows = set(np.round(np.linspace(win[0], win[-1], int(st.overlay_frames))).astype(int)) if overlay else set()
    shown = []
    for k, ft, frame in track_frames(tracker, video, frames, jpx, np.flatnonzero(in_log), shows, workers):
        xy[k, 1:], valid[k, 1:], mismatch[k] = ft.positions, ft.valid, ft.length_mismatch_m
        past_roi[k], off_image[k], stretch[k], unplaced[k] = ft.past_roi, ft.off_image, ft.stretch, ft.unplaced
        if ft.stretch_seen:
            measured[k] = ft.seen_ratio
        elif ft.grasp_arc is not None or ft.tip_arc is not None:
            arcs[k] = (ft.grasp_arc, ft.tip_arc)
        if frame is not None:
            shown.append((k, frame, ft.path_px))
    # the end not seen: the points spread by the stretch seen in the frames about it
    held = held_stretch(t, measured, st.stretch_hold_ms / 1000, st.scale_sigma)
    spread = respread_frames(held, arcs, tracker.s_targets)
    for k, (pos, ok, s) in spread.items():
        xy[k, 1:], valid[k, 1:], stretch[k] = pos, ok, s
    shown = [(k, frame, path, cal.robot_to_pixel(np.nan_to_num(xy[k])), valid[k].copy()) for k, frame, path in shown]
    valid[:, 1:] &= inside_image(cal, xy[:, 1:])   # a point outside the image is never valid (nor its position)
    xy[:, 1:][~valid[:, 1:]] = np.nan
    df = pd.DataFrame({
        "frame": np.repeat(np.arange(F), n + 1).astype(np.int64),
        "t_s": np.repeat(t, n + 1),
        "point": np.tile(np.arange(n + 1), F).astype(np.int64),
        "x_m": xy[..., 0].ravel(), "y_m": xy[..., 1].ravel(),
        "valid": valid.ravel(),
    })
    seen = measured[judged][np.isfinite(measured[judged])]
    stretch_frames = {"measured_frames": len(seen), "measured_p95": float(np.percentile(seen, 95)) if len(seen) else None,
                      "held_frames": int(sum(judged[k] for k in spread)),
                      "unheld_frames": int(sum(judged[k] and not np.isfinite(held[k]) for k in arcs))}
    quality = tracking_quality(df, mismatch, campaign.string.length, n, judged, rest, st, past_roi, off_image,
                               campaign.string_setting, _scale_note(cal, campaign), stretch, unplaced, stretch_frames)
    return TrackedVideo(df, quality, shown, scale)


def _motion_span(t_j: np.ndarray, q_j: np.ndarray) -> tuple[float, float]:
    """The arm's motion window (s), or the log's span where the arm never moves."""
    try:
        return motion_window(t_j, q_j)
    except ValueError:  # the arm never moves
        return float(t_j[0]), float(t_j[-1])


def _tracker(video, cal: Calibration, t: np.ndarray, motion: tuple[float, float], in_log, jpx, scale: float,
             rest: np.ndarray, campaign, st: TrackingSettings, workers: int) -> tuple[FrameTracker, np.ndarray]:
    """The frame tracker over the background of ``video`` (step 1; ``motion``: the arm's motion window, s;
    ``rest``: the still frames before the motion, indices), and the motion's frames (indices)."""
    t_start, t_end = motion
    win = np.nonzero((t >= t_start) & (t <= t_end + 0.1) & in_log)[0]
    if len(win) < 9:
        win = np.arange(len(t))
    span = st.background_window_s   # None: the whole motion window (the string hangs still in a short one)
    early = win if span is None else win[t[win] <= t[win[0]] + span]
    bwin = early if len(early) >= 9 else win
    samples = background_samples(bwin, int(st.background_samples), int(st.background_bursts))
    pre = rest[-int(st.rest_frames):]
    cached = isinstance(video, CachedVideo)
    second = video if cached else open_trial_video(video.path)  # decoding: the main pass runs ahead
    try:
        bg, noise = build_background(second, samples.astype(int), pre, lambda k: draw_arm_mask(
            (video.height, video.width), jpx[k], campaign.arm, st, scale, grow_px=2.0), workers if cached else 1)
    finally:
        if second is not video:
            second.close()
    return FrameTracker(bg, noise, cal, campaign, st), win


def run_tracking(trial: TrialFiles | str | Path, geometry_json, clock_json, campaign, out_parquet, overlay_png=None,
                 frames_npy=None, workers: int = 1, quality_json: str | Path | None = None, *,
                 tracking: TrackingSettings) -> pd.DataFrame:
    """Track the string in one trial (:func:`track_video`); write ``tracks.parquet``, ``tracking.json``
    (the tracking's self-measures and verdict, :mod:`stringcast.track.quality`) and the overlay PNG.

    Parameters
    ----------
    trial : TrialFiles, str or Path
        The trial's video and ``joints.csv`` (:class:`~stringcast.core.TrialFiles`; a folder: its files by
        the data contract's names).
    geometry_json, clock_json : str or Path
        This trial's ``geometry.json`` and ``clock.json`` (or, before the sweep, ``calibration.json`` and
        ``sync.json``).
    campaign : Campaign
        The resolved campaign (arm, string length L and n).
    out_parquet : str or Path
        Where to write ``tracks.parquet``.
    overlay_png : str or Path, optional
        If given, a strip of ``overlay_frames`` frames with the tracked points.
    frames_npy : str or Path, optional
        The video's frames decoded once (:func:`~stringcast.video.write_frame_cache`), read instead of
        decoding the video; None: decode it (the background's frames a second time).
    workers : int
        Processes that track frames side by side, from ``frames_npy`` only (a video being decoded is
        tracked in this process, as it is decoded); the same result for any number.
    quality_json : str or Path, optional
        Where to write ``tracking.json`` (None: beside ``out_parquet``).
    tracking : TrackingSettings

    Returns
    -------
    DataFrame
        The long table ``frame, t_s, point, x_m, y_m, valid``, (n + 1) rows per frame, s and m in the
        robot frame; frames outside the joint log are all invalid.

    Raises
    ------
    DataError
        Missing or malformed inputs (named), or a frame count or image size that disagrees with the
        clock or the geometry.
    """
    trial = TrialFiles.of(trial)
    cal = Calibration.from_json(geometry_json)
    clock = read_json(clock_json, mapping=True)
    t_j, q_j = read_joint_table(trial.joints, n_joints=campaign.arm.n_joints, arm_name=campaign.arm.name)
    video = open_trial_video(trial.video, frames_npy)
    try:
        if (video.width, video.height) != tuple(cal.image_size):
            raise DataError(f"{video.path}: frames are {video.width}x{video.height}, {geometry_json} is for "
                            f"{cal.image_size[0]}x{cal.image_size[1]}")
        F = video.n_frames
        if "frames" in clock and int(clock["frames"]) != F:
            raise DataError(f"{video.path}: {F} frames, but {clock_json} (from video.yaml) says {clock['frames']}")
        found = track_video(video, cal, frame_times(clock, F), t_j, q_j, campaign, tracking=tracking,
                            fps=float(clock["fps"]), joint_log=clock.get("joint_log"), workers=workers,
                            overlay=overlay_png is not None)
    finally:
        video.close()
    write_parquet(out_parquet, found.table)
    write_json(Path(out_parquet).with_name("tracking.json") if quality_json is None else quality_json, found.quality)
    if overlay_png is not None:
        write_overlay(overlay_png, found.shown, found.table["t_s"].to_numpy()[::campaign.string.n_points + 1],
                      found.m_per_px, campaign.string.length)
    return found.table
