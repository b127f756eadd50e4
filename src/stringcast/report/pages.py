"""Self-contained HTML reports: one page per trial, one per campaign.

Figures are inlined as PNG data URIs (``report_figures``), the page is rendered
with Jinja2 from ``templates/``. The trial page shows the paper's figures for the
trial (Fig. 8a tip paths, Fig. 8b arm paths, Fig. 11 parameters, Table 4 masses),
E over the search, a frame strip with tracked and simulated points, how often each
point was tracked, calibration and sync, and the next motion. At its top a banner gives the
verdicts the stages wrote (calibration.json, sync.json, tracking.json if there is one, and the
fit's in params.json: ok green, warn amber, fail red) with their reasons; a next motion planned
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
                             TrialFiles, TrialResults, Verdict, hand_pose, model_ranges, motion_start, read_joint_table,
                             read_json, read_parquet, tracks_arrays, worst, write_text)
from . import figures as figs
from .provenance import provenance
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

    ``trial``: the trial's raw files (:class:`~stringcast.core.TrialFiles`: the video, the joint log and
    the played motion.json; a folder: by the data contract's names). ``results``: its products
    (:class:`~stringcast.core.TrialResults`; a folder: by name). ``settings``: every stage's (:class:`~stringcast.core.Settings`): the page names the method
    they make (:mod:`.provenance`), and reads Table 2's ranges (``model``) and the flight
    window (``motion``).

    Raises:
        DataError: a required result file is missing or malformed (named).
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
    model_figures, values, lo, hi, diagnostics = _parameter_figures(params, settings.model)
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

    summary = _trial_summary(params, diagnostics, valid, d_meas, campaign, played, nxt)
    tracking = Path(res.tracking)
    verdicts = stage_verdicts({calib_stage: calib, sync_stage: sync,
                               "tracking": read_json(tracking) if tracking.exists() else None, "fit": params})
    warnings = [str(w) for w in calib.get("warnings", [])] + [str(w) for w in [params.get("message")] if w]
    cal_rows = _calibration_rows(calib, sync)
    ctx = _common(campaign, f"Campaign {campaign.name}, trial {Path(out).parent.name.split('_')[-1]}", settings)
    ctx.update(summary=summary, warnings=warnings, figures=figures, calib=cal_rows, verdicts=verdicts,
               params=[(k, v, a, b) for k, v, a, b in zip(PARAM_NAMES, values, lo, hi)])
    write_text(out, _env().get_template("trial.html.j2").render(**ctx))


def _parameter_figures(params: dict, model: ModelSettings) -> tuple[list, list, np.ndarray, np.ndarray, dict]:
    """The estimate's figures: coefficients within Table 2's ranges (Fig. 11), masses (Table 4), E over
    the search. Returns them, the coefficients in PARAM_NAMES order, the ranges (lo, hi) and the
    estimate's diagnostics."""
    figures = []
    lo, hi, (mu_lo, mu_hi) = model_ranges(model)
    coeffs = params["coefficients"]
    values = [coeffs[k] for k in PARAM_NAMES]
    diagnostics = params.get("diagnostics") or {}
    diag = {d["name"]: (10 ** d["log10_min"], 10 ** d["log10_max"], d["status"])
            for d in diagnostics.get("parameters", []) if d.get("name") in PARAM_NAMES}
    figures.append({"id": "fig-params", "caption": "Estimated coefficients on log axes within Table 2's ranges "
                    "(paper Fig. 11), with the range of the parameter sets whose E is within "
                    f"{diagnostics.get('near_best_tol', 0.05) * 100:.0f} % of the best: a short "
                    "(green) bar means this motion pins the parameter down, a long (orange) one that it does not.",
                    "src": figs.parameters(list(PARAM_NAMES), values, lo, hi, diag)})
    mu = np.asarray(params["mu"], float)
    figures.append({"id": "fig-masses", "caption": "Estimated relative mass per point (paper Table 4); orange: "
                    "points where a weight or stiff section is known to sit.",
                    "src": figs.masses(mu, params.get("special_points", []))})
    hist = params.get("history", {})
    if hist.get("evaluations"):
        figures.append({"id": "fig-search", "caption": f"Best E over the search ({params.get('optimizer')}).",
                        "src": figs.search_history(hist["evaluations"], np.asarray(hist["best_E_mm"], dtype=float) / 1000)})
    return figures, values, lo, hi, diagnostics


def _trial_summary(params: dict, diagnostics: dict, valid: np.ndarray, d_meas: float, campaign: Campaign,
                   played: dict, nxt: dict) -> list[tuple[str, str]]:
    """The trial page's summary rows: the estimate, the tracking, the measured and predicted approaches."""
    summary = [("E (eqs. 4-6)", _fmt(params.get("E_mm"), ".2f", " mm")),
               ("optimizer, evaluations", f"{params.get('optimizer')}, {params.get('evaluations')}"),
               ("estimation time", _fmt(params.get("seconds"), ".1f", " s")),
               ("pinned down by this motion / loose", " / ".join(
                   ", ".join(diagnostics.get(k) or ["-"]) for k in ("pinned", "loose"))),
               ("tracked points valid", f"{valid[:, 1:].mean() * 100:.1f} %"),
               ("measured closest approach of the tip", _fmt(d_meas * 1000, ".1f", " mm")),
               ("measured hit", "yes" if d_meas <= campaign.target.radius else "no"),
               ("played motion: predicted closest approach", _fmt(played.get("closest_approach_mm"), ".1f", " mm")),
               ("next motion: predicted closest approach", _fmt(nxt.get("closest_approach_mm"), ".1f", " mm"))]
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


