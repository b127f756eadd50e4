"""Video-to-controller clock synchronisation: ``sync.json`` (the offset of frame 0 on the controller clock).

Frame k is at ``t_k = offset_s + k / fps`` on the controller clock of ``joints.csv``.
:func:`run_sync` with ``config["sync"]["method"]: video`` estimates the offset from the
video: the arm seen in the frames is matched with the forward
kinematics of the joint log (:mod:`stringcast.sync_arm`), sub-frame, with or without
the recording's ``trigger_time_s`` (used only as a starting guess, and compared).
``method: trigger`` (the default until the video method is reliable: see
``benchmarks/sync.py``) takes the offset from ``video.yaml`` as it is.

``sync.json`` holds: offset_s, fps, frames, method, residual_mm (where the still arm is
seen vs where the forward kinematics and the board-to-robot transform put it: the
calibration's check), time_residual_ms (spread of the frames' own best offsets),
trigger_time_s and trigger_minus_estimate_ms, frames_used, dropped_frames (where the
file has timestamps), board_check, score_curve, warnings, note.
"""
from __future__ import annotations

import math
import sys
import warnings
from pathlib import Path

import numpy as np

from . import sync_arm
from .arm import motion_window
from .files import DataError, check_joint_coverage, find_video, read_joint_table, read_video_meta, write_json

METHOD_TRIGGER = "video.yaml trigger_time_s"
METHOD_VIDEO = "video: arm vs forward kinematics of joints.csv"


def _trigger_doc(meta: dict, video_yaml: Path) -> dict:
    trig = meta.get("trigger_time_s")
    if trig is None:
        raise DataError(f"{video_yaml}: no trigger_time_s, and config sync.method is 'trigger'; give the "
                        "controller-clock time of frame 0, or use sync.method: video")
    return {"offset_s": float(trig), "method": METHOD_TRIGGER, "residual_mm": None,
            "note": "offset taken from the recording's trigger time, not estimated from the video"}


