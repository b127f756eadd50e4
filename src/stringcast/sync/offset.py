"""Video-to-controller clock synchronisation: ``sync.json`` (the offset of frame 0 on the controller clock).

**Frame-time convention.** ``offset_s`` is the controller-clock time (the clock of
``joints.csv``) of the *middle of frame 0's exposure*; frame k's exposure is centred on
``t_k = offset_s + k / fps`` (:func:`frame_times`). That is docs/data_contract.md's ``trigger_time_s``
("controller-clock time of frame 0") read as the exposure centre, as the virtual lab
writes it; a camera whose trigger marks the *start* of the exposure has a trigger time
half an exposure earlier than ``offset_s``. With motion blur the arm seen in a frame is
its mean over the exposure, i.e. (to first order) its pose at the exposure centre, so
the video estimate measures the centre whatever the exposure.

:func:`run_sync` with the sync setting ``method: video`` (the default) estimates the
offset from the video: the arm seen in the frames is matched with the forward kinematics
of the joint log (:mod:`stringcast.sync.arm_match`, :mod:`stringcast.sync.video_offset`; the arm
rather than the tracked grasp point, because the links are large, sharp-edged and seen in
every frame, whereas the grasp point hides behind the gripper and blurs), sub-frame. The
recording's ``trigger_time_s``, when given, is never silently overruled: both candidates
are judged by the arm-match residual at their offsets, and the video wins only with
clearly better evidence (:mod:`stringcast.sync.confidence`). ``method: trigger`` takes the
offset from ``video.yaml`` as it is.

**The joint log** may start after the first frame (at the motion's start) or end before
the last one where the arm is still at that end of the log: the arm is taken as still
there, in the log's first (last) posture (:func:`stringcast.core.check_joint_coverage`); a
log whose end shows the arm moving misses part of the motion and is refused.

``sync.json`` holds: offset_s, uncertainty_ms (a bound on its error, :func:`~stringcast.sync.confidence.choose_offset`;
null where not determined), fps, frames, method, chosen (``trigger`` or ``video``),
candidates (``trigger``: offset_s, residual_mm, minus_video_ms, excess_mm (its residual
minus the video's), excess_standard_error_mm, excess_p (the share of block resamples of
the frames in which the trigger fits as well), excess_p_needed, resamples, block_frames,
beyond_video_uncertainty; ``video``: offset_s,
residual_mm, time_residual_ms, standard_error_ms, frames_used, segments_used, ambiguous,
second_peak_s, block_frames, residual_px, arm_width_px, uncertainty_px, systematic_ms,
mapping_error_mm, speed_eff_m_s, uncertainty_ms; or ``error`` when
the video gave no estimate), verdict (:class:`~stringcast.core.Verdict`), joint_log
(starts_after_video_s, ends_before_video_s, extended, first_speed_share,
last_speed_share), residual_mm (at the chosen offset: robust spread, over the agreeing
segments and the frames, of the distance across each segment between where the frame
shows it and where the forward kinematics put it:
:func:`stringcast.sync.arm_match.match_residual`), residual_matches, arm_shift_mm (the board
check's translation, by which the predicted arm is moved), time_residual_ms (spread of
the frames' own best offsets), segment_offsets_s, segments_in_view and segments_used
(each arm segment's own peak; those that agree are used), trigger_time_s,
trigger_minus_estimate_ms, trigger_disagrees (the video overruled the trigger time),
frames_used, dropped_frames (where the file has timestamps), board_check
(:func:`stringcast.calibrate.board_check.check_board_to_robot` on the rest frames),
score_curve, warnings (the verdict's reasons), note.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from .confidence import choose_offset
from .rate_check import clock_rate, rate_reason
from .video_offset import estimate_offset
from stringcast.calibrate import Calibration
from stringcast.core import (
    BoardCheckSettings,
    DataError,
    SyncSettings,
    Verdict,
    TrialFiles,
    check_joint_coverage,
    end_speed_shares,
    read_joint_table,
    read_video_meta,
    write_json,
)
from stringcast.video import check_frame_count, dropped_frames, open_trial_video

METHOD_TRIGGER = "video.yaml trigger_time_s"
METHOD_VIDEO = "video: arm vs forward kinematics of joints.csv"
METHOD_CHECKED = "video.yaml trigger_time_s, checked against the arm in the video"


def _trigger_doc(meta: dict, video_yaml: Path) -> dict:
    trig = meta.get("trigger_time_s")
    if trig is None:
        raise DataError(f"{video_yaml}: no trigger_time_s, and config sync.method is 'trigger'; give the "
                        "controller-clock time of frame 0, or use sync.method: video")
    return {"offset_s": float(trig), "uncertainty_ms": None, "method": METHOD_TRIGGER, "residual_mm": None,
            "chosen": "trigger",
            "candidates": {"trigger": {"offset_s": float(trig), "residual_mm": None}},
            "note": "offset taken from the recording's trigger time, not estimated from the video"}


def _check_log_starts_still(t_j: np.ndarray, q_j: np.ndarray, arm, joints_csv: Path, sync: SyncSettings) -> None:
    """Raise a DataError naming ``joints_csv`` when the log's first samples show the arm moving: the video's
    estimate takes the log's first posture as the arm at rest in the first frames."""
    first, _ = end_speed_shares(t_j, q_j, arm.qd_max, sync.still_window_s)
    if first > sync.still_speed_share:
        raise DataError(f"{joints_csv}: the joint log starts with the arm moving ({first:.0%} of its speed limit, "
                        f"more than sync.still_speed_share {sync.still_speed_share:.0%}): it misses the start of the "
                        "motion; the log must start with the arm still, before the motion or at its start")


