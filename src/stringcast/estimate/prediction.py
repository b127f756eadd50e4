"""Next-motion prediction error: how well trial k's estimate predicts trial k + 1 (issue 27).

This is the standard out-of-sample validation of system identification: a model fitted on one
record is simulated on a fresh record it was not fitted to, driven by that record's measured
input, and its output is compared with the measured output (simulation error on validation
data; L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, Ch. 16). Here:

* the model: the string model (:mod:`stringcast.model.string_model`) with trial k's estimate,
  ``params.json``'s ``coefficients`` and ``mu`` (its best set);
* the input: trial k + 1's *measured* joint log (``joints.csv``), through the forward
  kinematics to the grasp's path and the hand's angle, from trial k + 1's tracked rest state
  (:func:`stringcast.estimate.problem.build_problem`, as the paper's fit builds its problem);
* the output compared: trial k + 1's tracked tip (point n of ``tracks.parquet``), in every frame
  where it is valid, from the motion's start (the joint log's, :func:`stringcast.core.motion_start`)
  to the tracked tip's closest approach to the target. That closest approach is searched from
  the motion's start to ``motion.flight_window_s`` after the arm stops
  (:func:`stringcast.core.motion_window`), the window the planner aims the hit in.

The figures are the median, 95th percentile and largest distance (mm) over those frames, the
frames in the window and the share of them with a tracked tip. ``prediction.json``'s verdict
says whether the figure can be trusted (enough tracked tips, the model stayed finite), not
whether it is small: there is no threshold for a good prediction. The pipeline's files only:
no ground truth is read.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from stringcast.core import (PARAM_NAMES, TRACK_COLUMNS, Campaign, DataError, EstimationSettings,
                             EvaluationSettings, ModelSettings, MotionSettings, TrackingSettings, Verdict,
                             motion_window, read_joint_table, read_json, read_parquet, write_json)
from stringcast.model import planned_parameters, simulate_batch
from .problem import EstimationProblem, build_problem_explained

MIN_VALID_FRAMES = 5
"""Fewer frames with a tracked tip in the window than this: the error is not judged (warn)."""
MIN_VALID_SHARE = 0.5
"""A smaller share of the window's frames with a tracked tip: the error is doubtful (warn)."""


def tip_prediction_error(problem: EstimationProblem, coeffs: np.ndarray, mu: np.ndarray,
                         target_xy: np.ndarray, t_end: float) -> dict:
    """The model's tip against the tracked tip of ``problem``'s trial (module doc).

    Args:
        problem: the trial predicted (:func:`~stringcast.estimate.problem.build_problem` of its
            tracks and measured joint log): hand path, rest state, frames, tracked points.
        coeffs: (10,) the estimate's coefficients, ``PARAM_NAMES`` order, Table 2 units.
        mu: (n,) its relative masses of points 1..n.
        target_xy: (2,) m, the target. t_end: s (controller clock), the end of the search for
            the tracked tip's closest approach (motion end + flight window).

    Returns:
        dict: ``median_mm``, ``p95_mm``, ``max_mm`` (None without a compared frame, or after a
        blow-up), ``frames`` (in the window), ``valid_frames`` (with a tracked tip),
        ``valid_share``, ``window_s`` [motion start, closest approach] s,
        ``tracked_closest_approach_mm``, ``blew_up`` (the model left its valid range), ``tip_path``
        (the compared frames' ``t_s``, ``tracked_mm`` and ``predicted_mm`` tips, :func:`_tip_path`).

    Raises:
        ValueError: ``coeffs`` not (10,), ``mu`` not (n,) or ``target_xy`` not (2,).
        DataError: no tracked tip between the motion's start and ``t_end``.
    """
    n = problem.n_points
    coeffs, mu, target_xy = (np.asarray(a, float) for a in (coeffs, mu, target_xy))
    if coeffs.shape != (len(PARAM_NAMES),) or mu.shape != (n,) or target_xy.shape != (2,):
        raise ValueError(f"tip_prediction_error: coeffs (10,), mu ({n},), target_xy (2,) expected; got "
                         f"{coeffs.shape}, {mu.shape}, {target_xy.shape}")
    t, tip, ok = problem.frame_t, problem.tracked[:, -1], problem.valid[:, -1]
    t0 = problem.t_motion_start
    search = ok & (t >= t0) & (t <= t_end)
    if not search.any():
        raise DataError(f"no tracked tip between the motion's start ({t0:.3f} s) and {t_end:.3f} s")
    d_target = np.where(search, np.hypot(*(tip - target_xy).T), np.inf)
    i_close = int(np.argmin(d_target))
    window = (t >= t0) & (t <= t[i_close])
    pos, fine = simulate_batch(coeffs[None], mu[None], problem.hand_t, problem.hand[None], np.zeros(1, np.int64),
                               problem.p_init[None], problem.l0, problem.psi0, problem.dt, t, drag=problem.drag,
                               halvings=problem.halvings)
    model_tip = np.asarray(pos)[0, :, -1]
    use = window & ok
    err = np.hypot(*(model_tip[use] - tip[use]).T) * 1000
    blew_up = not bool(np.asarray(fine)[0]) or not np.all(np.isfinite(err))
    figures = (None, None, None) if blew_up or not len(err) else (
        float(np.median(err)), float(np.percentile(err, 95)), float(err.max()))
    return {"median_mm": figures[0], "p95_mm": figures[1], "max_mm": figures[2], "frames": int(window.sum()),
            "valid_frames": int(use.sum()), "valid_share": float(use.sum() / max(1, window.sum())),
            "window_s": [float(t0), float(t[i_close])], "tracked_closest_approach_mm": float(d_target[i_close] * 1000),
            "blew_up": blew_up, "tip_path": _tip_path(t, tip, model_tip, use)}


