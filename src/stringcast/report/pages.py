"""Self-contained HTML reports: the trial page (the campaign page: :mod:`.campaign_page`).

Figures are inlined as PNG data URIs (``report_figures``), the page is rendered
with Jinja2 from ``templates/``. The trial page shows the paper's figures for the
trial (Fig. 8a tip paths, Fig. 8b arm paths, Fig. 11 parameters, Table 4 masses),
E over the search, a frame strip with tracked and simulated points, how often each
point was tracked, calibration and sync, and the next motion. At its top a box gives the
verdicts the stages wrote (geometry.json, clock.json, tracking.json, and the fit's in
params.json: ok green, warn amber, fail red), one line per stage with its first reason, each
reason once on the page, the others folded (:func:`.verdicts.verdict_box`); then the prediction
check (``prediction.json``: the previous estimate driven by this trial's joints, against its tracked
tip), the next motion's predicted closest approach with its spread over the estimate's near-best
sets, and the coefficients and masses at a bound of their range flagged. A next motion planned
on a failed fit says so instead of "predicted hit". Every page ends with what
produced it (:mod:`stringcast.report.provenance`: the method, the git commit, the library versions).

The pages show only what the pipeline measured and computed. The virtual lab's
ground truth files are never read here, as in every other stage: footage from a
real camera has none. The lab's verdict and the tracking error against its truth
are in the campaign driver's ``campaign_summary.json`` (:mod:`stringcast_lab.campaign`)
and in ``benchmarks/``.
"""
from __future__ import annotations

import datetime as _dt
from pathlib import Path

import jinja2
import numpy as np
import pandas as pd

from stringcast import __version__
from stringcast.calibrate import Calibration
from stringcast.core import (PARAM_NAMES, TRACK_COLUMNS, Campaign, DataError, ModelSettings, MotionSettings, Settings,
                             TrialFiles, TrialResults, hand_pose, model_ranges, motion_start, read_joint_table,
                             read_json, read_parquet, tracks_arrays, write_text)
from . import figures as figs
from .provenance import provenance
from .verdicts import at_bounds, reason_key, verdict_box
from .strip import frame_strip, strip_data_uri


def _env() -> jinja2.Environment:
    return jinja2.Environment(loader=jinja2.PackageLoader("stringcast.report", "templates"),
                              autoescape=jinja2.select_autoescape(["html", "j2"]))


def _common(campaign: Campaign, title: str, settings: Settings) -> dict:
    return {"title": title, "version": __version__, "provenance": provenance(settings),
            "created": _dt.datetime.now().isoformat(timespec="seconds"),
            "string": campaign.string_id or campaign.string.name,
            "length_mm": f"{campaign.string.length * 1000:.0f}", "n_points": campaign.string.n_points,
            "target_mm": (f"{campaign.target.x * 1000:.0f}", f"{campaign.target.y * 1000:.0f}"),
            "radius_mm": f"{campaign.target.radius * 1000:.0f}"}