def stage_verdicts(docs: dict) -> dict:
    """The page's verdict banner from each stage's JSON document (None: the stage wrote no file).

    Args:
        docs: stage name -> its JSON (calibration.json, sync.json, tracking.json, params.json) or None.

    Returns:
        {"status": the worst status, "rows": [{"stage", "status", "reasons", "cause"}]}: one row per
        document given; a document without a ``"verdict"`` has status "not judged". Raises nothing:
        a malformed verdict is shown as not judged.
    """
    rows, judged = [], []
    for stage, doc in docs.items():
        if doc is None:
            continue
        raw = doc.get("verdict") if isinstance(doc, dict) else None
        try:
            v = Verdict.from_dict(raw) if raw else None
        except (ValueError, TypeError, AttributeError):
            v = None
        if v is not None:
            judged.append(v)
        rows.append({"stage": stage, "status": v.status if v else "not judged", "reasons": list(v.reasons) if v else [],
                     "cause": str(raw.get("likely_cause") or "") if isinstance(raw, dict) else ""})
    status = worst(*judged).status if judged else "not judged"
    return {"status": status, "rows": rows}


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


def _stage_times(results: Path) -> tuple[list, list]:
    """Wall seconds per rule from Snakemake's ``benchmark:`` files, per trial."""
    rows: dict[str, dict] = {}
    stages: list[str] = []
    for f in sorted((results / "benchmarks").glob("*.tsv")):
        stem = f.stem
        stage, _, k = stem.rpartition("_")
        if not k.isdigit():
            stage, k = stem, "-"
        try:
            s = float(pd.read_csv(f, sep="\t")["s"].iloc[0])
        except Exception:  # a benchmark file being written by a running job
            continue
        if stage not in stages:
            stages.append(stage)
        rows.setdefault(k, {})[stage] = f"{s:.1f}"
    return sorted(rows.items(), key=lambda kv: (not kv[0].isdigit(), int(kv[0]) if kv[0].isdigit() else 0)), stages


def write_campaign_report(data_dir: Path, results_dir: Path, campaign: Campaign, out: Path, *,
                          settings: Settings) -> None:
    """Write ``results/<campaign>/report.html``: one row per execution (paper Table 3).

    ``settings``: every stage's: the page names the method they make (:mod:`.provenance`) and
    reads the flight window (``motion``).

    Raises:
        DataError: a result file that is missing or malformed (named).
    """
    try:
        _write_campaign_report(Path(data_dir), Path(results_dir), campaign, Path(out), settings)
    except MALFORMED as exc:
        raise DataError(f"{results_dir}: a result file the campaign report reads is malformed "
                        f"({type(exc).__name__}: {exc})") from exc


def _fit_cell(params: dict) -> dict:
    """The campaign table's fit cell from a trial's ``params.json``: ``fit_status`` (ok, warn, fail or
    "not judged") and ``fit_cause`` (the likely cause where not ok, else "")."""
    row = stage_verdicts({"fit": params})["rows"][0]
    return {"fit_status": row["status"], "fit_cause": row["cause"] if row["status"] in ("warn", "fail") else ""}


def _write_campaign_report(data_dir: Path, results_dir: Path, campaign: Campaign, out: Path,
                           settings: Settings) -> None:
    """:func:`write_campaign_report`'s work."""
    motion = settings.motion
    rows, tips = [], {}
    n = campaign.string.n_points
    trials = sorted(int(p.name.split("_")[1]) for p in data_dir.glob("trial_*") if p.name.split("_")[1].isdigit())
    for k in trials:
        dd, rd = data_dir / f"trial_{k}", results_dir / f"trial_{k}"
        if not (rd / "params.json").exists():
            continue
        params = read_json(rd / "params.json", mapping=True)
        tracks = read_parquet(rd / "tracks.parquet")
        t0, t1, played = _motion_window(TrialFiles(Path(), dd / "joints.csv", played=dd / "motion.json"), motion,
                                        campaign.arm)
        t, xy, valid = _tracked(tracks, n)
        d, _ = closest_approach(t, xy[:, n], campaign.target.xy, t0, t1)
        window = (t >= t0) & (t <= t1)
        tips[f"execution {k}"] = xy[window, n]
        row = {"trial": k, "E_mm": _fmt(params.get("E_mm")), "measured_mm": _fmt(d * 1000, ".1f"),
               "predicted_mm": _fmt(played.get("closest_approach_mm"), ".1f"),
               "hit_measured": bool(d <= campaign.target.radius),
               "tip_valid_pct": _fmt(float(valid[window, n].mean()) * 100 if window.any() else None, ".0f"),
               **_fit_cell(params), "played_on_failed_fit": bool(played.get("planned_on_failed_fit"))}
        rows.append(row)
    figures = []
    if tips:
        figures.append({"id": "fig-campaign-tips", "caption": "Tracked tip path of each execution during the "
                        "motion and flight window.", "src": figs.campaign_tips(tips, campaign.target.xy,
                                                                                 campaign.target.radius)})
    timings, stages = _stage_times(results_dir)
    ctx = _common(campaign, f"Campaign {campaign.name}", settings)
    ctx.update(rows=rows, figures=figures, timings=timings, stages=stages)
    write_text(out, _env().get_template("campaign.html.j2").render(**ctx))