TIP_PATH_POINTS = 300
"""``prediction.json``'s ``tip_path`` keeps at most this many frames (for the trial page's figure)."""


def _tip_path(t: np.ndarray, tip: np.ndarray, model_tip: np.ndarray, use: np.ndarray) -> dict:
    """The compared frames' times (s), tracked and predicted tips (mm), at most :data:`TIP_PATH_POINTS`
    of them, evenly spread; non-finite values (a blow-up) as None."""
    idx = np.flatnonzero(use)
    idx = idx[np.unique(np.linspace(0, len(idx) - 1, min(len(idx), TIP_PATH_POINTS)).astype(int))] if len(idx) else idx

    def mm(xy):
        return [[float(v) * 1000 if np.isfinite(v) else None for v in row] for row in np.asarray(xy)[idx]]

    return {"t_s": [float(x) for x in t[idx]], "tracked_mm": mm(tip), "predicted_mm": mm(model_tip)}


def prediction_verdict(figures: dict) -> Verdict:
    """Whether :func:`tip_prediction_error`'s figures can be trusted: warn after a blow-up, with
    fewer than :data:`MIN_VALID_FRAMES` tracked tips, or under :data:`MIN_VALID_SHARE` of them."""
    v = Verdict()
    if figures["blew_up"]:
        v = v.add("warn", "the model with the earlier estimate blew up on this motion: no prediction to compare")
    if figures["valid_frames"] < MIN_VALID_FRAMES:
        v = v.add("warn", f"only {figures['valid_frames']} frames with a tracked tip between the motion's start and "
                          f"the tip's closest approach (need {MIN_VALID_FRAMES}): the error is not judged")
    elif figures["valid_share"] < MIN_VALID_SHARE:
        v = v.add("warn", f"the tip was tracked in {figures['valid_share']:.0%} of the {figures['frames']} frames "
                          f"compared (under {MIN_VALID_SHARE:.0%}): the error is doubtful")
    return v


def run_prediction(params_json: Path, tracks_parquet: Path, joints_csv: Path, campaign: Campaign,
                   out_json: Path, *, model: ModelSettings, tracking: TrackingSettings,
                   motion: MotionSettings) -> dict:
    """Write ``prediction.json``: trial k's estimate predicting trial k + 1 (module doc).

    Parameters
    ----------
    params_json : Path
        Trial k's ``params.json`` (the estimate).
    tracks_parquet, joints_csv : Path
        Trial k + 1's tracked points and measured joint log.
    campaign : Campaign
        The resolved campaign (string, target, arm).
    out_json : Path
        ``prediction.json`` to write.
    model : ModelSettings
        The model's step and rest direction.
    tracking : TrackingSettings
        ``rest_frames``, the rest state's frames.
    motion : MotionSettings
        ``flight_window_s``, the hit window after the arm stops, s.

    Returns
    -------
    dict
        The document written: :func:`tip_prediction_error`'s figures (the tip's error, mm: median, p95;
        frames compared), ``params``, ``tracks``, ``verdict``.

    Raises
    ------
    DataError
        Unreadable or inconsistent inputs (named), or no tracked tip in the window.
    """
    n = campaign.string.n_points
    coeffs, mu = planned_parameters(n, read_json(params_json, mapping=True), str(params_json))
    t_j, q_j = read_joint_table(joints_csv, n_joints=campaign.arm.n_joints, arm_name=campaign.arm.name)
    # every frame the log covers (the fit's compare_after_motion_s does not apply); E's w is not used
    compare_all = dataclasses.replace(EstimationSettings(), compare_after_motion_s=None)
    problem = build_problem_explained(read_parquet(tracks_parquet, TRACK_COLUMNS), t_j, q_j, campaign, tracks_parquet,
                                      {}, model=model, evaluation=EvaluationSettings(), estimation=compare_all,
                                      tracking=tracking)
    try:
        t_end = motion_window(t_j, q_j)[1] + float(motion.flight_window_s)
        figures = tip_prediction_error(problem, coeffs, mu, campaign.target.xy, t_end)
    except (ValueError, DataError) as exc:
        raise DataError(f"{tracks_parquet}: {exc}") from exc
    doc = {**figures, "params": str(params_json), "tracks": str(tracks_parquet), "joints": str(joints_csv),
           "verdict": prediction_verdict(figures).as_dict()}
    write_json(out_json, doc)
    return doc