def estimate_offset(video, calibration, arm, t_j: np.ndarray, q_j: np.ndarray, tracking_st: dict, st: dict,
                    trigger_s: float | None = None) -> dict:
    """Offset of frame 0 on the controller clock, from the arm seen in the video.

    Args:
        video: a :class:`~stringcast.video.VideoReader` (fps known). calibration:
            :class:`~stringcast.calibration.Calibration`. t_j (K,) s, q_j (K, J) rad: the
            joint log. tracking_st: tracking settings (the arm's outline). st: sync settings.
        trigger_s: the recording's trigger time, a starting guess only.

    Returns:
        dict with offset_s, time_residual_ms, frames_used, board_check, score_curve, coarse.

    Raises:
        DataError: the video has no still frames of the arm before the motion, or no
            frame in the motion.
    """
    fps = float(video.fps)
    hw = sync_arm.segment_half_widths(arm, tracking_st, st["strip_margin_mm"] / 1000)
    n_u, n_v, sig = int(st["strip_samples"]), int(st["strip_width_samples"]), float(st["smooth_px"])
    rest_pts = sync_arm.strip_points(arm, q_j[0], hw, n_u, n_v)
    uv = calibration.robot_to_pixel(rest_pts.reshape(-1, 2)).reshape(rest_pts.shape)
    seen = np.all((uv >= 0) & (uv <= np.array([video.width - 1, video.height - 1])), axis=(1, 2, 3))
    if not seen.any():
        raise DataError(f"{video.path}: no segment of the arm is wholly in view at the start posture; sync "
                        "from the video needs one (or set sync.method: trigger)")
    hw = hw[seen]
    segments = np.nonzero(seen)[0]

    def strips(q):
        return sync_arm.strip_points(arm, q, hw, n_u, n_v, segments)

    rest_pts = strips(q_j[0])
    n_rest = max(1, min(int(st["rest_frames"]), video.n_frames))
    rest = np.median(np.stack([video.read(k).astype(np.float32) for k in range(n_rest)]), axis=0)
    rest_s = sync_arm.smooth(rest, sig)
    template = sync_arm.sample(rest_s, calibration, rest_pts)
    board = sync_arm.board_check(rest_s, calibration, arm, q_j[0], hw, segments)
    try:
        t_on, t_off = motion_window(t_j, q_j)
    except ValueError as exc:
        raise DataError(f"{video.path}: sync from the video needs the arm to move: {exc}") from exc
    search, step = st["search_ms"] / 1000, st["step_ms"] / 1000

    def coarse() -> float:
        rest_ncc = np.array([sync_arm.ncc(sync_arm.sample(sync_arm.smooth(f, sig), calibration, rest_pts), template)
                             for _, f in video])
        if np.mean(rest_ncc[:n_rest]) < 0.9:
            raise DataError(f"{video.path}: the first frames do not show the arm still at the joint log's first "
                            "posture; sync needs the video to start before the motion")
        tp = np.arange(t_j[0], t_j[-1], 1e-3)
        pred = sync_arm.ncc(sync_arm.sample(rest_s, calibration,
                                            strips(sync_arm.joints_at(tp, t_j, q_j))),
                            template)
        return sync_arm.coarse_offset(rest_ncc, fps, tp, pred, st["coarse_step_ms"] / 1000)

    def fine(tau0: float) -> tuple[np.ndarray, np.ndarray, list]:
        taus = tau0 + np.arange(-search, search + step / 2, step)
        k_t = np.arange(video.n_frames) / fps
        frames = np.nonzero((k_t + tau0 + search >= t_on) & (k_t + tau0 - search <= t_off))[0]
        if len(frames) == 0:
            raise DataError(f"{video.path}: no frame falls in the arm's motion ({t_on:.3f}-{t_off:.3f} s on the "
                            f"controller clock) for an offset near {tau0:.4f} s")
        total, best = np.zeros(len(taus)), []
        for k in frames:
            f = sync_arm.smooth(video.read(int(k)), sig)
            q = sync_arm.joints_at(taus + k / fps, t_j, q_j)
            score = sync_arm.ncc(sync_arm.sample(f, calibration, strips(q)),
                                 template)
            if np.ptp(score) >= st["min_frame_contrast"]:
                total += score
                best.append(taus[int(np.argmax(score))])
        return taus, total, best

    tau0 = trigger_s if trigger_s is not None else coarse()
    used_coarse = trigger_s is None
    for attempt in range(4):  # follow the peak while it sits at the edge of the search window
        taus, total, best = fine(tau0)
        i = int(np.argmax(total))
        if best and 2 <= i <= len(taus) - 3:
            break
        if attempt == 0 and not used_coarse:
            tau0, used_coarse = coarse(), True  # the trigger time was off by more than the search
        else:
            tau0 = float(taus[i])
    if not best:
        raise DataError(f"{video.path}: the arm's motion is not visible in the frames (no frame's match with the "
                        "forward kinematics depends on the offset)")
    offset = sync_arm.parabola_peak(taus, total)
    mad = float(np.median(np.abs(np.asarray(best) - offset))) * 1.4826
    return {"offset_s": offset, "time_residual_ms": mad * 1000, "frames_used": len(best), "board_check": board,
            "coarse_offset_s": tau0 if used_coarse else None,
            "score_curve": {"offset_s": taus.tolist(), "ncc_sum": total.tolist()}}