def _video_doc(trial: TrialFiles, calibration_json, campaign, meta: dict, video_yaml: Path, t_j: np.ndarray,
               q_j: np.ndarray, sync: SyncSettings, board_check: BoardCheckSettings,
               frames_npy: Path | None = None, workers: int = 1) -> tuple[dict, list[str]]:
    """``sync.json``'s fields from the video (``frames_npy``: its decoded frames, if given) and the trigger time,
    if any, and the warnings besides the choice's."""
    if calibration_json is None:
        raise DataError(f"{trial.name}: sync.method 'video' needs the trial's calibration.json")
    _check_log_starts_still(t_j, q_j, campaign.arm, trial.joints, sync)
    trigger = meta.get("trigger_time_s")
    cal = Calibration.from_json(calibration_json)
    est, failure = None, None
    fps = float(meta["fps"])
    with open_trial_video(trial.video, frames_npy, fps=fps) as video:
        warns = check_frame_count(video, meta, video_yaml)
        video.fps = fps   # video.yaml's, which every later stage's frame times use (a container's own is warned of)
        try:
            est = estimate_offset(video, cal, campaign.arm, t_j, q_j, sync, board_check, trigger, workers)
        except DataError as exc:
            if trigger is None:
                raise DataError(f"{exc}{_rate_cause(video, cal, campaign, t_j, q_j, sync, board_check, video_yaml)}"
                                ) from exc
            failure = str(exc)
        # the file's own frame times, where a full pass (the decode, or the coarse search) has read them already
        stamps = video.timestamps_s if frames_npy is not None or (est is not None and est["coarse_offset_s"]
                                                                   is not None) else None
        choice = choose_offset(est, failure, trigger, sync)
        if not choice["verdict"].ok:   # the arm nowhere where the log puts it: the frames' rate may be off
            cause = _rate_cause(video, cal, campaign, t_j, q_j, sync, board_check, video_yaml)
            if cause:
                choice["verdict"] = Verdict(choice["verdict"].status, (cause.removeprefix(": "), *choice["verdict"].reasons))
    doc = {k: v for k, v in (est or {}).items() if k != "evidence"}
    doc.update(offset_s=choice["offset_s"], uncertainty_ms=choice["uncertainty_ms"], chosen=choice["chosen"],
               candidates=choice["candidates"],
               verdict=choice["verdict"], residual_mm=choice["candidates"][choice["chosen"]]["residual_mm"],
               method=METHOD_VIDEO if choice["chosen"] == "video" else METHOD_CHECKED if est else METHOD_TRIGGER)
    doc["note"] = {"video": "offset estimated from the video" + (
        "; it overruled the trigger time" if trigger is not None else " (no trigger time)"),
        "trigger": "the trigger time, checked against the arm in the video" if est is not None else
        "the trigger time, unchecked: the video gave no estimate"}[choice["chosen"]]
    doc["trigger_minus_estimate_ms"] = None if trigger is None or est is None else \
        (float(trigger) - est["offset_s"]) * 1000
    doc["trigger_disagrees"] = None if trigger is None else choice["chosen"] == "video"
    doc["dropped_frames"] = None if stamps is None else [list(g) for g in dropped_frames(stamps, float(meta["fps"]))]
    bc = doc.get("board_check")
    if bc is not None and bc["residual_mm"] is not None and bc["residual_mm"] > sync.board_check_warn_mm:
        what = ("the calibration's intrinsics (weak; their error grows from the board to the arm), then the board "
                "pose in config" if bc.get("likely_cause") == "intrinsics" else "the board pose in config")
        warns.append(f"the still arm is seen {bc['residual_mm']:.1f} mm from where the forward kinematics and "
                     f"the board-to-robot transform put it (> {sync.board_check_warn_mm} mm): check {what}")
    if doc["dropped_frames"]:
        warns.append(f"{len(doc['dropped_frames'])} dropped frame(s) by the file's timestamps")
    return doc, warns


