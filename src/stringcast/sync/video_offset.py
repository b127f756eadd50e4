"""The video's estimate of the clock offset: the arm seen in the frames against the forward
kinematics of the joint log (:mod:`stringcast.sync.arm_match` describes the method).

:func:`estimate_offset` returns the offset with its quality figures and the evidence behind
it (:class:`VideoEvidence`: every frame's and segment's own best offset and match score),
which :mod:`stringcast.sync.confidence` uses to weigh the video's estimate against a trigger time.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from . import arm_match as sync_arm
from stringcast.calibrate import check_board_to_robot
from stringcast.core import BoardCheckSettings, DataError, SyncSettings, joints_at, motion_window
from stringcast.core import chunked, forked_map
from stringcast.video import CachedVideo

FRAMES_PER_TASK = 16
"""Frames one worker matches per task in the fine search (a few ms each)."""


@dataclass(frozen=True)
class VideoEvidence:
    """What the video's estimate rests on, for weighing it (:mod:`stringcast.sync.confidence`).

    Attributes:
        taus: (T,) s, the candidate offsets of the fine search (a grid of ``step_ms``).
        per_frame: (C, T, S) the NCC of each frame with contrast (C of them), at each candidate
            offset, for each segment in view (S); summed over frames and the agreeing segments it
            is the score whose peak is the offset.
        keep: (S,) bool, the segments that agree (used for the offset).
        tau_ks: (F, S) s, each motion frame's and segment's own best offset (NaN where flat).
        speeds: (F, S) m/s, each segment's speed across itself at those frames.
        fps: the frame rate, Hz.
        mm_per_px: the image scale at the arm's rest posture, mm per px.
        arm_width_mm: the narrowest agreeing segment's width (the arm's outline), mm.
    """

    taus: np.ndarray
    per_frame: np.ndarray
    keep: np.ndarray
    tau_ks: np.ndarray
    speeds: np.ndarray
    fps: float
    mm_per_px: float
    arm_width_mm: float


def estimate_offset(video, calibration, arm, t_j: np.ndarray, q_j: np.ndarray,
                    sync: SyncSettings, board_check: BoardCheckSettings, trigger_s: float | None = None,
                    workers: int = 1) -> dict:
    """Offset of frame 0 on the controller clock, from the arm seen in the video.

    Args:
        video: a :class:`~stringcast.video.container.VideoReader` (fps known). calibration:
            :class:`~stringcast.calibrate.calibration.Calibration`. t_j (K,) s, q_j (K, J) rad: the
            joint log.
        sync: sync settings (:class:`~stringcast.core.SyncSettings`).
        board_check: the board check's settings (:class:`~stringcast.core.BoardCheckSettings`), for
            the check on the rest frames when the calibration has none.
        trigger_s: the recording's trigger time, a starting guess only (whether it or the estimate is used is
            :func:`stringcast.sync.confidence.choose_offset`'s choice).
        workers: processes matching frames side by side, where ``video`` is a decoded
            :class:`~stringcast.video.CachedVideo` (the same result for any number).

    Steps: the board check on the median of the rest frames gives the translation d
    between where the still arm is seen and its FK position; the strips are moved by d
    (so a board pose or calibration error does not bias the timing); coarse and fine
    search as in :mod:`stringcast.sync.arm_match`, the search window re-centred on the peak
    until it sits within ``recentre_ms`` of the centre (on a fixed grid of candidate
    offsets, so the result does not depend on the starting guess); each segment's NCC is
    summed over the frames (a few bad frames only flatten their own curve), a segment
    whose own peak is more than ``segment_agree_ms`` from the median of the segments'
    peaks is left out (a static feature such as a cable behind it in the rest template
    pulls its match towards the rest posture), and the peak of the others' sum is the
    offset; the residual in mm is :func:`~stringcast.sync.arm_match.match_residual` over every
    frame's and segment's own best offset.

    Returns:
        dict with offset_s (s, exposure centre of frame 0), residual_mm (None if too few
        matches), residual_matches, arm_shift_mm (the board check's translation applied
        to the strips), time_residual_ms, frames_used, board_check, coarse_offset_s (None
        if the coarse search was not needed), segment_offsets_s, segments_used,
        segments_in_view, score_curve, and evidence (:class:`VideoEvidence`, not JSON).

    Raises:
        DataError: the video has no still frames of the arm before the motion, or no
            frame in the motion.
    """
    fps, st = float(video.fps), sync
    hw = sync_arm.segment_half_widths(arm, st.strip_margin_mm / 1000)
    n_u, n_v, sig = int(st.strip_samples), int(st.strip_width_samples), float(st.smooth_px)
    hw, segments = _segments_in_view(video, calibration, arm, q_j[0], hw, n_u, n_v)
    n_rest, rest, board, shift = _rest_and_board(video, calibration, arm, q_j[0], st, board_check)

    def strips(q):
        return sync_arm.strip_points(arm, q, hw, n_u, n_v, segments) + shift

    def strip_samples(image, q):  # sample(image, calibration, strips(q)), bit for bit, in one pass
        return sync_arm.sample_strips(image, calibration, arm, q, hw, n_u, n_v, segments, shift)

    def frame_strips(frame, q):  # strip_samples(smooth(frame, sig), q), smoothing only where the strips are
        return sync_arm.smoothed_strips(frame, sig, calibration, arm, q, hw, n_u, n_v, segments, shift)

    rest_pts = strips(q_j[0])
    rest_s = sync_arm.smooth(rest, sig)
    template = strip_samples(rest_s, q_j[0][None])[0]  # sample(rest_s, calibration, rest_pts); loads the kernel before any fork
    try:
        t_on, t_off = motion_window(t_j, q_j)
    except ValueError as exc:
        raise DataError(f"{video.path}: sync from the video needs the arm to move: {exc}") from exc
    search, step = st.search_ms / 1000, st.step_ms / 1000
    coarse = partial(_coarse_search, video, calibration, frame_strips, rest_s, template, strips, n_rest, t_j, q_j,
                     fps, st)
    fine = partial(_fine_search, video, template, frame_strips, t_j, q_j, fps, (t_on, t_off), search,
                   step, len(segments), st, workers if isinstance(video, CachedVideo) else 1, {})
    coarse_s, (taus, total, best, frames, tau_ks, per_frame) = _recentred_search(coarse, fine, trigger_s, step, st)
    if not best:
        raise DataError(f"{video.path}: the arm's motion is not visible in the frames (no frame's match with the "
                        "forward kinematics depends on the offset)")
    seg_peaks, keep, offset = _segment_offset(taus, total, per_frame.sum(axis=0), len(segments), st)
    speeds = _speeds(arm, t_j, q_j, frames, fps, offset, segments, n_u)
    residual_mm, n_eq = sync_arm.match_residual(tau_ks, speeds, offset)
    mad = float(np.median(np.abs(np.asarray(best) - offset))) * 1.4826
    widths = 2 * sync_arm.segment_half_widths(arm, 0.0)[segments]
    mm_per_px = 1000 * float(np.median(calibration.m_per_px(calibration.robot_to_pixel(rest_pts.reshape(-1, 2)))))
    width_mm = 1000 * float(widths[keep].min() if keep.any() else widths.min())
    evidence = VideoEvidence(taus, per_frame, keep, tau_ks, speeds, fps, mm_per_px, width_mm)
    return {"offset_s": offset, "time_residual_ms": mad * 1000, "frames_used": len(best), "board_check": board,
            "coarse_offset_s": coarse_s, "residual_mm": residual_mm,
            "residual_matches": n_eq, "arm_shift_mm": (shift * 1000).tolist(),
            "segment_offsets_s": seg_peaks.tolist(), "segments_used": [int(j) for j in segments[keep]],
            "segments_in_view": [int(j) for j in segments],
            "score_curve": {"offset_s": taus.tolist(), "ncc_sum": total.tolist()}, "evidence": evidence}


def _segments_in_view(video, calibration, arm, q0: np.ndarray, hw: np.ndarray, n_u: int,
                      n_v: int) -> tuple[np.ndarray, np.ndarray]:
    """The arm segments wholly in view at the start posture q0 (J,) rad: their strip half widths (S,) m
    and their indices (S,) among all the arm's segments.

    Raises:
        DataError: no segment is.
    """
    rest_pts = sync_arm.strip_points(arm, q0, hw, n_u, n_v)
    uv = calibration.robot_to_pixel(rest_pts.reshape(-1, 2)).reshape(rest_pts.shape)
    seen = np.all((uv >= 0) & (uv <= np.array([video.width - 1, video.height - 1])), axis=(1, 2, 3))
    if not seen.any():
        raise DataError(f"{video.path}: no segment of the arm is wholly in view at the start posture; sync "
                        "from the video needs one (or set sync.method: trigger)")
    return hw[seen], np.nonzero(seen)[0]


def _rest_and_board(video, calibration, arm, q0: np.ndarray, st: SyncSettings,
                    board_check: BoardCheckSettings) -> tuple[int, np.ndarray, dict, np.ndarray]:
    """The rest frames: their count n_rest, their median image (H, W) float32, the board check on it
    (calibrate's, if it ran) and the check's translation (2,) m (zero without a check residual)."""
    n_rest = max(1, min(int(st.rest_frames), video.n_frames))
    rest = np.median(np.stack([video.read(k).astype(np.float32) for k in range(n_rest)]), axis=0)
    board = calibration.board_check or check_board_to_robot(  # calibrate's, if it ran
        rest, calibration, arm, q0, board_check)
    shift = np.zeros(2) if board["residual_mm"] is None else np.array([board["dx_mm"], board["dy_mm"]]) / 1000
    return n_rest, rest, board, shift


def _coarse_search(video, calibration, frame_strips, rest_s: np.ndarray, template: np.ndarray,
                   strips, n_rest: int, t_j: np.ndarray, q_j: np.ndarray, fps: float, st: SyncSettings) -> float:
    """The coarse offset, s (:func:`stringcast.sync.arm_match.coarse_offset`): every frame's match with the rest
    template against the predicted match of the rest image at the arm's logged postures (1 ms grid).
    ``strips(q)``: the shifted strip points of postures q; ``frame_strips(frame, q)``: the frame, smoothed,
    sampled there.

    Raises:
        DataError: the first frames do not show the arm still at the log's first posture.
    """
    rest_ncc = np.array([sync_arm.ncc(frame_strips(f, q_j[:1])[0], template) for _, f in video])
    if np.mean(rest_ncc[:n_rest]) < 0.9:
        raise DataError(f"{video.path}: the first frames do not show the arm still at the joint log's first "
                        "posture; sync needs the video to start before the motion")
    tp = np.arange(t_j[0], t_j[-1], 1e-3)
    pred = sync_arm.ncc(sync_arm.sample(rest_s, calibration,
                                        strips(joints_at(tp, t_j, q_j))),
                        template)
    return sync_arm.coarse_offset(rest_ncc, fps, tp, pred, st.coarse_step_ms / 1000)


def _fine_search(video, template: np.ndarray, frame_strips, t_j: np.ndarray, q_j: np.ndarray,
                 fps: float, window: tuple[float, float], search: float, step: float, n_seg: int, st: SyncSettings,
                 workers: int, memo: dict, tau0: float) -> tuple[np.ndarray, np.ndarray, list, np.ndarray, np.ndarray, np.ndarray]:
    """Each motion frame's match over the candidate offsets taus = tau0 +- search (step), s.

    ``frame_strips(frame, q)``: the frame, smoothed, sampled at the (shifted) strips of postures q (T, J).

    The frames are matched by ``workers`` forked processes (:func:`~stringcast.core.forked.forked_map`)
    where the video is a :class:`~stringcast.video.CachedVideo` (any frame, no decoding); the result
    is the same for any number. ``memo`` {frame: {grid index: (S,) NCC}} keeps every match made, so a
    re-centred window only matches its new offsets (the candidate offsets lie on a fixed grid).

    Returns taus (T,) s, total (T,) (the summed mean NCC of the frames with contrast), best (the
    peak offset of each such frame, s), frames (F,) (the frames used), tau_ks (F, S) s (each
    frame's and segment's sub-step peak, NaN where flat or at an edge) and per_frame (C, T, S)
    (each frame with contrast's per-segment NCC; summed over C, the per-segment score).

    Raises:
        DataError: no frame falls in the motion ``window`` (t_on, t_off) s.
    """
    t_on, t_off = window
    taus = tau0 + np.arange(-search, search + step / 2, step)
    k_t = np.arange(video.n_frames) / fps
    # frames in the motion for every candidate offset: one near the motion's start or end
    # matches the still arm equally well for all earlier (or later) offsets, a one-sided
    # score that pulls the peak towards the rest posture (the overlapping ones if too few)
    frames = np.nonzero((k_t + tau0 - search >= t_on) & (k_t + tau0 + search <= t_off))[0]
    if len(frames) < st.min_frames:
        frames = np.nonzero((k_t + tau0 + search >= t_on) & (k_t + tau0 - search <= t_off))[0]
    if len(frames) == 0:
        raise DataError(f"{video.path}: no frame falls in the arm's motion ({t_on:.3f}-{t_off:.3f} s on the "
                        f"controller clock) for an offset near {tau0:.4f} s")
    total, best = np.zeros(len(taus)), []
    tau_ks = np.full((len(frames), n_seg), np.nan)
    per_frame = []

    grid = np.rint(taus / step).astype(np.int64)   # the offsets' places on the fixed grid: memo's keys

    def match(ks):  # each frame's per-segment NCC at the offsets not matched before, (T', S)
        out = []
        for k in ks:
            need = np.flatnonzero([g not in memo.get(int(k), ()) for g in grid])
            out.append((need, sync_arm.ncc_segments(frame_strips(
                video.read(int(k)), joints_at(taus[need] + k / fps, t_j, q_j)), template) if len(need) else None))
        return out

    matches = (m for part in forked_map(match, chunked(frames, FRAMES_PER_TASK), workers) for m in part)
    for i, (k, (need, rows)) in enumerate(zip(frames, matches)):
        known = memo.setdefault(int(k), {})
        known.update(zip(grid[need].tolist(), rows if rows is not None else ()))
        per_seg = np.stack([known[g] for g in grid.tolist()])   # (T, S)
        score = per_seg.mean(axis=1)
        if np.ptp(score) >= st.min_frame_contrast:
            total += score
            per_frame.append(per_seg)
            best.append(taus[int(np.argmax(score))])
        for s_ in range(per_seg.shape[1]):
            c = per_seg[:, s_]
            j = int(np.argmax(c))
            if np.ptp(c) >= st.min_frame_contrast and 1 <= j <= len(c) - 2:
                tau_ks[i, s_] = sync_arm.parabola_peak(taus[j - 1:j + 2], c[j - 1:j + 2])
    per_frame = np.stack(per_frame) if per_frame else np.zeros((0, len(taus), n_seg))
    return taus, total, best, frames, tau_ks, per_frame


def _on_grid(t: float, step: float) -> float:
    """``t`` s rounded to the step grid: the same candidate offsets whatever the start."""
    return float(np.round(t / step) * step)


def _recentred_search(coarse, fine, trigger_s: float | None, step: float,
                      st: SyncSettings) -> tuple[float | None, tuple]:
    """The fine search re-centred on its peak until the peak sits within ``recentre_ms`` of the window's
    centre (at most 5 windows; following the peak off an edge), from the trigger time, else (or when the
    trigger time is off by more than the search) from ``coarse()``. ``fine(tau0)`` is
    :func:`_fine_search`'s. Returns (the coarse offset s or None if not needed, the last ``fine``)."""
    coarse_s = None if trigger_s is not None else coarse()
    tau0 = _on_grid(trigger_s if trigger_s is not None else coarse_s, step)
    for attempt in range(5):  # re-centre the search window on the peak (and follow it off an edge)
        taus, total, best, frames, tau_ks, per_frame = fine(tau0)
        i = int(np.argmax(total))
        if best and 2 <= i <= len(taus) - 3 and abs(taus[i] - tau0) <= st.recentre_ms / 1000:
            break
        if attempt == 0 and coarse_s is None and not (best and 2 <= i <= len(taus) - 3):
            coarse_s = coarse()  # the trigger time was off by more than the search
            tau0 = _on_grid(coarse_s, step)
        else:
            tau0 = _on_grid(float(taus[i]), step)
    return coarse_s, (taus, total, best, frames, tau_ks, per_frame)


def _segment_offset(taus: np.ndarray, total: np.ndarray, total_seg: np.ndarray, n_seg: int,
                    st: SyncSettings) -> tuple[np.ndarray, np.ndarray, float]:
    """The offset, s, from the segments that agree: each segment's own peak (S,) s of its summed match
    total_seg (T, S) over taus (T,) s, which agree (S,) bool (a peak inside the window, within
    ``segment_agree_ms`` of the median of those), and the peak of their sum (of ``total`` (T,) if none
    agrees)."""
    # each segment's own summed match; a segment whose peak disagrees with the others (a static
    # feature such as a cable behind it in the rest template, the string across it) is left out, and
    # so is one whose match rises to the window's edge (no peak: a segment that barely moves across itself)
    seg_peaks = np.array([sync_arm.parabola_peak(taus, total_seg[:, j]) for j in range(n_seg)])
    half = 0.5 * (taus[1] - taus[0])
    inside = (seg_peaks > taus[0] + half) & (seg_peaks < taus[-1] - half)
    ref = np.median(seg_peaks[inside]) if inside.any() else np.median(seg_peaks)
    keep = (inside | ~inside.any()) & (np.abs(seg_peaks - ref) <= st.segment_agree_ms / 1000)
    offset = sync_arm.parabola_peak(taus, total_seg[:, keep].sum(axis=1)) if keep.any() else \
        sync_arm.parabola_peak(taus, total)
    return seg_peaks, keep, offset


def _speeds(arm, t_j: np.ndarray, q_j: np.ndarray, frames: np.ndarray, fps: float, offset: float,
            segments: np.ndarray, n_u: int) -> np.ndarray:
    """(F, S) m/s: each segment's speed across itself (:func:`~stringcast.sync.arm_match.normal_speeds`) at the
    frames' (F,) times at ``offset`` s (central difference over 1 ms), for
    :func:`~stringcast.sync.arm_match.match_residual`."""
    t_k = offset + frames / fps
    dt = 1e-3
    a, _, _ = sync_arm.normal_speeds(arm, joints_at(t_k - dt, t_j, q_j), joints_at(t_k, t_j, q_j),
                                     joints_at(t_k + dt, t_j, q_j), dt, segments, n_u)
    return a