def run_sync(trial_dir: str | Path, calibration_json: str | Path | None, campaign, config: dict | None,
             out_json: str | Path | None = None) -> dict:
    """Write ``sync.json`` for one trial (see the module docstring for its keys).

    Args:
        trial_dir: ``data/<campaign>/trial_<k>`` with ``video.yaml``, the video and ``joints.csv``.
        calibration_json: the trial's ``calibration.json`` (needed by ``method: video``).
        campaign: :class:`~stringcast.config.Campaign` (the arm). config: the project config.

    Raises:
        DataError: missing/malformed inputs (the file is named), no trigger time with
            ``method: trigger``, or a video in which the arm's motion cannot be found.
    """
    from .calibration import Calibration
    from .tracking import settings as tracking_settings
    from .video import check_frame_count, dropped_frames, open_video

    trial_dir = Path(trial_dir)
    video_yaml = trial_dir / "video.yaml"
    meta = read_video_meta(video_yaml)
    st = sync_arm.settings(config)
    doc = {"fps": float(meta["fps"]), "frames": int(meta["frames"]), "trigger_time_s": meta.get("trigger_time_s")}
    if st["method"] == "trigger":
        doc.update(_trigger_doc(meta, video_yaml))
    else:
        if calibration_json is None:
            raise DataError(f"{trial_dir}: sync.method 'video' needs the trial's calibration.json")
        t_j, q_j, _ = read_joint_table(trial_dir / "joints.csv")
        cal = Calibration.from_json(calibration_json)
        with open_video(find_video(trial_dir), fps=doc["fps"]) as video:
            warns = check_frame_count(video, meta, video_yaml)
            est = estimate_offset(video, cal, campaign.arm, t_j, q_j, tracking_settings(config), st,
                                  doc["trigger_time_s"])
            # the file's own frame times, where a full pass (the coarse search) has read them already
            stamps = video.timestamps_s if est["coarse_offset_s"] is not None else None
        check_joint_coverage(t_j, est["offset_s"] + np.arange(doc["frames"]) / doc["fps"], trial_dir / "joints.csv")
        bc = est["board_check"]
        doc.update(est, method=METHOD_VIDEO, residual_mm=bc["residual_mm"],
                   note="offset estimated from the video; the trigger time was only a starting guess"
                   if doc["trigger_time_s"] is not None else "offset estimated from the video (no trigger time)")
        if doc["trigger_time_s"] is not None:
            doc["trigger_minus_estimate_ms"] = (float(doc["trigger_time_s"]) - est["offset_s"]) * 1000
        doc["dropped_frames"] = None if stamps is None else [list(g) for g in dropped_frames(stamps, doc["fps"])]
        if bc["residual_mm"] is not None and bc["residual_mm"] > st["board_check_warn_mm"]:
            warns.append(f"the still arm is seen {bc['residual_mm']:.1f} mm from where the forward kinematics and "
                         f"the board-to-robot transform put it (> {st['board_check_warn_mm']} mm): check the "
                         "board pose in config")
        if doc["dropped_frames"]:
            warns.append(f"{len(doc['dropped_frames'])} dropped frame(s) by the file's timestamps")
        for w in warns:
            warnings.warn(f"{trial_dir}: {w}", stacklevel=2)
            print(f"sync warning: {trial_dir}: {w}", file=sys.stderr)
        doc["warnings"] = warns
    if not math.isfinite(doc["offset_s"]):
        raise DataError(f"{trial_dir}: sync produced a non-finite offset")
    if out_json is not None:
        write_json(out_json, doc)
    return doc


def frame_times(sync: dict, n: int | None = None) -> np.ndarray:
    """Controller-clock times of frames 0..n-1: ``offset_s + k / fps`` -> (n,) s.

    Args:
        sync: the ``sync.json`` mapping (offset_s, fps, frames).
        n: frame count (default ``sync["frames"]``).

    Raises:
        DataError: missing or non-positive fps, or missing offset.
    """
    try:
        offset, fps = float(sync["offset_s"]), float(sync["fps"])
        n = int(sync["frames"]) if n is None else int(n)
    except (KeyError, TypeError, ValueError) as exc:
        raise DataError(f"sync: needs offset_s, fps and frames, got {sync!r}") from exc
    if not (np.isfinite(fps) and fps > 0) or not np.isfinite(offset):
        raise DataError(f"sync: fps must be > 0 and offset finite, got fps={fps}, offset_s={offset}")
    return offset + np.arange(n) / fps