def _rate_cause(video, cal, campaign, t_j, q_j, sync: SyncSettings, board_check: BoardCheckSettings,
                video_yaml: Path) -> str:
    """``": <reason>"`` where the frames run at another rate than video.yaml's fps says
    (:func:`~stringcast.sync.rate_check.clock_rate`), else ``""``."""
    try:
        found = clock_rate(video, cal, campaign.arm, t_j, q_j, sync, board_check, float(video.fps))
    except DataError:
        return ""
    return "" if found is None else ": " + rate_reason(found, float(video.fps), video_yaml)


def run_sync(trial: TrialFiles | str | Path, calibration_json: str | Path | None, campaign, out_json: str | Path | None = None,
             frames_npy: str | Path | None = None, workers: int = 1, *, sync: SyncSettings,
             board_check: BoardCheckSettings) -> dict:
    """Write ``sync.json`` for one trial (see the module docstring for its keys).

    Parameters
    ----------
    trial : TrialFiles or path
        The trial's video, ``video.yaml`` and ``joints.csv`` (:class:`~stringcast.core.TrialFiles`;
        a folder: its files by the data contract's names).
    calibration_json : path or None
        The trial's ``calibration.json`` (needed by ``method: video``).
    campaign : Campaign
        :class:`~stringcast.core.specs.Campaign` (the arm, with its outline and speed limits).
    out_json : path, optional
        Where to write ``sync.json`` (None: not written).
    frames_npy : path, optional
        The video's frames decoded once (:func:`~stringcast.video.write_frame_cache`), read
        instead of decoding the video; None: decode it.
    workers : int
        Processes matching the decoded frames side by side (with ``frames_npy``; the same result).
    sync : SyncSettings
        Sync settings (:class:`~stringcast.core.SyncSettings`).
    board_check : BoardCheckSettings
        Board-check settings (:class:`~stringcast.core.BoardCheckSettings`), for the
        check on the rest frames when ``calibration.json`` has none.

    Returns
    -------
    dict
        The ``sync.json`` document (``offset_s`` in s on the controller clock, ``fps``, ``frames``, ...).

    Raises
    ------
    DataError
        Missing/malformed inputs (the file is named), no trigger time with
        ``method: trigger``, a video in which the arm's motion cannot be found and no trigger
        time, or a joint log that misses part of the motion (it starts or ends with the arm
        moving where the frames need it; ``joints.csv`` named).
    """
    trial = TrialFiles.of(trial)
    if trial.video_meta is None:
        raise DataError(f"{trial.name}: sync reads the trial's video.yaml, and none was given")
    video_yaml = trial.video_meta
    meta = read_video_meta(video_yaml)
    doc = {"fps": float(meta["fps"]), "frames": int(meta["frames"]), "trigger_time_s": meta.get("trigger_time_s")}
    joints_csv = trial.joints
    t_j, q_j = read_joint_table(joints_csv, n_joints=campaign.arm.n_joints, arm_name=campaign.arm.name)
    if sync.method == "trigger":
        doc.update(_trigger_doc(meta, video_yaml), verdict=Verdict())
        with open_trial_video(trial.video, None if frames_npy is None else Path(frames_npy),
                              fps=doc["fps"]) as video:   # the frame count every later stage's times rest on
            warns = check_frame_count(video, meta, video_yaml)
    else:
        est_doc, warns = _video_doc(trial, calibration_json, campaign, meta, video_yaml, t_j, q_j, sync,
                                    board_check, None if frames_npy is None else Path(frames_npy), workers)
        doc.update(est_doc)
    if not math.isfinite(doc["offset_s"]):
        raise DataError(f"{trial.name}: sync produced a non-finite offset")
    doc["joint_log"] = check_joint_coverage(
        t_j, doc["offset_s"] + np.arange(doc["frames"]) / doc["fps"], joints_csv, q_joints=q_j,
        qd_max=campaign.arm.qd_max, still_share=sync.still_speed_share, still_window_s=sync.still_window_s)
    verdict = doc["verdict"]
    for w in warns:
        verdict = verdict.add("warn", w)
    doc["verdict"], doc["warnings"] = verdict.as_dict(), list(verdict.reasons)
    for w in doc["warnings"]:   # an ok verdict's reasons are notes (an overruled trigger, recorded)
        print(f"sync {'note' if verdict.ok else 'warning'}: {trial.name}: {w}", file=sys.stderr)
    if out_json is not None:
        write_json(out_json, doc)
    return doc