def _tracked(tracks: pd.DataFrame, n_points: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """t (F,), xy (F, n+1, 2) m with NaN where not valid, valid (F, n+1)."""
    _, t, xy, valid = tracks_arrays(tracks, n_points)
    xy[~valid] = np.nan
    return t, xy, valid


def closest_approach(t: np.ndarray, tip: np.ndarray, target_xy: np.ndarray, t0: float, t1: float):
    """Smallest distance (m) of a tip path (F,2) to the target within [t0, t1]; (d, t) or (nan, nan)."""
    sel = (t >= t0) & (t <= t1) & np.isfinite(tip).all(axis=1)
    if not sel.any():
        return float("nan"), float("nan")
    d = np.hypot(tip[sel, 0] - target_xy[0], tip[sel, 1] - target_xy[1])
    i = int(np.argmin(d))
    return float(d[i]), float(t[sel][i])


def floor_clearance(t: np.ndarray, xy: np.ndarray, t0: float, t1: float, floor_y: float) -> float:
    """The tracked string's lowest point above the floor within [t0, t1], m (NaN where none is tracked).

    Parameters
    ----------
    t : ndarray, (F,)
        Frame times, s. xy: ndarray, (F, n + 1, 2), m, NaN where not valid (point 0, the grasp, is left out).
    t0, t1 : float
        The hit window, s. floor_y: the floor's height, m (``arm.floor_y``).

    Returns
    -------
    float
        Negative where the string went through where the floor is: in a lab with a real floor it struck
        it, and the pass is no hit (as the planner and the lab judge one).
    """
    sel = (t >= t0) & (t <= t1)
    y = xy[sel, 1:, 1]
    return float(np.nanmin(y)) - float(floor_y) if np.isfinite(y).any() else float("nan")


def measured_hit(d: float, floor_m: float, radius: float) -> tuple[bool, str]:
    """Whether a tracked pass hit, judged as the planner and the lab judge one: the tip's closest approach
    ``d`` (m) within ``radius`` (m) and the string nowhere below the floor (``floor_m``,
    :func:`floor_clearance`); and, where the floor decides, why ("the string went 13 mm below the floor")."""
    note = f"the string went {-floor_m * 1000:.0f} mm below the floor" if floor_m < 0 else ""
    return bool(d <= radius and not note), note


def _fmt(x, spec=".2f", unit=""):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "n/a"
    return f"{x:{spec}}{unit}"


def _motion_window(trial: TrialFiles, motion: MotionSettings, arm) -> tuple[float, float, dict]:
    t, q = read_joint_table(trial.joints, n_joints=arm.n_joints, arm_name=arm.name)
    played = read_json(trial.played) if trial.played is not None and trial.played.exists() else {}
    t0 = motion_start(t, q)
    T = float(played.get("T_s", t[-1] - t0))
    return t0, t0 + T + float(motion.flight_window_s), played


def write_trial_report(trial: TrialFiles | Path, results: TrialResults | Path, campaign: Campaign, out: Path, *,
                       settings: Settings) -> None:
    """Write ``results/<campaign>/trial_<k>/report.html`` from that trial's outputs.

    Parameters
    ----------
    trial : TrialFiles or Path
        The trial's raw files (:class:`~stringcast.core.TrialFiles`: the video, the joint log and
        the played motion.json; a folder: by the data contract's names).
    results : TrialResults or Path
        Its products (:class:`~stringcast.core.TrialResults`; a folder: by name).
    campaign : Campaign
        The resolved campaign (its target, string and arm).
    out : Path
        Where to write the page.
    settings : Settings
        Every stage's (:class:`~stringcast.core.Settings`): the page names the method
        they make (:mod:`.provenance`), and reads Table 2's ranges (``model``) and the flight
        window (``motion``).

    Raises
    ------
    DataError
        A required result file is missing or malformed (named).
    """
    try:
        results = results if isinstance(results, TrialResults) else TrialResults.in_folder(results)
        _write_trial_report(TrialFiles.of(trial), results, campaign, Path(out), settings)
    except MALFORMED as exc:
        raise DataError(f"{Path(out).parent}: a result file the trial report reads is malformed "
                        f"({type(exc).__name__}: {exc})") from exc


MALFORMED = (KeyError, TypeError, ValueError, IndexError, AttributeError)
"""What a result file of the wrong shape raises as the reports read it (a DataError for the user)."""


def _write_trial_report(trial: TrialFiles, res: TrialResults, campaign: Campaign, out: Path,
                        settings: Settings) -> None:
    """:func:`write_trial_report`'s work."""
    n = campaign.string.n_points
    params = read_json(res.params, mapping=True)
    # the sweep's geometry.json / clock.json, or (results made before the sweep) calibration.json / sync.json
    calib_stage, calib_json = Path(res.geometry).stem, res.geometry
    sync_stage, sync_json = Path(res.clock).stem, res.clock
    calib, sync = read_json(calib_json, mapping=True), read_json(sync_json, mapping=True)
    nxt = read_json(res.motion_meta, mapping=True)
    tracks = read_parquet(res.tracks, TRACK_COLUMNS)
    fit = read_parquet(res.fit)
    t_j, q_j = read_joint_table(trial.joints, n_joints=campaign.arm.n_joints, arm_name=campaign.arm.name)
    t0, t1, played = _motion_window(trial, settings.motion, campaign.arm)
    tgt = campaign.target.xy
    t_tr, xy_tr, valid = _tracked(tracks, n)
    d_meas, _ = closest_approach(t_tr, xy_tr[:, n], tgt, t0, t1)
    floor_m = floor_clearance(t_tr, xy_tr, t0, t1, campaign.arm.floor_y)

    tip_fit = fit[fit["point"] == n].sort_values("frame")
    figures = [{"id": "fig-tip-paths", "caption": "Tracked tip vs the model's tip driven by the measured joints, "
                "with the estimated parameters (paper Fig. 8a).",
                "src": figs.tip_paths(tip_fit["t_s"].to_numpy(), tip_fit[["x_tracked_m", "y_tracked_m"]].to_numpy(),
                                      tip_fit["t_s"].to_numpy(), tip_fit[["x_sim_m", "y_sim_m"]].to_numpy(),
                                      tgt, campaign.target.radius)}]
    t_n, q_n = read_joint_table(res.motion, n_joints=campaign.arm.n_joints,
                                 arm_name=campaign.arm.name)
    figures.append({"id": "fig-arm-paths", "caption": "Grasp-point paths of the motion played in this trial "
                    "(measured joints) and of the next motion (paper Fig. 8b).",
                    "src": figs.arm_paths({"played (measured)": hand_pose(campaign.arm, q_j)[:, :2],
                                           "next motion": hand_pose(campaign.arm, q_n)[:, :2]},
                                          tgt, campaign.target.radius)})
    model_figures, values, lo, hi, diagnostics, bounds = _parameter_figures(params, settings.model)
    figures += model_figures
    strip = frame_strip(trial.video, Calibration.from_json(calib_json), tracks, fit,
                        campaign.string.length)
    figures.append({"id": "fig-overlay", "caption": "Frames of the motion with the tracked points (green circles; "
                    "red: the grasp from forward kinematics) and the model's points simulated with the estimate "
                    "(orange crosses and line) overlaid.", "src": strip_data_uri(strip)})
    in_motion = (t_tr >= t0) & (t_tr <= t1)
    figures.append({"id": "fig-valid", "caption": "Share of the frames in which each point was tracked (valid), "
                    "over the whole clip and over the motion and flight window: the points E (eqs. 4-6) and the "
                    "measured closest approach rest on.",
                    "src": figs.valid_per_point(np.arange(1, n + 1), valid[:, 1:].mean(axis=0),
                                                valid[in_motion, 1:].mean(axis=0) if in_motion.any() else None)})
    figures.append({"id": "fig-next-motion", "caption": "Next motion: joint angles and velocities "
                    f"(T = {nxt.get('T_s', float('nan')):.3f} s).", "src": figs.joint_curves(t_n, q_n)})

    prediction = read_json(res.prediction, mapping=True) if res.prediction is not None else None
    if prediction and prediction.get("tip_path"):
        path = prediction["tip_path"]
        t_p = np.asarray(path["t_s"], float)
        figures.insert(1, {"id": "fig-prediction", "caption": "Prediction check: the previous trial's estimate "
                           "driven by this trial's measured joints (the model's tip) against the tracked tip, from "
                           "the motion's start to the tip's closest approach: what the planner relied on.",
                           "src": figs.tip_paths(t_p, np.asarray(path["tracked_mm"], float) / 1000, t_p,
                                                 np.asarray(path["predicted_mm"], float) / 1000, tgt,
                                                 campaign.target.radius, title="Prediction check")})
    summary = _trial_summary(params, diagnostics, valid, (d_meas, floor_m), campaign, played, nxt, bounds[1])
    tracking = Path(res.tracking)
    box = verdict_box({calib_stage: calib, sync_stage: sync,
                       "tracking": read_json(tracking) if tracking.exists() else None, "fit": params,
                       "plan": nxt})
    notes = [str(w) for w in calib.get("warnings", [])] + [str(w) for w in [params.get("message")] if w]
    warnings = list(dict.fromkeys(w for w in notes if reason_key(w) not in box["said"]))   # each said once
    cal_rows = _calibration_rows(calib, sync)
    ctx = _common(campaign, f"Campaign {campaign.name}, trial {Path(out).parent.name.split('_')[-1]}", settings)
    ctx.update(summary=summary, warnings=warnings, figures=figures, calib=cal_rows, verdicts=box,
               prediction=_prediction_rows(prediction),
               params=[(k, v, a, b, f) for k, v, a, b, f in zip(PARAM_NAMES, values, lo, hi, bounds[0])])
    write_text(out, _env().get_template("trial.html.j2").render(**ctx))


def _parameter_figures(params: dict, model: ModelSettings) -> tuple[list, list, np.ndarray, np.ndarray, dict, tuple]:
    """The estimate's figures: coefficients within Table 2's ranges (Fig. 11), masses (Table 4), E over
    the search. Returns them, the coefficients in PARAM_NAMES order, the ranges (lo, hi), the
    estimate's diagnostics and which coefficients and masses sit at a bound (:func:`.verdicts.at_bounds`)."""
    figures = []
    lo, hi, (mu_lo, mu_hi) = model_ranges(model)
    coeffs = params["coefficients"]
    values = [coeffs[k] for k in PARAM_NAMES]
    diagnostics = params.get("diagnostics") or {}
    diag = {d["name"]: (10 ** d["log10_min"], 10 ** d["log10_max"], d["status"])
            for d in diagnostics.get("parameters", []) if d.get("name") in PARAM_NAMES}
    mu = np.asarray(params["mu"], float)
    bounds = at_bounds(values, lo, hi, mu, (mu_lo, mu_hi))
    figures.append({"id": "fig-params", "caption": "Estimated coefficients on log axes within Table 2's ranges "
                    "(paper Fig. 11), with the range of the parameter sets whose E is within "
                    f"{diagnostics.get('near_best_tol', 0.05) * 100:.0f} % of the best: a short "
                    "(green) bar means this motion pins the parameter down, a long (orange) one that it does not. "
                    "A red ring: the estimate sits at a bound of its range, where the range, not the footage, "
                    "decided it.",
                    "src": figs.parameters(list(PARAM_NAMES), values, lo, hi, diag,
                                           at_bound=bounds[0])})
    figures.append({"id": "fig-masses", "caption": "Estimated relative mass per point (paper Table 4); orange: "
                    "points where a weight or stiff section is known to sit.",
                    "src": figs.masses(mu, params.get("special_points", []))})
    hist = params.get("history", {})
    if hist.get("evaluations"):
        figures.append({"id": "fig-search", "caption": f"Best E over the search ({params.get('optimizer')}).",
                        "src": figs.search_history(hist["evaluations"], np.asarray(hist["best_E_mm"], dtype=float) / 1000)})
    return figures, values, lo, hi, diagnostics, bounds


def _trial_summary(params: dict, diagnostics: dict, valid: np.ndarray, measured: tuple[float, float],
                   campaign: Campaign, played: dict, nxt: dict, masses_at_bound: dict) -> list[tuple[str, str]]:
    """The trial page's summary rows: the estimate, the tracking, the measured approach (``measured``: the
    tip's closest approach and the string's lowest point above the floor, m: :func:`floor_clearance`) and
    the predicted ones (the next motion's with its spread over the estimate's near-best sets, :func:`_spread`)."""
    d_meas, floor_m = measured
    hit, floor_note = measured_hit(d_meas, floor_m, campaign.target.radius)
    summary = [("E (eqs. 4-6)", _fmt(params.get("E_mm"), ".2f", " mm")),
               ("optimizer, evaluations", f"{params.get('optimizer')}, {params.get('evaluations')}"),
               ("estimation time", _fmt(params.get("seconds"), ".1f", " s")),
               ("pinned down by this motion / loose", " / ".join(
                   ", ".join(diagnostics.get(k) or ["-"]) for k in ("pinned", "loose"))),
               ("tracked points valid", f"{valid[:, 1:].mean() * 100:.1f} %"),
               ("measured closest approach of the tip", _fmt(d_meas * 1000, ".1f", " mm")),
               ("measured hit", ("yes" if hit else "no") + (f" ({floor_note})" if floor_note else "")),
               ("played motion: predicted closest approach", _fmt(played.get("closest_approach_mm"), ".1f", " mm")),
               ("next motion: predicted closest approach (the best set)",
                _fmt(nxt.get("closest_approach_mm"), ".1f", " mm"))]
    spread = _spread(nxt, campaign.target.radius * 1000)
    if spread:
        summary.append(("next motion: predicted closest approach over the estimate's near-best sets", spread))
    m = masses_at_bound
    if m["lower"] or m["upper"]:
        all_low = m["lower"] == m["n"]
        summary.append(("mass points at a bound of their range", f"{m['lower']} at the lower, {m['upper']} at the "
                        f"upper of {m['n']}" + (": every mass at its least, as a fit that cannot follow the "
                                                "string does" if all_low else "")))
    if nxt.get("planned_on_failed_fit"):
        summary.append(("next motion", "planned on a failed fit: its predicted closest approach is not to be "
                                       "trusted (see the fit's verdict at the top)"))
    else:
        summary.append(("next motion: predicted hit", str(nxt.get("hit_predicted"))))
    if nxt.get("message"):
        summary.append(("next motion: planner's note", str(nxt["message"])))
    res = nxt.get("residual_correction")
    if res:
        summary.append(("next motion: residual correction (tip error of the played motion, median / max)",
                        f"{res['median_mm']:.1f} / {res['max_mm']:.1f} mm, tip tracked in "
                        f"{res['valid_share'] * 100:.0f} % of its frames"))
    return summary


def _spread(nxt: dict, radius_mm: float) -> str:
    """The next motion's closest approach under each of the estimate's near-best sets (the robust
    planner's ensemble, ``motion.json``'s ``ensemble_d_min_mm``): median, 10-90 % range and the share
    of sets under which it hits; "" where the plan scored none."""
    d = np.asarray(nxt.get("ensemble_d_min_mm") or [], float)
    d = d[np.isfinite(d)]
    if not len(d):
        return ""
    share = nxt.get("ensemble_hit_share")
    share = float(np.mean(d <= radius_mm)) if share is None else float(share)
    return (f"{np.median(d):.1f} mm (10-90 %: {np.percentile(d, 10):.1f}-{np.percentile(d, 90):.1f} mm over "
            f"{len(d)} sets); hits under {share:.0%} of them")


def _prediction_rows(prediction: dict | None) -> list[tuple[str, str]]:
    """The prediction check's rows (``prediction.json``), or [] where the trial has none (trial 1)."""
    if not prediction:
        return []
    status = (prediction.get("verdict") or {}).get("status", "not judged")
    reasons = (prediction.get("verdict") or {}).get("reasons") or []
    rows = [("tip error of the previous estimate on this motion, median / p95",
             f"{_fmt(prediction.get('median_mm'), '.1f')} / {_fmt(prediction.get('p95_mm'), '.1f', ' mm')}"),
            ("frames compared (tip tracked / all)", f"{prediction.get('valid_frames')} / {prediction.get('frames')}"),
            ("tracked closest approach in that window", _fmt(prediction.get("tracked_closest_approach_mm"), ".1f",
                                                            " mm")),
            ("verdict", status + (f": {reasons[0]}" if reasons else ""))]
    return rows


def _calibration_rows(calib: dict, sync: dict) -> list[tuple[str, str]]:
    """The trial page's calibration and sync rows (and the sync's warnings and note)."""
    cal_rows = [("reprojection error (board, homography)", _fmt(calib.get("reprojection_error_px"), ".3f", " px")),
                ("intrinsics", "from calib/ clip" if calib.get("K") else "none (homography only)"),
                ("intrinsics rms", _fmt(calib.get("intrinsics_rms_px"), ".3f", " px")),
                ("intrinsics views (used / board found; chosen for pose diversity)",
                 f"{calib.get('intrinsics_views')} / {calib.get('intrinsics_views_found')}" if calib.get("K") else "-"),
                ("board corners used", str(calib.get("n_corners"))),
                ("sync offset (controller time of frame 0)", _fmt(sync.get("offset_s"), ".5f", " s")),
                ("sync method", str(sync.get("method"))),
                ("sync time residual (spread of the frames' own best offsets)",
                 _fmt(sync.get("time_residual_ms"), ".2f", " ms")),
                ("trigger time minus estimate", _fmt(sync.get("trigger_minus_estimate_ms"), ".2f", " ms")),
                ("sync: arm seen vs forward kinematics, after the offset (match residual)",
                 _fmt(sync.get("residual_mm"), ".2f", " mm")),
                ("board-to-robot check: still arm seen vs where the board pose puts it",
                 "not checked" if not calib.get("board_check") else
                 f"{_fmt(calib['board_check'].get('residual_mm'), '.1f', ' mm')} (dx "
                 f"{_fmt(calib['board_check'].get('dx_mm'), '+.1f')}, dy {_fmt(calib['board_check'].get('dy_mm'), '+.1f')} mm)")]
    sw = calib.get("sweep") or {}
    if sw.get("applied"):
        cal_rows += [("arm's sweep: link rows (frames), rms before -> after",
                      f"{sw['rows_used']} ({sw['frames']}), {sw['rms_before_mm']:.2f} -> {sw['rms_after_mm']:.2f} mm"),
                     ("arm's sweep: mapping moved (p95) / known to, where the string can be",
                      f"{sw['moved_p95_mm']:.2f} / {sw['uncertainty_p95_mm']:.2f} mm"),
                     ("arm's sweep: clock correction / known to",
                      f"{sw['clock_correction_ms']:+.2f} / {sw['clock_uncertainty_ms']:.2f} ms")]
    elif sw:
        cal_rows.append(("arm's sweep", f"not applied: {sw.get('reason')}"))
    for w in sync.get("warnings") or []:
        cal_rows.append(("sync warning", w))
    if sync.get("note"):
        cal_rows.append(("sync note", sync["note"]))
    return cal_rows
